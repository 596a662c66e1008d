//! ROS 2 messages in CDR and rosbag2 folders (SQLite or MCAP), written the
//! way `ros2 bag record` writes them, for the readers' tests.

#![allow(dead_code)]

use std::path::Path;

/// A little-endian CDR buffer (alignment counted from after the 4-byte encapsulation header).
pub struct Cdr(pub Vec<u8>);

impl Cdr {
    pub fn new() -> Cdr {
        Cdr(vec![0, 1, 0, 0])
    }
    fn align(&mut self, n: usize) {
        while (self.0.len() - 4) % n != 0 {
            self.0.push(0);
        }
    }
    pub fn u8(&mut self, v: u8) -> &mut Self {
        self.0.push(v);
        self
    }
    pub fn u32(&mut self, v: u32) -> &mut Self {
        self.align(4);
        self.0.extend(v.to_le_bytes());
        self
    }
    pub fn i32(&mut self, v: i32) -> &mut Self {
        self.align(4);
        self.0.extend(v.to_le_bytes());
        self
    }
    pub fn f64(&mut self, v: f64) -> &mut Self {
        self.align(8);
        self.0.extend(v.to_le_bytes());
        self
    }
    pub fn string(&mut self, s: &str) -> &mut Self {
        self.u32(s.len() as u32 + 1);
        self.0.extend(s.as_bytes());
        self.0.push(0);
        self
    }
    pub fn bytes(&mut self, b: &[u8]) -> &mut Self {
        self.u32(b.len() as u32);
        self.0.extend(b);
        self
    }
    pub fn header(&mut self, t_ns: i64, frame: &str) -> &mut Self {
        self.i32(t_ns.div_euclid(1_000_000_000) as i32).u32(t_ns.rem_euclid(1_000_000_000) as u32).string(frame)
    }
    pub fn f64s(&mut self, v: &[f64]) -> &mut Self {
        v.iter().for_each(|&x| {
            self.f64(x);
        });
        self
    }
}

/// `sensor_msgs/msg/Imu`.
pub fn imu(t_ns: i64, w: [f64; 3], a: [f64; 3]) -> Vec<u8> {
    let mut c = Cdr::new();
    c.header(t_ns, "imu_link").f64s(&[0.0, 0.0, 0.0, 1.0]).f64s(&[0.0; 9]);
    c.f64s(&w).f64s(&[0.0; 9]).f64s(&a).f64s(&[0.0; 9]);
    c.0
}

/// `sensor_msgs/msg/Temperature`.
pub fn temperature(t_ns: i64, celsius: f64) -> Vec<u8> {
    let mut c = Cdr::new();
    c.header(t_ns, "imu_link").f64(celsius).f64(0.01);
    c.0
}

/// `sensor_msgs/msg/Image` (`mono8`, rows of `width` bytes).
pub fn image_mono8(t_ns: i64, width: u32, height: u32, pixels: &[u8]) -> Vec<u8> {
    let mut c = Cdr::new();
    c.header(t_ns, "cam0").u32(height).u32(width).string("mono8").u8(0).u32(width).bytes(pixels);
    c.0
}

/// `geometry_msgs/msg/PoseStamped`: position and orientation (w, x, y, z).
pub fn pose_stamped(t_ns: i64, p: [f64; 3], q_wxyz: [f64; 4]) -> Vec<u8> {
    let mut c = Cdr::new();
    c.header(t_ns, "world").f64s(&p).f64s(&[q_wxyz[1], q_wxyz[2], q_wxyz[3], q_wxyz[0]]);
    c.0
}

/// One message of a bag: topic, type (`pkg/msg/Type`), receive time \[ns\], CDR bytes.
pub type BagMessage = (String, String, i64, Vec<u8>);

/// Write `msgs` into a rosbag2 SQLite file at `db3` (Humble's schema).
pub fn write_db3(db3: &Path, msgs: &[BagMessage]) {
    let _ = std::fs::remove_file(db3);
    let db = rusqlite::Connection::open(db3).unwrap();
    db.execute_batch(
        "CREATE TABLE schema(schema_version INTEGER PRIMARY KEY,ros_distro TEXT NOT NULL);
         INSERT INTO schema VALUES (3, 'humble');
         CREATE TABLE metadata(id INTEGER PRIMARY KEY,metadata_version INTEGER NOT NULL,metadata TEXT NOT NULL);
         CREATE TABLE topics(id INTEGER PRIMARY KEY,name TEXT NOT NULL,type TEXT NOT NULL,
             serialization_format TEXT NOT NULL,offered_qos_profiles TEXT NOT NULL);
         CREATE TABLE messages(id INTEGER PRIMARY KEY,topic_id INTEGER NOT NULL,timestamp INTEGER NOT NULL,
             data BLOB NOT NULL);
         CREATE INDEX timestamp_idx ON messages (timestamp ASC);",
    )
    .unwrap();
    let mut ids: Vec<String> = Vec::new();
    let tx = db.unchecked_transaction().unwrap();
    for (topic, ty, t, data) in msgs {
        let id = match ids.iter().position(|x| x == topic) {
            Some(i) => i + 1,
            None => {
                ids.push(topic.clone());
                tx.execute(
                    "INSERT INTO topics VALUES (?1, ?2, ?3, 'cdr', '')",
                    rusqlite::params![ids.len() as i64, topic, ty],
                )
                .unwrap();
                ids.len()
            }
        };
        tx.execute(
            "INSERT INTO messages (topic_id, timestamp, data) VALUES (?1, ?2, ?3)",
            rusqlite::params![id as i64, t, data],
        )
        .unwrap();
    }
    tx.commit().unwrap();
}

/// Write `msgs` into one MCAP file (ROS 2 profile: `ros2msg` schemas, `cdr` messages).
pub fn write_mcap(path: &Path, msgs: &[BagMessage]) {
    let mut w = mcap::Writer::new(std::io::BufWriter::new(std::fs::File::create(path).unwrap())).unwrap();
    let mut channels: Vec<(String, u16)> = Vec::new();
    for (seq, (topic, ty, t, data)) in msgs.iter().enumerate() {
        let ch = match channels.iter().find(|c| &c.0 == topic) {
            Some(c) => c.1,
            None => {
                let s = w.add_schema(ty, "ros2msg", b"...").unwrap();
                let c = w.add_channel(s, topic, "cdr", &Default::default()).unwrap();
                channels.push((topic.clone(), c));
                c
            }
        };
        let h = mcap::records::MessageHeader {
            channel_id: ch,
            sequence: seq as u32,
            log_time: *t as u64,
            publish_time: *t as u64,
        };
        w.write_to_known_channel(&h, data).unwrap();
    }
    w.finish().unwrap();
}

/// A rosbag2 folder `dir` with `metadata.yaml` and one storage file (`sqlite3` or `mcap`).
pub fn write_rosbag2(dir: &Path, storage: &str, msgs: &[BagMessage]) {
    let _ = std::fs::remove_dir_all(dir);
    std::fs::create_dir_all(dir).unwrap();
    let name = dir.file_name().unwrap().to_string_lossy().to_string();
    let file = if storage == "mcap" { format!("{name}_0.mcap") } else { format!("{name}_0.db3") };
    if storage == "mcap" {
        write_mcap(&dir.join(&file), msgs);
    } else {
        write_db3(&dir.join(&file), msgs);
    }
    let mut topics = String::new();
    let mut seen: Vec<&str> = Vec::new();
    for (topic, ty, _, _) in msgs {
        if !seen.contains(&topic.as_str()) {
            seen.push(topic);
            let n = msgs.iter().filter(|m| &m.0 == topic).count();
            topics.push_str(&format!(
                "    - topic_metadata:\n        name: {topic}\n        type: {ty}\n        serialization_format: cdr\n        offered_qos_profiles: \"\"\n      message_count: {n}\n"
            ));
        }
    }
    let meta = format!(
        "rosbag2_bagfile_information:\n  version: 5\n  storage_identifier: {storage}\n  duration:\n    nanoseconds: 0\n  starting_time:\n    nanoseconds_since_epoch: 0\n  message_count: {}\n  topics_with_message_count:\n{topics}  compression_format: \"\"\n  compression_mode: \"\"\n  relative_file_paths:\n    - {file}\n  files:\n    - path: {file}\n",
        msgs.len()
    );
    std::fs::write(dir.join("metadata.yaml"), meta).unwrap();
}

/// `sensor_msgs/msg/CameraInfo` (R, P, binning and ROI zero).
pub fn camera_info(t_ns: i64, width: u32, height: u32, model: &str, d: &[f64], k: [f64; 9]) -> Vec<u8> {
    let mut c = Cdr::new();
    c.header(t_ns, "cam0").u32(height).u32(width).string(model).u32(d.len() as u32).f64s(d).f64s(&k);
    c.f64s(&[0.0; 9]).f64s(&[0.0; 12]).u32(0).u32(0).u32(0).u32(0).u32(0).u32(0).u8(0);
    c.0
}

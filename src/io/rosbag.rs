//! `sensor_msgs/Imu` from ROS 1 bags (crate `rosbag`) and ROS 2 MCAP files
//! (crate `mcap`), decoded by hand (ROS 1 serialization and CDR are fixed
//! layouts for this message), into an [`ImuRecording`].
//!
//! Times are the messages' `header.stamp`; the topic is chosen by name, or
//! automatically when the file has exactly one IMU topic.

use super::imu::{ImuRecording, Stored};
use super::table::LineMap;
use super::validate::{validate, ValidateOptions};
use crate::error::InputError;
use std::collections::BTreeMap;
use std::path::Path;

/// One decoded IMU message: stamp \[ns\], angular velocity \[rad/s\], linear acceleration \[m/s²\].
type ImuMsg = (i64, [f64; 3], [f64; 3]);

/// Little-endian reader over a message buffer, with CDR alignment when `align` is set.
struct Reader<'a> {
    b: &'a [u8],
    pos: usize,
    origin: usize,
    align: bool,
}

impl Reader<'_> {
    fn take(&mut self, n: usize) -> Option<&[u8]> {
        if self.align {
            let a = n.min(8);
            let rel = self.pos - self.origin;
            self.pos += (a - rel % a) % a;
        }
        let s = self.b.get(self.pos..self.pos + n)?;
        self.pos += n;
        Some(s)
    }
    fn u32(&mut self) -> Option<u32> {
        Some(u32::from_le_bytes(self.take(4)?.try_into().ok()?))
    }
    fn f64(&mut self) -> Option<f64> {
        Some(f64::from_le_bytes(self.take(8)?.try_into().ok()?))
    }
    fn string(&mut self) -> Option<()> {
        let n = self.u32()? as usize;
        let align = std::mem::replace(&mut self.align, false);
        self.b.get(self.pos..self.pos + n)?;
        self.pos += n;
        self.align = align;
        Some(())
    }
    fn vec3(&mut self) -> Option<[f64; 3]> {
        Some([self.f64()?, self.f64()?, self.f64()?])
    }
    fn skip_f64(&mut self, n: usize) -> Option<()> {
        for _ in 0..n {
            self.f64()?;
        }
        Some(())
    }
}

/// Decode a ROS 1 `sensor_msgs/Imu`.
fn decode_ros1(b: &[u8]) -> Option<ImuMsg> {
    let mut r = Reader { b, pos: 0, origin: 0, align: false };
    r.u32()?; // seq
    let (sec, nsec) = (r.u32()?, r.u32()?);
    r.string()?; // frame_id
    r.skip_f64(4 + 9)?; // orientation, covariance
    let w = r.vec3()?;
    r.skip_f64(9)?;
    let a = r.vec3()?;
    Some((i64::from(sec) * 1_000_000_000 + i64::from(nsec), w, a))
}

/// Decode a ROS 2 `sensor_msgs/msg/Imu` in CDR (little-endian encapsulation).
fn decode_cdr(b: &[u8]) -> Option<ImuMsg> {
    if b.len() < 4 || b[1] != 0x01 {
        return None; // only CDR_LE is decoded
    }
    let mut r = Reader { b, pos: 4, origin: 4, align: true };
    let sec = r.u32()? as i32;
    let nsec = r.u32()?;
    r.string()?; // frame_id
    r.skip_f64(4 + 9)?;
    let w = r.vec3()?;
    r.skip_f64(9)?;
    let a = r.vec3()?;
    Some((i64::from(sec) * 1_000_000_000 + i64::from(nsec), w, a))
}

fn choose_topic<V>(path: &Path, topics: &BTreeMap<String, V>, topic: Option<&str>) -> Result<String, InputError> {
    match topic {
        Some(t) if topics.contains_key(t) => Ok(t.to_string()),
        Some(t) => Err(InputError::file(path, format!("no sensor_msgs/Imu topic '{t}'"))
            .with_hint(format!("IMU topics here: {}", topics.keys().cloned().collect::<Vec<_>>().join(", ")))),
        None => match topics.len() {
            0 => Err(InputError::file(path, "holds no sensor_msgs/Imu topic")),
            1 => Ok(topics.keys().next().cloned().unwrap_or_default()),
            _ => Err(InputError::file(path, "holds several sensor_msgs/Imu topics").with_hint(format!(
                "choose one with --topic: {}",
                topics.keys().cloned().collect::<Vec<_>>().join(", ")
            ))),
        },
    }
}

fn recording(path: &Path, mut msgs: Vec<ImuMsg>, checks: &ValidateOptions) -> Result<ImuRecording, InputError> {
    if msgs.is_empty() {
        return Err(InputError::file(path, "the IMU topic has no messages"));
    }
    // Bags store messages in arrival order; the validation then judges the stamps.
    msgs.sort_by_key(|m| m.0);
    let t0 = msgs[0].0;
    let mut rec = ImuRecording {
        sources: vec![path.to_path_buf()],
        t0_ns: t0,
        t: msgs.iter().map(|m| (m.0 - t0) as f64 * 1e-9).collect(),
        gyro: msgs.iter().map(|m| m.1).collect(),
        accel: msgs.iter().map(|m| m.2).collect(),
        gyro_units: Stored::Si,
        accel_units: Stored::Si,
        lines: LineMap::default(),
        ..ImuRecording::default()
    };
    if rec.gyro.iter().chain(&rec.accel).flatten().any(|v| !v.is_finite()) {
        return Err(InputError::file(path, "an IMU message holds a non-finite value"));
    }
    validate(&mut rec, checks)?;
    Ok(rec)
}

/// Read `sensor_msgs/msg/Imu` messages (CDR) from a ROS 2 MCAP file (one pass;
/// every IMU topic is decoded, then the chosen one kept).
pub fn read_mcap_imu(path: &Path, topic: Option<&str>, checks: &ValidateOptions) -> Result<ImuRecording, InputError> {
    let bytes = std::fs::read(path).map_err(|e| InputError::file(path, format!("cannot read: {e}")))?;
    let bad = |e: mcap::McapError| InputError::file(path, format!("not a readable MCAP file: {e}"));
    let mut by_topic: BTreeMap<String, Vec<ImuMsg>> = BTreeMap::new();
    for m in mcap::MessageStream::new(&bytes).map_err(bad)? {
        let m = m.map_err(bad)?;
        let is_imu = m.channel.schema.as_ref().is_some_and(|s| s.name == "sensor_msgs/msg/Imu");
        if is_imu && m.channel.message_encoding == "cdr" {
            let d = decode_cdr(&m.data).ok_or_else(|| {
                let t = &m.channel.topic;
                InputError::file(path, format!("message {} on {t} is not a CDR sensor_msgs/msg/Imu", m.sequence))
            })?;
            by_topic.entry(m.channel.topic.clone()).or_default().push(d);
        }
    }
    let topic = choose_topic(path, &by_topic, topic)?;
    recording(path, by_topic.remove(&topic).unwrap_or_default(), checks)
}

/// Check a ROS 1 bag's header before handing it to `rosbag`, which slices the
/// file at the header's `index_pos` without checking it.
/// `data` is the start of the file (at least its header record), `file_len` its length.
fn check_bag_header(path: &Path, data: &[u8], file_len: usize) -> Result<(), InputError> {
    let bad = |m: &str| Err(InputError::file(path, format!("not a ROS 1 bag: {m}")));
    let magic = b"#ROSBAG V2.0\n";
    if !data.starts_with(magic) {
        return bad("missing the '#ROSBAG V2.0' line");
    }
    let mut pos = magic.len();
    let u32_at = |p: usize| data.get(p..p + 4).map(|b| u32::from_le_bytes(b.try_into().unwrap_or([0; 4])) as usize);
    let Some(hlen) = u32_at(pos) else { return bad("truncated header") };
    pos += 4;
    let end = pos.saturating_add(hlen);
    if end > data.len() {
        return bad("truncated header");
    }
    // The header record's data (padding to 4 KiB) follows its fields: the index
    // starts after it, with at least a record's two length fields.
    let Some(data_len) = u32_at(end) else { return bad("truncated header record") };
    let record_end = end.saturating_add(4).saturating_add(data_len);
    let mut index_pos = None;
    while pos + 4 <= end {
        let Some(flen) = u32_at(pos) else { return bad("truncated header field") };
        let field = data.get(pos + 4..pos.saturating_add(4).saturating_add(flen)).unwrap_or(&[]);
        if let Some(v) = field.strip_prefix(b"index_pos=") {
            index_pos = Some(v.get(..8).map(|b| u64::from_le_bytes(b.try_into().unwrap_or([0; 8]))));
        }
        pos = pos.saturating_add(4).saturating_add(flen);
    }
    match index_pos {
        None => bad("its header has no index_pos field"),
        Some(None) => bad("its header's index_pos field is shorter than 8 bytes"),
        // An index at the very end is empty (no connections); anything else needs room for a record.
        Some(Some(i))
            if (i as usize) < record_end || (i as usize != file_len && (i as usize).saturating_add(8) > file_len) =>
        {
            bad(&format!(
                "its header's index_pos ({i}) does not point past the header record ({record_end} bytes) to a record \
             inside the file ({file_len} bytes) (truncated while recording? try `rosbag reindex`)"
            ))
        }
        Some(Some(_)) => Ok(()),
    }
}

/// Read `sensor_msgs/Imu` messages from a ROS 1 bag.
pub fn read_ros1_bag_imu(
    path: &Path,
    topic: Option<&str>,
    checks: &ValidateOptions,
) -> Result<ImuRecording, InputError> {
    // The header record comes first (4 KiB in bags rosbag writes); read only that much.
    let io = |e: std::io::Error| InputError::file(path, format!("cannot read: {e}"));
    let file = std::fs::File::open(path).map_err(io)?;
    let file_len = file.metadata().map_err(io)?.len() as usize;
    let mut head = Vec::new();
    std::io::Read::read_to_end(&mut std::io::Read::take(file, 1 << 20), &mut head).map_err(io)?;
    check_bag_header(path, &head, file_len)?;
    let bag =
        rosbag::RosBag::new(path).map_err(|e| InputError::file(path, format!("not a readable ROS 1 bag: {e}")))?;
    let bad = |e: rosbag::Error| InputError::file(path, format!("corrupt bag record: {e}"));
    // Connection records come before their messages; only IMU messages are decoded.
    let mut imu_conns: BTreeMap<u32, String> = BTreeMap::new();
    let mut by_topic: BTreeMap<String, Vec<ImuMsg>> = BTreeMap::new();
    for rec in bag.chunk_records() {
        if let rosbag::ChunkRecord::Chunk(chunk) = rec.map_err(bad)? {
            for msg in chunk.messages() {
                match msg.map_err(bad)? {
                    rosbag::MessageRecord::Connection(c) if c.tp == "sensor_msgs/Imu" => {
                        imu_conns.insert(c.id, c.topic.to_string());
                    }
                    rosbag::MessageRecord::Connection(_) => {}
                    rosbag::MessageRecord::MessageData(m) => {
                        if let Some(t) = imu_conns.get(&m.conn_id) {
                            let d = decode_ros1(m.data).ok_or_else(|| {
                                InputError::file(path, format!("a message on {t} is not a sensor_msgs/Imu (too short)"))
                            })?;
                            by_topic.entry(t.clone()).or_default().push(d);
                        }
                    }
                }
            }
        }
    }
    let topic = choose_topic(path, &by_topic, topic)?;
    recording(path, by_topic.remove(&topic).unwrap_or_default(), checks)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cdr_alignment_after_an_odd_frame_id() {
        let mut b = vec![0u8, 1, 0, 0];
        b.extend(5i32.to_le_bytes());
        b.extend(7u32.to_le_bytes());
        b.extend(4u32.to_le_bytes());
        b.extend(b"imu\0");
        // Now at offset 16 from the origin: already 8-aligned.
        for v in (0..13).map(|_| 0.0f64).chain([0.1, 0.2, 0.3]).chain((0..9).map(|_| 0.0)).chain([1.0, 2.0, 9.8]) {
            b.extend(v.to_le_bytes());
        }
        let (t, w, a) = decode_cdr(&b).unwrap();
        assert_eq!((t, w, a), (5_000_000_007, [0.1, 0.2, 0.3], [1.0, 2.0, 9.8]));
        assert!(decode_cdr(&b[..b.len() - 1]).is_none());
    }
}

#!/usr/bin/env python3
"""Write a synthetic rosbag2 SQLite folder (Humble schema) for reading
benchmarks: an IMU topic at RATE Hz with noise and a camera topic of
mono8 images at 20 Hz interleaved, as `ros2 bag record` stores them.

    python3 bench/scripts/make_rosbag2.py OUT_DIR --seconds 600 --rate 400 --image 320x240
    /usr/bin/time -v target/release/tumble inspect OUT_DIR
"""
import argparse, os, random, sqlite3, struct

def cdr_header(t_ns, frame):
    b = bytearray(b"\x00\x01\x00\x00")
    b += struct.pack("<iI", t_ns // 10**9, t_ns % 10**9)
    f = frame.encode() + b"\x00"
    b += struct.pack("<I", len(f)) + f
    return b

def align(b, n):
    while (len(b) - 4) % n:
        b.append(0)

def imu(t_ns, w, a):
    b = cdr_header(t_ns, "imu_link")
    align(b, 8)
    b += struct.pack("<4d", 0, 0, 0, 1) + struct.pack("<9d", *[0] * 9)
    b += struct.pack("<3d", *w) + struct.pack("<9d", *[0] * 9)
    b += struct.pack("<3d", *a) + struct.pack("<9d", *[0] * 9)
    return bytes(b)

def image(t_ns, w, h, px):
    b = cdr_header(t_ns, "cam0")
    align(b, 4)
    b += struct.pack("<II", h, w)
    e = b"mono8\x00"
    b += struct.pack("<I", len(e)) + e
    b += b"\x00"
    align(b, 4)
    b += struct.pack("<II", w, len(px)) + px
    return bytes(b)

def main():
    p = argparse.ArgumentParser()
    p.add_argument("out")
    p.add_argument("--seconds", type=float, default=600)
    p.add_argument("--rate", type=float, default=400)
    p.add_argument("--image", default="320x240")
    a = p.parse_args()
    w, h = map(int, a.image.split("x"))
    os.makedirs(a.out, exist_ok=True)
    name = os.path.basename(os.path.normpath(a.out)) + "_0.db3"
    db_path = os.path.join(a.out, name)
    if os.path.exists(db_path):
        os.remove(db_path)
    db = sqlite3.connect(db_path)
    db.executescript("""
      CREATE TABLE schema(schema_version INTEGER PRIMARY KEY,ros_distro TEXT NOT NULL);
      CREATE TABLE metadata(id INTEGER PRIMARY KEY,metadata_version INTEGER NOT NULL,metadata TEXT NOT NULL);
      CREATE TABLE topics(id INTEGER PRIMARY KEY,name TEXT NOT NULL,type TEXT NOT NULL,
        serialization_format TEXT NOT NULL,offered_qos_profiles TEXT NOT NULL);
      CREATE TABLE messages(id INTEGER PRIMARY KEY,topic_id INTEGER NOT NULL,timestamp INTEGER NOT NULL,
        data BLOB NOT NULL);
      CREATE INDEX timestamp_idx ON messages (timestamp ASC);
      INSERT INTO topics VALUES (1, '/imu0', 'sensor_msgs/msg/Imu', 'cdr', '');
      INSERT INTO topics VALUES (2, '/cam0/image_raw', 'sensor_msgs/msg/Image', 'cdr', '');
    """)
    rng = random.Random(1)
    t0 = 1_700_000_000 * 10**9
    n = int(a.seconds * a.rate)
    per_image = int(a.rate / 20)
    px = bytes(rng.randrange(256) for _ in range(w * h))
    rows = []
    for i in range(n):
        t = t0 + int(i * 1e9 / a.rate)
        g = [rng.gauss(0, 1e-3) for _ in range(3)]
        f = [rng.gauss(0, 1e-2), rng.gauss(0, 1e-2), 9.81 + rng.gauss(0, 1e-2)]
        rows.append((1, t, imu(t, g, f)))
        if i % per_image == 0:
            rows.append((2, t, image(t, w, h, px)))
        if len(rows) >= 20000:
            db.executemany("INSERT INTO messages (topic_id, timestamp, data) VALUES (?,?,?)", rows)
            rows = []
    db.executemany("INSERT INTO messages (topic_id, timestamp, data) VALUES (?,?,?)", rows)
    db.commit()
    n_img = (n + per_image - 1) // per_image
    with open(os.path.join(a.out, "metadata.yaml"), "w") as m:
        m.write(f"""rosbag2_bagfile_information:
  version: 5
  storage_identifier: sqlite3
  relative_file_paths:
    - {name}
  duration:
    nanoseconds: {int(a.seconds * 1e9)}
  starting_time:
    nanoseconds_since_epoch: {t0}
  message_count: {n + n_img}
  topics_with_message_count:
    - topic_metadata:
        name: /imu0
        type: sensor_msgs/msg/Imu
        serialization_format: cdr
        offered_qos_profiles: ""
      message_count: {n}
    - topic_metadata:
        name: /cam0/image_raw
        type: sensor_msgs/msg/Image
        serialization_format: cdr
        offered_qos_profiles: ""
      message_count: {n_img}
  compression_format: ""
  compression_mode: ""
""")

if __name__ == "__main__":
    main()

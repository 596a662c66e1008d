//! Shared by the `db3` and `mcap` targets: one input as a ROS 2 container
//! file of the given extension, opened as tumble opens it. Any file gives
//! topics, messages and an IMU recording, or an error naming the file —
//! never a panic.
use tumble::io::ros::{read_ros_imu, ImuTopics, Storage};
use tumble::io::validate::ValidateOptions;

pub fn open_as(ext: &str, file: &[u8]) {
    // tumble turns a panic of the MCAP reader into an error (catch_unwind);
    // libFuzzer's panic hook would abort before that. Without a hook a panic
    // tumble does not catch still unwinds into libfuzzer-sys, which aborts:
    // it is found all the same.
    static QUIET: std::sync::Once = std::sync::Once::new();
    QUIET.call_once(|| std::panic::set_hook(Box::new(|_| {})));
    let dir = std::env::temp_dir().join(format!("tumble-fuzz-{ext}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(format!("input.{ext}"));
    std::fs::write(&path, file).unwrap();
    let storage = Storage::of(&path).unwrap().expect("a .db3 or .mcap path is a ROS container");
    if let Ok(topics) = storage.topics() {
        let names: Vec<&str> = topics.iter().map(|t| t.name.as_str()).collect();
        let _ = storage.for_each(&names, &mut |_| Ok(()));
    }
    if let Ok(rec) = read_ros_imu(&storage, &ImuTopics::default(), &ValidateOptions::default()) {
        assert!(!rec.t.is_empty() && rec.t.len() == rec.gyro.len());
    }
    // A fresh file each time: SQLite keeps journal files beside it.
    let _ = std::fs::remove_dir_all(&dir);
}

//! rosbag2's SQLite storage (`.db3`) as tumble reads it (see ros_container.rs).
#![no_main]
#[path = "ros_container.rs"]
mod ros_container;
libfuzzer_sys::fuzz_target!(|data: &[u8]| ros_container::open_as("db3", data));

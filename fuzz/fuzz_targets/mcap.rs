//! MCAP files (rosbag2's other storage) as tumble reads them (see ros_container.rs).
#![no_main]
#[path = "ros_container.rs"]
mod ros_container;
libfuzzer_sys::fuzz_target!(|data: &[u8]| ros_container::open_as("mcap", data));

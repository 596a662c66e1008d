//! YAML configs and sensor files: any text gives a value or an error.
#![no_main]
use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        if let Ok(cfg) = tumble::io::yaml::parse_yaml::<tumble::sim::SimConfig>(Path::new("sim.yaml"), text) {
            let _ = cfg.check();
        }
        let _ = tumble::io::asl::parse_camera_sensor(Path::new("sensor.yaml"), text);
        let _ = tumble::io::asl::parse_imu_sensor(Path::new("sensor.yaml"), text);
    }
});

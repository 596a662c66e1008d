//! The message decoders under the ROS readers (ROS 1 serialization and ROS 2
//! CDR): any bytes give a message or `None`, never a panic; what is decoded
//! is finite where the readers rely on it.
#![no_main]
use libfuzzer_sys::fuzz_target;
use tumble::io::ros::msgs::{self, Encoding};

const POSE_TYPES: [&str; 4] =
    ["geometry_msgs/PoseStamped", "geometry_msgs/PoseWithCovarianceStamped", "geometry_msgs/TransformStamped", "nav_msgs/Odometry"];

fuzz_target!(|data: &[u8]| {
    for enc in [Encoding::Ros1, Encoding::Cdr] {
        let _ = msgs::imu(enc, data);
        let _ = msgs::temperature(enc, data);
        if let Some(image) = msgs::image(enc, data) {
            let _ = format!("{image:?}");
        }
        let _ = msgs::compressed_image(enc, data);
        let _ = msgs::camera_info(enc, data);
        for ty in POSE_TYPES {
            let _ = msgs::pose(ty, enc, data);
        }
    }
});

//! `tumble convert`: a ROS recording as an ASL/EuRoC folder.

use super::common::{paths, progress_bar, TopicArgs};
use super::CliResult;
use clap::Args;
use std::path::PathBuf;
use tumble::io::convert::{convert_to_asl, ConvertOptions};

/// Flags of `tumble convert`.
#[derive(Args)]
pub struct ConvertArgs {
    /// ROS recording: a rosbag2 folder (metadata.yaml with .db3 or .mcap), a .db3, .mcap or ROS 1 .bag.
    input: PathBuf,
    /// New (or empty) output folder; gets mav0/imu0, mav0/camN, mav0/state_groundtruth_estimate0.
    #[arg(long)]
    out: PathBuf,
    #[command(flatten)]
    topics: TopicArgs,
    /// Image topics in camera order, comma separated (default: all, sorted by name).
    #[arg(long, value_delimiter = ',')]
    images: Option<Vec<String>>,
    /// The ground-truth pose topic (PoseStamped, PoseWithCovarianceStamped, TransformStamped or Odometry; default: the only one).
    #[arg(long)]
    groundtruth_topic: Option<String>,
}

impl ConvertArgs {
    pub fn run(self) -> CliResult {
        let opts = ConvertOptions {
            imu: self.topics.topics(),
            images: self.images,
            groundtruth: self.groundtruth_topic,
            ..Default::default()
        };
        let bar = progress_bar(0, "convert [{bar:40}] {pos}/{len} messages {elapsed_precise} (eta {eta})");
        let report = convert_to_asl(&self.input, &self.out, &opts, &mut |done, total| {
            if done % 64 == 0 {
                bar.set_length(total as u64);
                bar.set_position(done as u64);
            }
        })?;
        bar.finish_and_clear();
        for n in &report.notes {
            println!("note: {n}");
        }
        println!("imu0: {} samples from {}", report.imu.0, report.imu.1);
        for (cam, topic, n, yaml) in &report.cameras {
            let y = if *yaml { " and sensor.yaml from its camera_info" } else { "" };
            println!("{cam}: {n} frames from {topic}{y}");
        }
        if let Some((topic, n)) = &report.groundtruth {
            println!("state_groundtruth_estimate0: {n} poses from {topic}");
        }
        println!("wrote {} (and the frames)", paths(&report.files));
        Ok(())
    }
}

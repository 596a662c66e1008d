//! `tumble inspect`: what a recording holds and what looks wrong.

use super::common::RecordingArgs;
use super::CliResult;
use clap::Args;
use std::path::PathBuf;
use tumble::io::{AxisStats, Stored};

/// Flags of `tumble inspect`.
#[derive(Args)]
pub struct InspectArgs {
    /// ASL dataset folder (or its mav0/), a ROS recording (rosbag2 folder, .db3, .mcap, .bag), a phone
    /// logger's export folder, a text/CSV file (.gz allowed), or imu_tk's accelerometer file.
    recording: PathBuf,
    #[command(flatten)]
    read: RecordingArgs,
    /// Also write a PNG of the accelerometer and gyro (and temperature) against time.
    #[arg(long, value_name = "FILE.png")]
    plot: Option<PathBuf>,
}

impl InspectArgs {
    pub fn run(self) -> CliResult {
        // A ROS recording: what it holds first (the topic to choose may be among them).
        if let Some(storage) = tumble::io::ros::Storage::of(&self.recording)? {
            println!("{}: topics", self.recording.display());
            for t in storage.topics()? {
                let n = t.count.map(|n| format!("{n} messages")).unwrap_or_else(|| "count not indexed".into());
                println!("  {:<40} {:<36} {n}", t.name, t.msg_type);
            }
        }
        let start = std::time::Instant::now();
        let r = tumble::io::open_recording(&self.recording, &self.read.options())?;
        println!("{}: {} samples in {:.2} s", r.source_name(), r.len(), start.elapsed().as_secs_f64());
        if let Some(t) = &r.topic {
            println!("  IMU topic {t}");
        }
        println!("  duration {:.3} s, mean rate {:.3} Hz", r.duration(), r.mean_rate());
        let stats = r.stats();
        let unit = |u: Stored, si: &'static str| if u == Stored::Si { si } else { "counts" };
        let line = |s: Option<AxisStats>, name: &str, unit: &str| {
            if let Some(AxisStats { mean: m, std: sd }) = s {
                println!(
                    "  {name:<6} mean [{:+.5}, {:+.5}, {:+.5}] std [{:.5}, {:.5}, {:.5}] {unit}",
                    m[0], m[1], m[2], sd[0], sd[1], sd[2]
                );
            }
        };
        line(stats.gyro, "gyro", unit(r.gyro_units, "rad/s"));
        line(stats.accel, "accel", unit(r.accel_units, "m/s²"));
        if let Some((lo, hi)) = stats.temperature {
            println!("  temperature {lo:.2} … {hi:.2} °C");
        }
        // A static log (gravity does not turn) also gets its knocks and steps.
        let disturbances = tumble::allan::static_disturbances(&r).unwrap_or_default();
        if r.warnings.is_empty() && disturbances.is_empty() {
            println!("  no problems found");
        }
        for w in &r.warnings {
            println!("warning: {w}");
        }
        for d in &disturbances {
            println!("warning: static log disturbed: {d}");
        }
        if let Some(png) = self.plot {
            tumble::inspect::write_overview_png(&r, &png)?;
            println!("wrote {}", png.display());
        }
        Ok(())
    }
}

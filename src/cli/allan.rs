//! `tumble allan`: noise identification from a static recording, or from a
//! recording in motion against its ground truth (`--groundtruth`).

use super::common::{paths, progress_bar, RecordingArgs};
use super::CliResult;
use clap::builder::TypedValueParser as _;
use clap::Args;
use std::path::PathBuf;
use tumble::allan::{AllanOptions, AllanRunOptions, AxisStat, DeviationKind, TauGrid, TimeSpan};

/// Flags of `tumble allan`.
#[derive(Args)]
pub struct AllanArgs {
    /// Static recording: ASL folder, ROS bag/MCAP, or text/CSV (.gz allowed);
    /// with --groundtruth, a recording in motion.
    recording: PathBuf,
    #[command(flatten)]
    read: RecordingArgs,
    /// Output folder.
    #[arg(long)]
    out: PathBuf,
    /// Estimator (noise coefficients are identified from oadev or adev curves).
    #[arg(long, default_value = "oadev",
          value_parser = clap::builder::PossibleValuesParser::new(DeviationKind::NAMES).map(|s| s.parse::<DeviationKind>().expect("listed")))]
    kind: DeviationKind,
    /// τ values: a number of log-spaced values per decade, `octave`, or `all`.
    #[arg(long, default_value = "20", value_parser = |s: &str| s.parse::<TauGrid>())]
    taus: TauGrid,
    /// Largest τ as a fraction of the record length.
    #[arg(long, default_value_t = 0.1)]
    max_tau_fraction: f64,
    /// Confidence level of the deviation intervals (0.683 = 1 σ).
    #[arg(long, default_value_t = 0.683)]
    confidence: f64,
    /// How the three axes become Kalibr's single number.
    #[arg(long, default_value = "max",
          value_parser = clap::builder::PossibleValuesParser::new(AxisStat::NAMES).map(|s| s.parse::<AxisStat>().expect("listed")))]
    axis_stat: AxisStat,
    /// Analyse only this time span of the recording [s from its start], e.g. 0:3600.
    #[arg(long, value_parser = |s: &str| s.parse::<TimeSpan>())]
    span: Option<TimeSpan>,
    /// Ground truth of the IMU's pose on the recording's clock (EuRoC's
    /// state_groundtruth_estimate0/data.csv, or TUM): analyse what the IMU
    /// reads beyond the truth's motion while it moves (the noise on its
    /// platform in use, rotors running), not a static log.
    #[arg(long)]
    groundtruth: Option<PathBuf>,
    /// Local gravity [m/s²] for --groundtruth.
    #[arg(long, default_value_t = 9.81)]
    gravity: f64,
}

impl AllanArgs {
    pub fn run(self) -> CliResult {
        let opts = AllanRunOptions {
            allan: AllanOptions {
                kind: self.kind,
                taus: self.taus,
                max_tau_fraction: self.max_tau_fraction,
                confidence: self.confidence,
            },
            axis_stat: self.axis_stat,
            cut_disturbances: self.span.is_none(),
        };
        opts.validate()?;
        let start = std::time::Instant::now();
        let mut rec = tumble::io::open_recording(&self.recording, &self.read.options())?;
        if let Some(span) = self.span {
            rec = rec.slice_time(span.start_s, span.end_s);
        }
        eprintln!("read {} samples ({:.1} s) in {:.2} s", rec.len(), rec.duration(), start.elapsed().as_secs_f64());
        let bar = progress_bar(0, "allan [{bar:40}] {pos}/{len} τ  {elapsed_precise} (eta {eta})");
        let t = std::time::Instant::now();
        let progress = |done: usize, total: usize| {
            bar.set_length(total as u64);
            bar.set_position(done as u64);
        };
        let report = match &self.groundtruth {
            Some(path) => {
                let truth = tumble::io::trajectory::read_trajectory(path)?;
                tumble::allan::in_motion::run_allan_in_motion(&rec, &truth, self.gravity, &opts, &progress)?.0
            }
            None => tumble::allan::run_allan_with_progress(&rec, &opts, &progress)?,
        };
        bar.finish_and_clear();
        let elapsed = t.elapsed().as_secs_f64();
        print!("{}", report.summary_table());
        let files = report.write_all(&self.out)?;
        println!("\ncomputed in {elapsed:.2} s; wrote {}", paths(&files));
        Ok(())
    }
}

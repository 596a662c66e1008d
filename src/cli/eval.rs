//! `tumble eval`: a trajectory against ground truth.

use super::common::paths;
use super::CliResult;
use clap::Args;
use std::path::PathBuf;
use tumble::eval::{Alignment, EvalOptions};

/// Flags of `tumble eval`.
#[derive(Args)]
pub struct EvalArgs {
    /// Estimated trajectory: TUM (`t[s] x y z qx qy qz qw`) or ASL CSV.
    #[arg(long)]
    estimate: PathBuf,
    /// Ground truth: EuRoC/ASL CSV (with bias columns for bias errors) or TUM.
    #[arg(long)]
    groundtruth: PathBuf,
    /// Alignment before the absolute errors: se3, sim3, posyaw (VIO's gauge) or none.
    #[arg(long, default_value = "posyaw", value_parser = |s: &str| s.parse::<Alignment>())]
    align: Alignment,
    /// Bias track (`tumble vio`'s biases.csv); default: biases.csv beside the estimate, if there.
    #[arg(long)]
    biases: Option<PathBuf>,
    /// Relative-error distances [m], comma separated; default 10–50 % of the path.
    #[arg(long, value_delimiter = ',')]
    rpe_distances: Vec<f64>,
    /// Bias errors count from this many seconds after the first estimate.
    #[arg(long, default_value_t = 10.0)]
    bias_after: f64,
    /// Largest ground-truth gap to interpolate across [s].
    #[arg(long, default_value_t = 0.1)]
    max_gap: f64,
    /// Times [s, the estimate's clock] at which the estimate begins again in a
    /// frame of its own, comma separated: each piece is aligned by itself.
    /// Default: the `starts` of `tumble vio`'s summary.json beside the estimate.
    #[arg(long, value_delimiter = ',')]
    pieces: Option<Vec<f64>>,
    /// Output folder (default: `eval/` beside the estimate).
    #[arg(long)]
    out: Option<PathBuf>,
}

impl EvalArgs {
    pub fn run(self) -> CliResult {
        let mut opts = EvalOptions {
            alignment: self.align,
            rpe_distances: self.rpe_distances,
            bias_after_s: self.bias_after,
            max_gap_s: self.max_gap,
            piece_starts_s: self.pieces.clone().unwrap_or_default(),
        };
        opts.validate()?;
        let inputs = tumble::eval::EvalInputs::read(&self.estimate, &self.groundtruth, self.biases.as_deref())?;
        if self.pieces.is_none() && !inputs.piece_starts_s.is_empty() {
            println!("pieces: {} (summary.json beside the estimate)", inputs.piece_starts_s.len());
            opts.piece_starts_s = inputs.piece_starts_s.clone();
            opts.validate()?;
        }
        if let (None, Some(b)) = (&self.biases, &inputs.biases_file) {
            println!("biases: {}", b.display());
        }
        let ev = tumble::eval::evaluate(&inputs.estimate, inputs.biases.as_ref(), &inputs.groundtruth, &opts)?;
        for w in &ev.metrics.warnings {
            eprintln!("warning: {w}");
        }
        print!("{}", ev.metrics.table());
        let dir = self.out.unwrap_or_else(|| self.estimate.with_file_name("eval"));
        let files = tumble::eval::write_report(&dir, &ev)?;
        println!("wrote {}", paths(&files));
        Ok(())
    }
}

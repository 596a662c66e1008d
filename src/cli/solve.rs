//! `tumble solve`: a g2o pose graph or a BAL problem on the solver.

use super::CliResult;
use clap::{Args, ValueEnum};
use std::path::PathBuf;
use tumble::posegraph::{solve_file, EdgeErrorChoice, SolveFileOptions};
use tumble_solvers::{LmOptions, Method, Summary};

#[derive(Clone, Copy, ValueEnum)]
enum MethodArg {
    Lm,
    Gn,
}

/// `tumble solve --edge-error`: the cost of a 3-D g2o edge.
#[derive(Clone, Copy, ValueEnum)]
enum EdgeErrorArg {
    /// Log(Z⁻¹ X₁⁻¹ X₂), GTSAM's BetweenFactor.
    Log,
    /// Ceres' pose_graph_3d error [R₁ᵀ(p₂−p₁) − p_z, 2·vec(q_z q₁₂⁻¹)].
    Ceres,
    /// Ceres' error first, then log from its solution (reaches Ceres' minimum
    /// of torus3D in the log cost).
    CeresThenLog,
}

/// Flags of `tumble solve`.
#[derive(Args)]
pub struct SolveArgs {
    /// Input file.
    file: PathBuf,
    /// Nonlinear method.
    #[arg(long, value_enum, default_value = "lm")]
    method: MethodArg,
    /// Maximum iterations.
    #[arg(long, default_value_t = LmOptions::default().max_iterations)]
    max_iterations: usize,
    /// Initial Levenberg–Marquardt damping λ (relative to diag(H)).
    #[arg(long, default_value_t = LmOptions::default().initial_lambda)]
    initial_lambda: f64,
    /// Smallest factor λ shrinks by after a good step.
    #[arg(long, default_value_t = LmOptions::default().min_lambda_decrease)]
    min_lambda_decrease: f64,
    /// Relative cost decrease still to come at which the solve ends.
    #[arg(long, default_value_t = LmOptions::default().function_tolerance)]
    function_tolerance: f64,
    /// g2o: replace non-positive-definite information matrices by the nearest
    /// positive-definite ones (with a warning each) instead of refusing the file.
    #[arg(long)]
    repair_information: bool,
    /// g2o: the cost of each 3-D edge.
    #[arg(long, value_enum, default_value = "log")]
    edge_error: EdgeErrorArg,
    /// Print the per-iteration log.
    #[arg(long)]
    verbose: bool,
    /// g2o only: write a PNG of the initial guess and the solution seen from above.
    #[arg(long, value_name = "FILE.png")]
    plot: Option<PathBuf>,
}

fn print_log(s: &Summary) {
    println!("{:>5} {:>16} {:>10} {:>12} {:>9} {:>8}", "iter", "cost", "lambda", "|step|", "gain", "accepted");
    for l in &s.log {
        println!(
            "{:>5} {:>16.8e} {:>10.2e} {:>12.4e} {:>9.3} {:>8}",
            l.iteration, l.cost, l.lambda, l.step_norm, l.gain_ratio, l.accepted
        );
    }
}

impl SolveArgs {
    pub fn run(self) -> CliResult {
        let defaults = LmOptions::default();
        let lm = LmOptions {
            method: match self.method {
                MethodArg::Lm => Method::LevenbergMarquardt,
                MethodArg::Gn => Method::GaussNewton,
            },
            max_iterations: self.max_iterations,
            function_tolerance: self.function_tolerance,
            initial_lambda: self.initial_lambda,
            min_lambda_decrease: self.min_lambda_decrease,
            ..defaults
        };
        let opts = SolveFileOptions {
            lm,
            repair_information: self.repair_information,
            edge_error: match self.edge_error {
                EdgeErrorArg::Log => EdgeErrorChoice::Log,
                EdgeErrorArg::Ceres => EdgeErrorChoice::Ceres,
                EdgeErrorArg::CeresThenLog => EdgeErrorChoice::CeresThenLog,
            },
            plot: self.plot.is_some(),
        };
        let solved = solve_file(&self.file, &opts, &mut |line| println!("{line}"))?;
        for w in &solved.warnings {
            eprintln!("warning: {w}");
        }
        if let Some(first) = &solved.first_stage {
            println!("first stage, Ceres' quaternion edge error:");
            if self.verbose {
                print_log(first);
            }
            println!("{first}");
            println!(
                "both stages: {} iterations, {:.3} s; second stage, the log edge error from the first's solution:",
                first.iterations + solved.summary.iterations,
                first.time_total + solved.summary.time_total
            );
        }
        if self.verbose {
            print_log(&solved.summary);
        }
        println!("{}", solved.summary);
        println!("final chi2 {:.6}", 2.0 * solved.summary.final_cost);
        if let Some(png) = self.plot {
            solved.plot_top_view(&self.file, &png)?;
            println!("wrote {}", png.display());
        }
        Ok(())
    }
}

//! Shared pieces of tumble's benchmark programs: running each solver on a
//! problem file in a fresh process and reporting comparable figures.
//!
//! Every peer gets the same problem: the g2o edges with their information
//! matrices (permuted to each library's tangent order), GTSAM's between error
//! `Log(Z⁻¹ X₁⁻¹ X₂)`, the first pose fixed (tumble holds it constant; the peers
//! get a prior with σ = 1e-3 on it, as their own examples do). Final costs are
//! all re-evaluated by tumble's graph from each peer's solution, so the χ²
//! column means the same thing for everyone.

pub mod peers;

use serde_json::json;
use std::path::Path;
use std::time::Instant;
use tumble::io::{bal, g2o};
use tumble_solvers::{Graph, LmOptions, Optimizer, Values};

/// One solver's result on one problem.
#[derive(Clone, Debug, Default)]
pub struct Record {
    /// Problem name (file stem).
    pub problem: String,
    /// Solver name.
    pub solver: String,
    /// Free variables.
    pub variables: usize,
    /// Factors.
    pub factors: usize,
    /// Iterations reported by the solver (`None` when it does not report them).
    pub iterations: Option<usize>,
    /// χ² at the start (sum of squared whitened residuals).
    pub initial_chi2: f64,
    /// χ² at the end.
    pub final_chi2: f64,
    /// Median seconds of the optimize call.
    pub total_s: f64,
    /// Seconds in numeric factorization (tumble only; NaN for peers).
    pub factorize_s: f64,
    /// Peak resident memory of the worker process \[MB\].
    pub peak_rss_mb: f64,
    /// Why the solver did not run, if it did not.
    pub skipped: Option<String>,
}

impl Record {
    /// The JSON line the issue asks for.
    pub fn to_json(&self) -> String {
        json!({
            "problem": self.problem, "solver": self.solver, "variables": self.variables,
            "factors": self.factors, "iterations": self.iterations,
            "initial_chi2": self.initial_chi2, "final_chi2": self.final_chi2,
            "total_s": self.total_s, "factorize_s": if self.factorize_s.is_finite() { json!(self.factorize_s) } else { json!(null) },
            "peak_rss_mb": self.peak_rss_mb, "skipped": self.skipped,
        })
        .to_string()
    }
    /// Parse a line written by [`Record::to_json`].
    pub fn from_json(line: &str) -> Option<Record> {
        let v: serde_json::Value = serde_json::from_str(line).ok()?;
        let f = |k: &str| v[k].as_f64().unwrap_or(f64::NAN);
        Some(Record {
            problem: v["problem"].as_str()?.to_string(),
            solver: v["solver"].as_str()?.to_string(),
            variables: v["variables"].as_u64().unwrap_or(0) as usize,
            factors: v["factors"].as_u64().unwrap_or(0) as usize,
            iterations: v["iterations"].as_u64().map(|i| i as usize),
            initial_chi2: f("initial_chi2"),
            final_chi2: f("final_chi2"),
            total_s: f("total_s"),
            factorize_s: f("factorize_s"),
            peak_rss_mb: f("peak_rss_mb"),
            skipped: v["skipped"].as_str().map(|s| s.to_string()),
        })
    }
}

/// The numeric options of a benchmark's command line: for each `(flag,
/// default)` the number after the flag, or the default. Prints `usage` and
/// exits on `-h`/`--help`; exits with status 2, naming it, on any other
/// argument, a flag without a value or a value that is not a number.
pub fn numeric_args(usage: &str, flags: &[(&str, f64)]) -> Vec<f64> {
    args_with_switches(usage, flags, &[]).0
}

/// [`numeric_args`], and for each of `switches` (flags without a value,
/// such as `--no-peer`) whether it was given.
pub fn args_with_switches(usage: &str, flags: &[(&str, f64)], switches: &[&str]) -> (Vec<f64>, Vec<bool>) {
    let mut values: Vec<f64> = flags.iter().map(|f| f.1).collect();
    let mut given = vec![false; switches.len()];
    let mut args = std::env::args().skip(1);
    let fail = |why: String| -> ! {
        eprintln!("error: {why}\n{usage}");
        std::process::exit(2)
    };
    while let Some(a) = args.next() {
        if a == "-h" || a == "--help" {
            println!("{usage}");
            std::process::exit(0);
        }
        if let Some(k) = switches.iter().position(|s| *s == a) {
            given[k] = true;
            continue;
        }
        let Some(k) = flags.iter().position(|f| f.0 == a) else { fail(format!("unknown argument {a}")) };
        match args.next().map(|v| v.parse::<f64>()) {
            Some(Ok(v)) if v.is_finite() => values[k] = v,
            _ => fail(format!("{a} needs a number")),
        }
    }
    (values, given)
}

/// Peak resident set size of this process \[MB\] (Linux `VmHWM`).
pub fn peak_rss_mb() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines().find(|l| l.starts_with("VmHWM:")).and_then(|l| l.split_whitespace().nth(1)?.parse::<f64>().ok())
        })
        .map_or(f64::NAN, |kb| kb / 1024.0)
}

/// Median of a non-empty slice.
pub fn median(v: &mut [f64]) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

/// A problem loaded by tumble's readers.
pub struct TumbleProblem {
    /// The graph.
    pub graph: Graph,
    /// Initial values.
    pub values: Values,
    /// Solver options (Schur on points for BAL).
    pub options: LmOptions,
    /// Whether it is bundle adjustment.
    pub is_bal: bool,
}

/// Load a g2o or BAL file with tumble's readers; 3-D g2o edges get `edge_error`.
pub fn load(path: &Path, edge_error: g2o::EdgeError) -> Result<TumbleProblem, tumble::InputError> {
    let options = LmOptions { log_iterations: false, ..LmOptions::default() };
    if path.extension().is_some_and(|e| e == "g2o") {
        let opts = g2o::G2oOptions { edge_error, ..Default::default() };
        let pg = g2o::read_g2o(path, &opts)?;
        Ok(TumbleProblem { graph: pg.graph, values: pg.values, options, is_bal: false })
    } else {
        let p = bal::read_bal(path)?;
        Ok(TumbleProblem {
            graph: p.graph,
            values: p.values,
            options: LmOptions { eliminate: vec!['l'], ..options },
            is_bal: true,
        })
    }
}

/// Run tumble `repeat` times on a problem, under the solver name `solver`:
/// `"tumble"` (the log edge error, as the peers), `"tumble-ceres-error"`
/// (Ceres' `pose_graph_3d` edge error; its χ² is Ceres' cost, not comparable
/// with the others') or `"tumble-two-stage"` (Ceres' error, then the log
/// error from its solution: [`tumble::posegraph::solve_two_stage`]; χ² in the
/// log cost, times and iterations of both stages summed).
pub fn run_tumble(path: &Path, repeat: usize, solver: &str) -> Record {
    let name = problem_name(path);
    let log_error = solver == "tumble";
    let edge_error = if log_error { g2o::EdgeError::Log } else { g2o::EdgeError::CeresQuaternion };
    let p = match load(path, edge_error) {
        Ok(p) => p,
        Err(e) => return skipped(&name, solver, &e.to_string()),
    };
    let second = if solver == "tumble-two-stage" {
        match load(path, g2o::EdgeError::Log) {
            Ok(l) => Some(l),
            Err(e) => return skipped(&name, solver, &e.to_string()),
        }
    } else {
        None
    };
    let mut times = Vec::new();
    let mut fact = Vec::new();
    let mut last = None;
    for _ in 0..repeat.max(1) {
        let t = Instant::now();
        let r = match &second {
            None => Optimizer::new(p.options.clone()).optimize(&p.graph, &p.values).map(|(_, s)| (None, s)),
            Some(l) => tumble::posegraph::solve_two_stage(&p.graph, &l.graph, &p.values, &p.options)
                .map(|(_, first, second)| (Some(first), second)),
        };
        times.push(t.elapsed().as_secs_f64());
        match r {
            Ok((first, s)) => {
                fact.push(s.time_factorize + first.as_ref().map_or(0.0, |f| f.time_factorize));
                last = Some((first, s));
            }
            Err(e) => return skipped(&name, solver, &e.to_string()),
        }
    }
    let (first, s) = last.expect("at least one run");
    if std::env::var_os(SUMMARY_ENV).is_some() {
        if let Some(f) = &first {
            eprintln!("{name} (first stage): {f}");
        }
        eprintln!("{name}: {s}");
    }
    // χ² at the start in the cost the record reports.
    let initial_chi2 = match (&first, &second) {
        (Some(_), Some(l)) => l.graph.cost(&l.values).map_or(f64::NAN, |c| 2.0 * c),
        _ => 2.0 * s.initial_cost,
    };
    Record {
        problem: name,
        solver: solver.into(),
        variables: s.variables,
        factors: s.factors,
        iterations: Some(s.iterations + first.as_ref().map_or(0, |f| f.iterations)),
        initial_chi2,
        final_chi2: 2.0 * s.final_cost,
        total_s: median(&mut times),
        factorize_s: median(&mut fact),
        peak_rss_mb: peak_rss_mb(),
        skipped: None,
    }
}

/// Environment variable that makes tumble's workers print their solver
/// summary (time per phase) on stderr.
pub const SUMMARY_ENV: &str = "TUMBLE_BENCH_SUMMARY";

/// File stem of a problem.
pub fn problem_name(path: &Path) -> String {
    path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default()
}

/// A record saying the solver did not run.
pub fn skipped(problem: &str, solver: &str, why: &str) -> Record {
    Record {
        problem: problem.into(),
        solver: solver.into(),
        skipped: Some(why.into()),
        factorize_s: f64::NAN,
        ..Default::default()
    }
}

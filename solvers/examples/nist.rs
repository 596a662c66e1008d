//! The NIST StRD nonlinear regression suite (27 problems × 2 starts) on the
//! solver with its default options: one R^N variable, one factor per
//! observation with exact (automatic) Jacobians. Prints, per case, the
//! smallest LRE of the parameters against NIST's certified values (solved:
//! LRE ≥ 4), the cost, the termination and the time, then the totals — and,
//! when Python with scipy and sympy is there, MINPACK's LM and scipy's trf on
//! the same cases in the same run (`nist_scipy.py` beside this file).
//!
//! ```sh
//! cargo run --release -p tumble-solvers --example nist [-- DIR] [--no-peer]
//! ```
//!
//! DIR defaults to `$TUMBLE_DATA/nist` (the files as NIST publishes them).

use nalgebra::SVector;
use std::path::{Path, PathBuf};
use std::time::Instant;
use tumble_solvers::prelude::*;
use tumble_solvers::Termination;

/// One NIST problem: its data, starts and certified values.
struct Problem {
    name: String,
    /// Observations: the response and the predictors.
    y: Vec<f64>,
    x: Vec<Vec<f64>>,
    starts: [Vec<f64>; 2],
    certified: Vec<f64>,
    certified_rss: f64,
}

/// Parse a NIST `.dat` file; the error names the file and what is missing.
fn read_problem(path: &Path) -> Result<Problem, String> {
    let name = path.file_stem().and_then(|s| s.to_str()).unwrap_or("?").to_string();
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let lines: Vec<&str> = text.lines().collect();
    let nums = |l: &str| -> Vec<f64> { l.split_whitespace().filter_map(|t| t.parse().ok()).collect() };
    let (mut starts, mut certified) = ([Vec::new(), Vec::new()], Vec::new());
    for l in &lines {
        let t = l.trim_start();
        if t.starts_with('b') && t.contains('=') {
            let v = nums(t.split_once('=').map_or("", |x| x.1));
            if v.len() == 4 {
                starts[0].push(v[0]);
                starts[1].push(v[1]);
                certified.push(v[2]);
            }
        }
    }
    let rss = lines
        .iter()
        .find(|l| l.trim_start().starts_with("Residual Sum of Squares"))
        .and_then(|l| nums(l.split_once(':')?.1).first().copied())
        .ok_or_else(|| format!("{}: no certified residual sum of squares", path.display()))?;
    // The data follow the last line starting with "Data:" (the column header).
    let header = lines
        .iter()
        .rposition(|l| l.trim_start().starts_with("Data:"))
        .ok_or_else(|| format!("{}: no data section", path.display()))?;
    let (mut y, mut x) = (Vec::new(), Vec::new());
    for l in &lines[header + 1..] {
        let v = nums(l);
        if v.len() >= 2 {
            y.push(v[0]);
            x.push(v[1..].to_vec());
        }
    }
    if certified.is_empty() || y.is_empty() {
        return Err(format!("{}: no parameters or no data", path.display()));
    }
    Ok(Problem { name, y, x, starts, certified, certified_rss: rss })
}

/// The problems [`model`] knows.
const MODELS: [&str; 27] = [
    "Bennett5", "BoxBOD", "Chwirut1", "Chwirut2", "DanWood", "ENSO", "Eckerle4", "Gauss1", "Gauss2", "Gauss3", "Hahn1",
    "Kirby2", "Lanczos1", "Lanczos2", "Lanczos3", "MGH09", "MGH10", "MGH17", "Misra1a", "Misra1b", "Misra1c",
    "Misra1d", "Nelson", "Rat42", "Rat43", "Roszman1", "Thurber",
];

/// The model of problem `name` (one of [`MODELS`]) at parameters `b` and predictors `x`.
fn model<T: Real>(name: &str, b: &[T], x: &[f64]) -> T {
    let c = |v: f64| T::from(v);
    let x0 = x[0];
    let pi = std::f64::consts::PI;
    match name {
        "Misra1a" | "BoxBOD" => b[0] * (c(1.0) - (-b[1] * x0).exp()),
        "Misra1b" => b[0] * (c(1.0) - (c(1.0) + b[1] * (x0 / 2.0)).powi(-2)),
        "Misra1c" => b[0] * (c(1.0) - (c(1.0) + b[1] * (2.0 * x0)).powf(-0.5)),
        "Misra1d" => b[0] * b[1] * x0 / (c(1.0) + b[1] * x0),
        "Chwirut1" | "Chwirut2" => (-b[0] * x0).exp() / (b[1] + b[2] * x0),
        "DanWood" => b[0] * (b[1] * x0.ln()).exp(),
        "Lanczos1" | "Lanczos2" | "Lanczos3" => {
            b[0] * (-b[1] * x0).exp() + b[2] * (-b[3] * x0).exp() + b[4] * (-b[5] * x0).exp()
        }
        "Gauss1" | "Gauss2" | "Gauss3" => {
            let g = |a: T, m: T, s: T| a * (-((c(x0) - m) * (c(x0) - m)) / (s * s)).exp();
            b[0] * (-b[1] * x0).exp() + g(b[2], b[3], b[4]) + g(b[5], b[6], b[7])
        }
        "Kirby2" => (b[0] + b[1] * x0 + b[2] * (x0 * x0)) / (c(1.0) + b[3] * x0 + b[4] * (x0 * x0)),
        "Hahn1" | "Thurber" => {
            let (x2, x3) = (x0 * x0, x0 * x0 * x0);
            (b[0] + b[1] * x0 + b[2] * x2 + b[3] * x3) / (c(1.0) + b[4] * x0 + b[5] * x2 + b[6] * x3)
        }
        "Nelson" => b[0] - b[1] * x0 * (-b[2] * x[1]).exp(),
        "MGH17" => b[0] + b[1] * (-b[3] * x0).exp() + b[2] * (-b[4] * x0).exp(),
        "ENSO" => {
            let w = 2.0 * pi * x0;
            b[0] + b[1] * (w / 12.0).cos()
                + b[2] * (w / 12.0).sin()
                + b[4] * (c(w) / b[3]).cos()
                + b[5] * (c(w) / b[3]).sin()
                + b[7] * (c(w) / b[6]).cos()
                + b[8] * (c(w) / b[6]).sin()
        }
        "MGH09" => b[0] * (b[1] * x0 + x0 * x0) / (b[2] * x0 + b[3] + x0 * x0),
        "MGH10" => b[0] * (b[1] / (b[2] + x0)).exp(),
        "Eckerle4" => {
            let z = (c(x0) - b[2]) / b[1];
            b[0] / b[1] * (z * z * -0.5).exp()
        }
        "Rat42" => b[0] / (c(1.0) + (b[1] - b[2] * x0).exp()),
        "Rat43" => b[0] / ((c(1.0) + (b[1] - b[2] * x0).exp()).ln() / b[3]).exp(),
        "Bennett5" => b[0] * (-(b[1] + x0).ln() / b[2]).exp(),
        "Roszman1" => b[0] - b[1] * x0 - b[2].atan2(c(x0) - b[3]) / pi,
        _ => T::from(f64::NAN),
    }
}

/// One observation's residual: response − model (Nelson models log y).
struct Observation<const N: usize> {
    keys: [Key; 1],
    name: String,
    y: f64,
    x: Vec<f64>,
}

impl<const N: usize> AutoDiffResidual<N> for Observation<N> {
    fn keys(&self) -> &[Key] {
        &self.keys
    }
    fn residual_dim(&self) -> usize {
        1
    }
    fn residual<T: Real>(&self, p: &[&[T]]) -> Vec<T> {
        let y = if self.name == "Nelson" { self.y.ln() } else { self.y };
        vec![T::from(y) - model(&self.name, p[0], &self.x)]
    }
}

/// The result of one case.
struct Outcome {
    lre: f64,
    cost: f64,
    termination: Termination,
    /// The solver's own claim of a minimum ([`Summary::converged`]).
    converged: bool,
    iterations: usize,
    seconds: f64,
    /// The solver's scaled gradient at the end.
    scaled_gradient: f64,
}

/// Log relative error of `b` against `certified`, capped at 11 (as Ceres' table).
fn lre(b: f64, certified: f64) -> f64 {
    let rel = (b - certified).abs() / certified.abs();
    if rel == 0.0 {
        11.0
    } else {
        (-rel.log10()).clamp(0.0, 11.0)
    }
}

fn solve<const N: usize>(p: &Problem, start: &[f64], options: &LmOptions) -> Outcome {
    let mut graph = Graph::new();
    for (y, x) in p.y.iter().zip(&p.x) {
        graph.add(
            AutoDiff::<_, N>::new(Observation::<N> { keys: [X(0)], name: p.name.clone(), y: *y, x: x.clone() }),
            NoiseModel::Unit,
        );
    }
    let mut values = Values::new();
    values.insert(X(0), SVector::<f64, N>::from_column_slice(start));
    let t = Instant::now();
    let result = Optimizer::new(options.clone()).optimize(&graph, &values);
    let seconds = t.elapsed().as_secs_f64();
    match result {
        Ok((sol, s)) => {
            let b: &SVector<f64, N> = sol.get(X(0)).expect("the solution holds X(0)");
            let lre = b.iter().zip(&p.certified).map(|(b, c)| lre(*b, *c)).fold(f64::INFINITY, f64::min);
            Outcome {
                lre,
                cost: s.final_cost,
                termination: s.termination,
                converged: s.converged(),
                iterations: s.iterations,
                seconds,
                scaled_gradient: s.scaled_gradient,
            }
        }
        Err(_) => Outcome {
            lre: 0.0,
            cost: f64::NAN,
            termination: Termination::NoProgress,
            converged: false,
            iterations: 0,
            seconds,
            scaled_gradient: f64::NAN,
        },
    }
}

fn solve_any(p: &Problem, start: &[f64], options: &LmOptions) -> Outcome {
    match p.certified.len() {
        2 => solve::<2>(p, start, options),
        3 => solve::<3>(p, start, options),
        4 => solve::<4>(p, start, options),
        5 => solve::<5>(p, start, options),
        6 => solve::<6>(p, start, options),
        7 => solve::<7>(p, start, options),
        8 => solve::<8>(p, start, options),
        9 => solve::<9>(p, start, options),
        _ => Outcome {
            lre: 0.0,
            cost: f64::NAN,
            termination: Termination::NoProgress,
            converged: false,
            iterations: 0,
            seconds: 0.0,
            scaled_gradient: f64::NAN,
        },
    }
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let no_peer = args.iter().any(|a| a == "--no-peer");
    let dir = match args.iter().find(|a| !a.starts_with("--")) {
        Some(dir) => PathBuf::from(dir),
        None => match std::env::var_os("TUMBLE_DATA") {
            Some(root) => Path::new(&root).join("nist"),
            None => {
                println!("SKIPPED: give the NIST folder, or set TUMBLE_DATA (docs/datasets.md)");
                return;
            }
        },
    };
    let mut files: Vec<PathBuf> = match std::fs::read_dir(&dir) {
        Ok(d) => {
            d.filter_map(|e| e.ok().map(|e| e.path())).filter(|p| p.extension().is_some_and(|e| e == "dat")).collect()
        }
        Err(e) => {
            println!("SKIPPED: {}: {e} (the NIST StRD files, docs/datasets.md)", dir.display());
            return;
        }
    };
    files.sort();
    let mut options = LmOptions { log_iterations: false, ..LmOptions::default() };
    // Experiments: --set=NAME=VALUE overrides a default (initial_lambda,
    // function_tolerance, min_lambda_decrease, max_iterations, check_stationarity).
    for a in args.iter().filter_map(|a| a.strip_prefix("--set=")) {
        let (k, v) = a.split_once('=').unwrap_or((a, ""));
        let v: f64 = v.parse().unwrap_or(f64::NAN);
        match k {
            "initial_lambda" => options.initial_lambda = v,
            "function_tolerance" => options.function_tolerance = v,
            "min_lambda_decrease" => options.min_lambda_decrease = v,
            "max_iterations" => options.max_iterations = v as usize,
            "check_stationarity" => options.check_stationarity = v != 0.0,
            "min_gain_ratio" => options.min_gain_ratio = v,
            _ => println!("unknown option {k}"),
        }
    }
    println!(
        "{:<10} {:>5} {:>6} {:>14} {:>14} {:>5} {:>9}  termination",
        "problem", "start", "LRE", "cost", "certified", "iter", "time [ms]"
    );
    let (mut solved, mut wrong_converged, mut cases, mut total_s) = (0, 0, 0, 0.0);
    for f in &files {
        let p = match read_problem(f) {
            Ok(p) if !MODELS.contains(&p.name.as_str()) => {
                println!("SKIPPED: {}: no model for {}", f.display(), p.name);
                continue;
            }
            Ok(p) => p,
            Err(e) => {
                println!("SKIPPED: {e}");
                continue;
            }
        };
        for (k, start) in p.starts.iter().enumerate() {
            let o = solve_any(&p, start, &options);
            cases += 1;
            total_s += o.seconds;
            let ok = o.lre >= 4.0;
            solved += usize::from(ok);
            let flag = if !ok && o.converged {
                wrong_converged += 1;
                "  <- unsolved, reported as converged"
            } else {
                ""
            };
            println!(
                "{:<10} {:>5} {:>6.1} {:>14.6e} {:>14.6e} {:>5} {:>9.2}  {:?} (scaled gradient {:.1e}){flag}",
                p.name,
                k + 1,
                o.lre,
                2.0 * o.cost,
                p.certified_rss,
                o.iterations,
                1e3 * o.seconds,
                o.termination,
                o.scaled_gradient
            );
        }
    }
    println!(
        "\ntumble, {}: {solved} of {cases} solved (LRE >= 4), {wrong_converged} unsolved reported as converged, {:.3} s in all",
        if args.iter().any(|a| a.starts_with("--set=")) { "options as set" } else { "default options" },
        total_s
    );
    if no_peer {
        return;
    }
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/nist_scipy.py");
    match std::process::Command::new("python3").arg(&script).arg(&dir).output() {
        Ok(o) if o.status.success() => print!("\n{}", String::from_utf8_lossy(&o.stdout)),
        Ok(o) => println!(
            "\npeers skipped: {}",
            String::from_utf8_lossy(&o.stderr).lines().last().unwrap_or("python3 failed")
        ),
        Err(e) => println!("\npeers skipped: python3: {e}"),
    }
}

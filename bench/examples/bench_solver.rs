//! Solver benchmark: tumble against GTSAM (Python wheel, if installed), factrs,
//! tiny-solver and apex-solver on the same problems, each run in its own
//! process (so peak memory is its own).
//!
//! ```sh
//! cargo run --release -p tumble-bench --example bench_solver -- $TUMBLE_DATA/pose_graphs/*.g2o $TUMBLE_DATA/bal/*.txt
//! cargo run --release -p tumble-bench --example bench_solver -- --json --repeat 1 FILE...
//! ```
//! Prints per problem and solver: variables, factors, iterations, initial and
//! final χ² (sum of squared whitened residuals, all re-evaluated by tumble),
//! the median time of the optimize call, tumble's factorization time, peak RSS,
//! and the ratio of each time to tumble's.

use std::path::PathBuf;
use std::process::{Command, Stdio};
use tumble_bench::{peers, run_tumble, Record};

const SOLVERS: [&str; 5] = ["tumble", "gtsam", "factrs", "tiny-solver", "apex-solver"];

fn worker(solver: &str, file: &std::path::Path, repeat: usize) -> Record {
    match solver {
        "tumble" | "tumble-ceres-error" | "tumble-two-stage" => run_tumble(file, repeat, solver),
        "factrs" => peers::run_factrs(file, repeat),
        "tiny-solver" => peers::run_tiny(file, repeat),
        "apex-solver" => peers::run_apex(file, repeat),
        other => tumble_bench::skipped(&tumble_bench::problem_name(file), other, "unknown solver"),
    }
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.first().map(|s| s.as_str()) == Some("--worker") {
        let (solver, file, repeat) = (&args[1], PathBuf::from(&args[2]), args[3].parse().unwrap_or(3));
        println!("{}", worker(solver, &file, repeat).to_json());
        return;
    }
    let mut json = false;
    let mut repeat = 3usize;
    let mut solvers: Vec<String> = SOLVERS.iter().map(|s| s.to_string()).collect();
    let mut files = Vec::new();
    let mut it = args.iter();
    while let Some(a) = it.next() {
        match a.as_str() {
            "--json" => json = true,
            "--repeat" => repeat = it.next().and_then(|s| s.parse().ok()).unwrap_or(3),
            "--solvers" => solvers = it.next().map(|s| s.split(',').map(String::from).collect()).unwrap_or_default(),
            "-h" | "--help" => {
                println!("usage: bench_solver [--json] [--repeat N] [--solvers tumble,gtsam,factrs,tiny-solver,apex-solver] FILE...");
                println!("  also, for 3-D graphs: tumble-ceres-error (Ceres' pose_graph_3d edge error; its χ² is Ceres' cost),");
                println!("  tumble-two-stage (Ceres' error, then the log error from there; χ² in the log cost)");
                println!("  TUMBLE_BENCH_SUMMARY=1 also prints tumble's solver summary (time per phase) on stderr");
                return;
            }
            f => files.push(PathBuf::from(f)),
        }
    }
    if files.is_empty() {
        eprintln!("usage: bench_solver [--json] [--repeat N] [--solvers LIST] FILE...  (g2o or BAL files)");
        std::process::exit(2);
    }
    let exe = std::env::current_exe().expect("own path");
    if !json {
        println!(
            "{:<16} {:<18} {:>6} {:>6} {:>5} {:>14} {:>14} {:>9} {:>9} {:>8} {:>10}",
            "problem",
            "solver",
            "vars",
            "facts",
            "iters",
            "initial chi2",
            "final chi2",
            "total s",
            "factor s",
            "RSS MB",
            "vs tumble"
        );
    }
    // With TUMBLE_BENCH_SUMMARY the workers' stderr (tumble's summary) reaches the terminal.
    let summary = std::env::var_os(tumble_bench::SUMMARY_ENV).is_some();
    for file in &files {
        let mut tumble_time = f64::NAN;
        for solver in &solvers {
            let out = if solver == "gtsam" {
                // GTSAM through its Python wheel (pip install gtsam==4.3.0), same JSON line.
                let script = concat!(env!("CARGO_MANIFEST_DIR"), "/scripts/bench_gtsam.py");
                Command::new("python3")
                    .args([script, "--repeat", &repeat.to_string(), &file.to_string_lossy()])
                    .output()
            } else {
                Command::new(&exe)
                    .args(["--worker", solver, &file.to_string_lossy(), &repeat.to_string()])
                    .stderr(if summary { Stdio::inherit() } else { Stdio::piped() })
                    .output()
            };
            let rec = match out {
                Ok(o) => String::from_utf8_lossy(&o.stdout).lines().find_map(Record::from_json).unwrap_or_else(|| {
                    let err = String::from_utf8_lossy(&o.stderr);
                    let last = err.lines().rev().find(|l| !l.trim().is_empty()).unwrap_or("no output");
                    tumble_bench::skipped(&tumble_bench::problem_name(file), solver, &format!("worker failed: {last}"))
                }),
                Err(e) => tumble_bench::skipped(&tumble_bench::problem_name(file), solver, &e.to_string()),
            };
            if solver == "tumble" {
                tumble_time = rec.total_s;
            }
            if json {
                println!("{}", rec.to_json());
            } else if let Some(why) = &rec.skipped {
                println!("{:<16} {:<18} skipped: {why}", rec.problem, rec.solver);
            } else {
                println!(
                    "{:<16} {:<18} {:>6} {:>6} {:>5} {:>14.6} {:>14.6} {:>9.4} {:>9} {:>8.1} {:>9.2}x",
                    rec.problem,
                    rec.solver,
                    rec.variables,
                    rec.factors,
                    rec.iterations.map_or("-".to_string(), |i| i.to_string()),
                    rec.initial_chi2,
                    rec.final_chi2,
                    rec.total_s,
                    if rec.factorize_s.is_finite() { format!("{:.4}", rec.factorize_s) } else { "-".into() },
                    rec.peak_rss_mb,
                    rec.total_s / tumble_time
                );
            }
        }
    }
}

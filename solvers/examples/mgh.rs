//! Classic unconstrained least-squares test problems (Moré, Garbow & Hillstrom,
//! "Testing unconstrained optimization software", ACM TOMS 7(1), 1981), from
//! their standard starts, on the solver with its default options — a second
//! suite beside NIST (`examples/nist.rs`), so that no default is judged on one
//! collection. Each problem is one factor (all its residuals) on one R^n
//! variable with exact (automatic) Jacobians. Solved: the final sum of squares
//! within 1e-6 (relative) of one of the minima the paper lists, or below 1e-20
//! where that minimum is 0. A solve that is not solved but ends on a
//! tolerance is flagged as reported converged.
//!
//! ```sh
//! cargo run --release -p tumble-solvers --example mgh [-- --show NAME]
//! ```
//!
//! `--show NAME` prints that problem's solver summary and iteration log.

use nalgebra::SVector;
use std::time::Instant;
use tumble_solvers::prelude::*;
use tumble_solvers::Summary;

/// One test problem: residuals r(x), start and the minima of Σr² the paper lists.
struct Problem {
    name: &'static str,
    n: usize,
    m: usize,
    start: Vec<f64>,
    minima: Vec<f64>,
}

/// Bard's and Kowalik–Osborne's and Osborne 1's data.
const BARD_Y: [f64; 15] = [0.14, 0.18, 0.22, 0.25, 0.29, 0.32, 0.35, 0.39, 0.37, 0.58, 0.73, 0.96, 1.34, 2.10, 4.39];
const GAUSS_Y: [f64; 15] = [
    0.0009, 0.0044, 0.0175, 0.0540, 0.1295, 0.2420, 0.3521, 0.3989, 0.3521, 0.2420, 0.1295, 0.0540, 0.0175, 0.0044,
    0.0009,
];
const KO_Y: [f64; 11] = [0.1957, 0.1947, 0.1735, 0.1600, 0.0844, 0.0627, 0.0456, 0.0342, 0.0323, 0.0235, 0.0246];
const KO_U: [f64; 11] = [4.0, 2.0, 1.0, 0.5, 0.25, 0.167, 0.125, 0.1, 0.0833, 0.0714, 0.0625];
const OSB1_Y: [f64; 33] = [
    0.844, 0.908, 0.932, 0.936, 0.925, 0.908, 0.881, 0.850, 0.818, 0.784, 0.751, 0.718, 0.685, 0.658, 0.628, 0.603,
    0.580, 0.558, 0.538, 0.522, 0.506, 0.490, 0.478, 0.467, 0.457, 0.448, 0.438, 0.431, 0.424, 0.420, 0.414, 0.411,
    0.406,
];

fn problems() -> Vec<Problem> {
    let p = |name, n, m, start: &[f64], minima: &[f64]| Problem {
        name,
        n,
        m,
        start: start.to_vec(),
        minima: minima.to_vec(),
    };
    vec![
        p("Rosenbrock", 2, 2, &[-1.2, 1.0], &[0.0]),
        p("Freudenstein-Roth", 2, 2, &[0.5, -2.0], &[0.0, 48.9842]),
        p("Powell badly scaled", 2, 2, &[0.0, 1.0], &[0.0]),
        p("Brown badly scaled", 2, 3, &[1.0, 1.0], &[0.0]),
        p("Beale", 2, 3, &[1.0, 1.0], &[0.0]),
        p("Jennrich-Sampson", 2, 10, &[0.3, 0.4], &[124.362]),
        p("Helical valley", 3, 3, &[-1.0, 0.0, 0.0], &[0.0]),
        p("Bard", 3, 15, &[1.0, 1.0, 1.0], &[8.21487e-3, 17.4286]),
        p("Gaussian", 3, 15, &[0.4, 1.0, 0.0], &[1.12793e-8]),
        p("Box 3-D", 3, 10, &[0.0, 10.0, 20.0], &[0.0]),
        p("Powell singular", 4, 4, &[3.0, -1.0, 0.0, 1.0], &[0.0]),
        p("Wood", 4, 6, &[-3.0, -1.0, -3.0, -1.0], &[0.0]),
        p("Kowalik-Osborne", 4, 11, &[0.25, 0.39, 0.415, 0.39], &[3.07505e-4, 1.02734e-3]),
        p("Brown-Dennis", 4, 20, &[25.0, 5.0, -5.0, -1.0], &[85822.2]),
        p("Penalty I", 4, 5, &[1.0, 2.0, 3.0, 4.0], &[2.24997e-5]),
        p("Osborne 1", 5, 33, &[0.5, 1.5, -1.0, 0.01, 0.02], &[5.46489e-5]),
        p("Biggs EXP6", 6, 13, &[1.0, 2.0, 1.0, 1.0, 1.0, 1.0], &[5.65565e-3, 0.0]),
        p("Variably dimensioned", 10, 12, &(1..=10).map(|j| 1.0 - j as f64 / 10.0).collect::<Vec<_>>(), &[0.0]),
        p("Trigonometric", 10, 10, &[0.1; 10], &[0.0, 2.79506e-5]),
        p("Brown almost-linear", 10, 10, &[0.5; 10], &[0.0, 1.0]),
        p("Broyden tridiagonal", 10, 10, &[-1.0; 10], &[0.0]),
        p("Extended Rosenbrock", 10, 10, &[-1.2, 1.0, -1.2, 1.0, -1.2, 1.0, -1.2, 1.0, -1.2, 1.0], &[0.0]),
    ]
}

/// The residuals of problem `name` at `x`.
fn residuals<T: Real>(name: &str, x: &[T]) -> Vec<T> {
    let c = |v: f64| T::from(v);
    let n = x.len();
    match name {
        "Rosenbrock" => vec![(x[1] - x[0] * x[0]) * 10.0, c(1.0) - x[0]],
        "Freudenstein-Roth" => {
            vec![x[0] - 13.0 + ((c(5.0) - x[1]) * x[1] - 2.0) * x[1], x[0] - 29.0 + ((x[1] + 1.0) * x[1] - 14.0) * x[1]]
        }
        "Powell badly scaled" => vec![x[0] * x[1] * 1e4 - 1.0, (-x[0]).exp() + (-x[1]).exp() - 1.0001],
        "Brown badly scaled" => vec![x[0] - 1e6, x[1] - 2e-6, x[0] * x[1] - 2.0],
        "Beale" => [1.5, 2.25, 2.625]
            .iter()
            .enumerate()
            .map(|(i, y)| c(*y) - x[0] * (c(1.0) - x[1].powi(i as i32 + 1)))
            .collect(),
        "Jennrich-Sampson" => (1..=10)
            .map(|i| {
                let i = i as f64;
                c(2.0 + 2.0 * i) - ((x[0] * i).exp() + (x[1] * i).exp())
            })
            .collect(),
        "Helical valley" => {
            let theta = x[1].atan2(x[0]) / (2.0 * std::f64::consts::PI);
            vec![(x[2] - theta * 10.0) * 10.0, ((x[0] * x[0] + x[1] * x[1]).sqrt() - 1.0) * 10.0, x[2]]
        }
        "Bard" => (1..=15)
            .map(|i| {
                let (u, v) = (i as f64, 16.0 - i as f64);
                c(BARD_Y[i - 1]) - (x[0] + c(u) / (x[1] * v + x[2] * u.min(v)))
            })
            .collect(),
        "Gaussian" => (1..=15)
            .map(|i| {
                let t = (8.0 - i as f64) / 2.0;
                x[0] * ((x[1] * -0.5) * (c(t) - x[2]) * (c(t) - x[2])).exp() - GAUSS_Y[i - 1]
            })
            .collect(),
        "Box 3-D" => (1..=10)
            .map(|i| {
                let t = 0.1 * i as f64;
                (x[0] * -t).exp() - (x[1] * -t).exp() - x[2] * ((-t).exp() - (-10.0 * t).exp())
            })
            .collect(),
        "Powell singular" => vec![
            x[0] + x[1] * 10.0,
            (x[2] - x[3]) * 5f64.sqrt(),
            (x[1] - x[2] * 2.0).powi(2),
            (x[0] - x[3]).powi(2) * 10f64.sqrt(),
        ],
        "Wood" => vec![
            (x[1] - x[0] * x[0]) * 10.0,
            c(1.0) - x[0],
            (x[3] - x[2] * x[2]) * 90f64.sqrt(),
            c(1.0) - x[2],
            (x[1] + x[3] - 2.0) * 10f64.sqrt(),
            (x[1] - x[3]) / 10f64.sqrt(),
        ],
        "Kowalik-Osborne" => (0..11)
            .map(|i| {
                let u = KO_U[i];
                c(KO_Y[i]) - x[0] * (x[1] * u + u * u) / (x[2] * u + x[3] + u * u)
            })
            .collect(),
        "Brown-Dennis" => (1..=20)
            .map(|i| {
                let t = i as f64 / 5.0;
                (x[0] + x[1] * t - t.exp()).powi(2) + (x[2] + x[3] * t.sin() - t.cos()).powi(2)
            })
            .collect(),
        "Penalty I" => {
            let mut r: Vec<T> = x.iter().map(|&v| (v - 1.0) * 1e-5f64.sqrt()).collect();
            r.push(x.iter().fold(c(0.0), |s, &v| s + v * v) - 0.25);
            r
        }
        "Osborne 1" => (0..33)
            .map(|i| {
                let t = 10.0 * i as f64;
                c(OSB1_Y[i]) - (x[0] + x[1] * (x[3] * -t).exp() + x[2] * (x[4] * -t).exp())
            })
            .collect(),
        "Biggs EXP6" => (1..=13)
            .map(|i| {
                let t = 0.1 * i as f64;
                let y = (-t).exp() - 5.0 * (-10.0 * t).exp() + 3.0 * (-4.0 * t).exp();
                x[2] * (x[0] * -t).exp() - x[3] * (x[1] * -t).exp() + x[5] * (x[4] * -t).exp() - y
            })
            .collect(),
        "Variably dimensioned" => {
            let s = (0..n).fold(c(0.0), |s, j| s + (x[j] - 1.0) * (j + 1) as f64);
            let mut r: Vec<T> = x.iter().map(|&v| v - 1.0).collect();
            r.push(s);
            r.push(s * s);
            r
        }
        "Trigonometric" => {
            let sc = x.iter().fold(c(0.0), |s, &v| s + v.cos());
            (0..n).map(|i| c(n as f64) - sc + (c(1.0) - x[i].cos()) * (i + 1) as f64 - x[i].sin()).collect()
        }
        "Brown almost-linear" => {
            let s = x.iter().fold(c(0.0), |s, &v| s + v);
            let mut r: Vec<T> = (0..n - 1).map(|i| x[i] + s - (n + 1) as f64).collect();
            r.push(x.iter().fold(c(1.0), |p, &v| p * v) - 1.0);
            r
        }
        "Broyden tridiagonal" => (0..n)
            .map(|i| {
                let prev = if i > 0 { x[i - 1] } else { c(0.0) };
                let next = if i + 1 < n { x[i + 1] } else { c(0.0) };
                (c(3.0) - x[i] * 2.0) * x[i] - prev - next * 2.0 + 1.0
            })
            .collect(),
        "Extended Rosenbrock" => {
            (0..n).map(|i| if i % 2 == 0 { (x[i + 1] - x[i] * x[i]) * 10.0 } else { c(1.0) - x[i - 1] }).collect()
        }
        _ => vec![c(f64::NAN)],
    }
}

/// All residuals of one problem as one factor.
struct Residuals<const N: usize> {
    keys: [Key; 1],
    name: &'static str,
    m: usize,
}

impl<const N: usize> AutoDiffResidual<N> for Residuals<N> {
    fn keys(&self) -> &[Key] {
        &self.keys
    }
    fn residual_dim(&self) -> usize {
        self.m
    }
    fn residual<T: Real>(&self, p: &[&[T]]) -> Vec<T> {
        residuals(self.name, p[0])
    }
}

fn solve<const N: usize>(p: &Problem, options: &LmOptions) -> Option<(f64, Summary)> {
    let mut graph = Graph::new();
    graph.add(AutoDiff::<_, N>::new(Residuals::<N> { keys: [X(0)], name: p.name, m: p.m }), NoiseModel::Unit);
    let mut values = Values::new();
    values.insert(X(0), SVector::<f64, N>::from_column_slice(&p.start));
    let (_, s) = Optimizer::new(options.clone()).optimize(&graph, &values).ok()?;
    Some((2.0 * s.final_cost, s))
}

fn solve_any(p: &Problem, options: &LmOptions) -> Option<(f64, Summary)> {
    match p.n {
        2 => solve::<2>(p, options),
        3 => solve::<3>(p, options),
        4 => solve::<4>(p, options),
        5 => solve::<5>(p, options),
        6 => solve::<6>(p, options),
        10 => solve::<10>(p, options),
        _ => None,
    }
}

/// Whether `f` (a sum of squares) is one of the listed minima.
/// The listed minima carry six digits, so 1e-5 relative; a zero minimum is
/// reached when Σr² fell ten orders of magnitude below the start's `f0`.
fn reaches(f: f64, f0: f64, minima: &[f64]) -> bool {
    minima.iter().any(|&m| if m == 0.0 { f <= 1e-10 * f0 } else { ((f - m) / m).abs() <= 1e-5 })
}

fn main() {
    // The previous defaults, for comparison in the same run.
    let previous = LmOptions {
        function_tolerance: 1e-6,
        max_iterations: 100,
        check_stationarity: false,
        keep_largest_scale: false,
        trust_radius: false,
        log_iterations: false,
        ..LmOptions::default()
    };
    let args: Vec<String> = std::env::args().skip(1).collect();
    let show = args.iter().position(|a| a == "--show").and_then(|i| args.get(i + 1)).cloned();
    let runs = [("default options", LmOptions::default()), ("previous", previous)];
    println!(
        "{:<22} {:>3} {:>3} {:>13} {:>13} {:>5}  termination (default options); previous defaults: sum of squares",
        "problem", "n", "m", "Σr²", "listed", "iter"
    );
    let problems = problems();
    let mut totals = vec![(0usize, 0usize, 0.0f64); runs.len()];
    for p in &problems {
        let mut line = String::new();
        for (k, (_, o)) in runs.iter().enumerate() {
            let t = Instant::now();
            let outcome = solve_any(p, o);
            totals[k].2 += t.elapsed().as_secs_f64();
            let (f, s) = match outcome {
                Some(x) => x,
                None => {
                    line += "  (solver error)";
                    continue;
                }
            };
            let ok = reaches(f, 2.0 * s.initial_cost, &p.minima);
            if k == 0 && show.as_deref() == Some(p.name) {
                println!("{s}");
                for l in &s.log {
                    println!("  {l:?}");
                }
            }
            totals[k].0 += usize::from(ok);
            let wrong = !ok && s.converged();
            totals[k].1 += usize::from(wrong);
            if k == 0 {
                line = format!(
                    "{:<22} {:>3} {:>3} {:>13.6e} {:>13.6e} {:>5}  {:?}{}",
                    p.name,
                    p.n,
                    p.m,
                    f,
                    p.minima[0],
                    s.iterations,
                    s.termination,
                    if wrong { " <- unsolved, reported as converged" } else { "" }
                );
            } else {
                line += &format!(
                    ";  {f:.6e}{}",
                    if ok { String::new() } else { format!(" (unsolved, {:?})", s.termination) }
                );
            }
        }
        println!("{line}");
    }
    for ((name, _), (solved, wrong, secs)) in runs.iter().zip(&totals) {
        println!(
            "tumble, {name}: {solved} of {} solved, {wrong} unsolved reported as converged, {secs:.3} s in all",
            problems.len()
        );
    }
}

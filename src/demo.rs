//! `tumble demo`: the whole chain on simulated recordings with known truth —
//! calibrate a hand tumble, identify the noise from a static log, audit the
//! calibration for the effect hidden in the data, and estimate biases online
//! with a camera on the paper's 6-minute walk.
//!
//! ```no_run
//! let opts = tumble::demo::DemoOptions::default();
//! let report = tumble::demo::run(&opts, "tumble-demo".as_ref(), &mut |stage| eprintln!("{stage}")).unwrap();
//! print!("{}", report.table());
//! ```

use crate::calib::{CalibOptions, Triad};
use crate::pipeline::{run_chain, ChainInputs, ChainOptions, Progress, Status};
use crate::sim::{hide_effect, simulate, Scenario, SimConfig, TriadModel};
use crate::vio::{VioInput, VioOptions};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// What the demo simulates.
#[derive(Clone, Debug)]
pub struct DemoOptions {
    /// Effect hidden in the tumble recording, with its strength (see [`hide_effect`]).
    pub hidden: (String, f64),
    /// Seed of every simulation.
    pub seed: u64,
    /// Length of the static log for the Allan variance \[s\].
    pub static_s: f64,
    /// Length of the walk \[s\] (the paper's: 360).
    pub walk_s: f64,
    /// The walk: [`Scenario::Corridor`] (laps of a corridor at walking speed,
    /// the default) or [`Scenario::Walk`] (hand motion in a room).
    pub walk: Scenario,
}

impl Default for DemoOptions {
    fn default() -> Self {
        DemoOptions {
            hidden: ("g_sensitivity".into(), 2.0),
            seed: 1,
            static_s: 7200.0,
            walk_s: 360.0,
            walk: Scenario::Corridor,
        }
    }
}

/// One row of a truth-vs-estimate table.
#[derive(Clone, Debug)]
pub struct Row {
    /// What is compared.
    pub name: String,
    /// Simulated value.
    pub truth: f64,
    /// Estimate.
    pub estimate: f64,
    /// Its standard deviation (NaN when not given).
    pub std: f64,
    /// The estimate after the audit added the missing effect (and its σ), when there is one.
    pub audited: Option<(f64, f64)>,
}

/// Everything the demo measured.
#[derive(Clone, Debug)]
pub struct DemoReport {
    /// Calibrated parameters against the simulator's.
    pub calibration: Vec<Row>,
    /// Noise coefficients (largest axis, as in Kalibr's `imu.yaml`) against the simulator's.
    pub noise: Vec<Row>,
    /// The hidden effect and what the audit found.
    pub hidden: String,
    /// See `hidden`.
    pub found: Vec<String>,
    /// Audit gap before and after.
    pub gap: (f64, f64),
    /// Walk: distance walked (the ground truth's) \[m\], fused and IMU-only closed-loop error \[m\].
    pub walk: (f64, f64, f64),
    /// Walk: ATE \[m\], gyro and accel bias RMSE.
    pub walk_errors: (Option<f64>, Option<f64>, Option<f64>),
    /// Wall time per stage \[s\].
    pub stage_s: Vec<(String, f64)>,
    /// The chain's `report.md` with every table and figure.
    pub report: PathBuf,
}

fn triad_rows(out: &mut Vec<Row>, name: &str, truth: &TriadModel, est: &Triad, audited: &Triad) {
    let row = |n: String, truth: f64, get: &dyn Fn(&Triad) -> (f64, f64)| {
        let (e, s) = get(est);
        Row { name: n, truth, estimate: e, std: s, audited: Some(get(audited)) }
    };
    for (k, axis) in ["x", "y", "z"].iter().enumerate() {
        out.push(row(format!("{name} K_{axis}"), truth.scale[k], &|t| (t.k[k], t.k_std[k])));
    }
    for (k, axis) in ["x", "y", "z"].iter().enumerate() {
        out.push(row(format!("{name} b_{axis}"), truth.bias[k], &|t| (t.b[k], t.b_std[k])));
    }
    for (r, c) in [(0, 1), (0, 2), (1, 0), (1, 2), (2, 0), (2, 1)] {
        if name == "accel" && r > c {
            continue;
        }
        out.push(row(format!("{name} T_{r}{c}"), truth.misalignment[r][c], &|t| (t.t[(r, c)], t.t_std[(r, c)])));
    }
}

/// Simulate the three recordings and run the chain of [`crate::pipeline`] on
/// them into `out` (which gets `report.md`); `stage` is told what starts.
pub fn run(
    opts: &DemoOptions,
    out: &Path,
    stage: &mut dyn FnMut(&str),
) -> Result<DemoReport, crate::pipeline::ChainError> {
    if !matches!(opts.walk, Scenario::Walk | Scenario::Corridor) {
        return Err(format!("the demo walks in a room or a corridor, not {:?}", opts.walk).into());
    }
    let mut cfg = SimConfig::default();
    hide_effect(&mut cfg, &opts.hidden.0, opts.hidden.1)?;
    let t = std::time::Instant::now();
    stage(&format!(
        "simulating: a hand tumble, a {:.0}-minute static log and a {:.0}-minute walk with a camera, \
         one BMI055-like IMU with {} ×{} hidden",
        opts.static_s / 60.0,
        opts.walk_s / 60.0,
        opts.hidden.0,
        opts.hidden.1
    ));
    let tumble = simulate(Scenario::Tumble, &cfg, opts.seed)?;
    let still = simulate(Scenario::Static, &SimConfig { duration_s: Some(opts.static_s), ..cfg.clone() }, opts.seed)?;
    let wcfg = SimConfig { duration_s: Some(opts.walk_s), ..cfg.clone() };
    let walk = simulate(opts.walk, &wcfg, opts.seed)?;
    let simulate_s = t.elapsed().as_secs_f64();

    let inputs = ChainInputs {
        tumble: Some(tumble.imu.to_recording()),
        still: Some(still.imu.to_recording()),
        vio: Some(Box::new(move |cal| Ok(VioInput::from_simulation_calibrated(&walk, cal)?))),
        ..Default::default()
    };
    let chain_opts = ChainOptions {
        calib: CalibOptions { gravity: cfg.gravity, ..Default::default() },
        vio: VioOptions::for_simulation(&wcfg),
        bias_after_s: 20.0,
        ..Default::default()
    };
    let chain = run_chain(inputs, &chain_opts, out, &mut |p| {
        if let Progress::Stage(s, line) = p {
            stage(&format!("{}: {line}", s.id()));
        }
    })?;

    let cal = chain.calibration.as_ref().ok_or("the calibrate stage did not run")?;
    let audited = chain.audit.as_ref().ok_or("the audit stage did not run")?;
    let k = chain.allan.as_ref().and_then(|a| a.kalibr.as_ref()).ok_or("the Allan stage gave no noise coefficients")?;
    let (_, _, s) = chain.vio.as_ref().ok_or("the vio stage did not run")?;
    let max = |v: [f64; 3]| v.iter().fold(0.0f64, |a, b| a.max(*b));
    let noise_row = |name: &str, truth: [f64; 3], estimate: f64| Row {
        name: name.into(),
        truth: max(truth),
        estimate,
        std: f64::NAN,
        audited: None,
    };
    let noise = vec![
        noise_row("gyro N [rad/s/√Hz]", cfg.imu.gyro.noise_density, k.gyroscope_noise_density),
        noise_row("gyro K [rad/s²/√Hz]", cfg.imu.gyro.random_walk, k.gyroscope_random_walk),
        noise_row("accel N [m/s²/√Hz]", cfg.imu.accel.noise_density, k.accelerometer_noise_density),
        noise_row("accel K [m/s³/√Hz]", cfg.imu.accel.random_walk, k.accelerometer_random_walk),
    ];
    let mut calibration = Vec::new();
    let after = &audited.calibration;
    triad_rows(&mut calibration, "accel", &cfg.imu.accel, &cal.calibration.accel, &after.accel);
    triad_rows(&mut calibration, "gyro", &cfg.imu.gyro, &cal.calibration.gyro, &after.gyro);
    let mut stage_s = vec![("simulate".to_string(), simulate_s)];
    stage_s.extend(chain.stages.iter().filter_map(|st| match st.status {
        Status::Ran(secs) => Some((st.stage.id().to_string(), secs)),
        _ => None,
    }));
    Ok(DemoReport {
        calibration,
        noise,
        hidden: opts.hidden.0.clone(),
        found: audited.effects_added().iter().map(|e| e.id().to_string()).collect(),
        gap: (audited.base.gap(), audited.final_fit().gap()),
        walk: (s.walked_m(), s.closed_loop_error_m, s.imu_only_closed_loop_error_m),
        walk_errors: (s.ate_rmse_m, s.bias_rmse_gyro, s.bias_rmse_accel),
        stage_s,
        report: chain.report_path.clone(),
    })
}

impl DemoReport {
    /// The terminal table.
    pub fn table(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(
            s,
            "\ncalibration (hand tumble, raw = T K x + b): `calibrate` (eq. 1 only), then re-solved by the audit with the effect\n  \
             {:<12} {:>10} {:>10} {:>8} {:>6} {:>10} {:>8} {:>6}",
            "", "truth", "calibrate", "±1σ", "err/σ", "audited", "±1σ", "err/σ"
        );
        let z = |e: f64, t: f64, sd: f64| if sd > 0.0 { format!("{:.1}", (e - t) / sd) } else { "–".into() };
        for r in &self.calibration {
            let (a, sa) = r.audited.unwrap_or((f64::NAN, f64::NAN));
            let _ = writeln!(
                s,
                "  {:<12} {:>10.6} {:>10.6} {:>8.1e} {:>6} {:>10.6} {:>8.1e} {:>6}",
                r.name,
                r.truth,
                r.estimate,
                r.std,
                z(r.estimate, r.truth, r.std),
                a,
                sa,
                z(a, r.truth, sa)
            );
        }
        let _ = writeln!(s, "\nnoise (static log, Allan deviation, largest axis)");
        for r in &self.noise {
            let _ = writeln!(
                s,
                "  {:<22} {:>12.3e} {:>12.3e}   ({:+.0} %)",
                r.name,
                r.truth,
                r.estimate,
                100.0 * (r.estimate / r.truth - 1.0)
            );
        }
        let found = if self.found.is_empty() { "nothing".to_string() } else { self.found.join(", ") };
        let (g0, g1) = self.gap;
        let _ = writeln!(
            s,
            "\naudit: hidden {}, found {found}; gap {g0:.3} → {g1:.3} ({:.0} % smaller)",
            self.hidden,
            if g0 > 0.0 { 100.0 * (1.0 - g1 / g0) } else { 0.0 }
        );
        let (d, fused, imu) = self.walk;
        let _ = writeln!(
            s,
            "\nwalk: {d:.1} m walked, back at the start: fused error {fused:.3} m ({:.2} %), IMU only {imu:.1} m",
            100.0 * fused / d.max(1e-9)
        );
        if let (Some(ate), Some(bg), Some(ba)) = self.walk_errors {
            let _ = writeln!(s, "      ATE {ate:.3} m, bias RMSE gyro {bg:.2e} rad/s, accel {ba:.2e} m/s²");
        }
        let times: Vec<String> = self.stage_s.iter().map(|(n, t)| format!("{n} {t:.1} s")).collect();
        let _ = writeln!(s, "\ntime: {}", times.join(", "));
        let _ = writeln!(s, "report with figures: {}", self.report.display());
        s
    }
}

//! Turntable-free calibration: simulated recordings with known truth, the two
//! real imu_tk data sets against imu_tk's printed results, and bad recordings.

mod common;

use nalgebra::{Matrix3, Vector3};
use tumble::calib::{calibrate, CalibOptions, CalibrationResult, ImuCalibration, Triad};
use tumble::sim::{simulate, Scenario, SimConfig};

/// (estimate − truth) / std for every free parameter of one triad, and the
/// largest absolute misalignment/scale error.
#[allow(clippy::needless_range_loop)]
fn normalized_errors(
    est: &Triad,
    truth_t: &[[f64; 3]; 3],
    truth_k: &[f64; 3],
    truth_b: &[f64; 3],
    upper: bool,
) -> (Vec<f64>, f64) {
    let mut z = Vec::new();
    let mut worst: f64 = 0.0;
    for r in 0..3 {
        for c in 0..3 {
            if r == c || (upper && r > c) {
                continue;
            }
            let e = est.t[(r, c)] - truth_t[r][c];
            worst = worst.max(e.abs());
            z.push(e / est.t_std[(r, c)]);
        }
        let e = est.k[r] - truth_k[r];
        worst = worst.max(e.abs());
        z.push(e / est.k_std[r]);
        z.push((est.b[r] - truth_b[r]) / est.b_std[r]);
    }
    (z, worst)
}

fn sim_config() -> SimConfig {
    SimConfig::default()
}

/// Upper 95 % quantile of χ² with `n` degrees of freedom (Wilson–Hilferty).
fn chi2_95(n: f64) -> f64 {
    let a = 2.0 / (9.0 * n);
    n * (1.0 - a + 1.644_854 * a.sqrt()).powi(3)
}

fn run_seed(cfg: &SimConfig, seed: u64) -> (CalibrationResult, tumble::sim::Simulation) {
    let sim = simulate(Scenario::Tumble, cfg, seed).unwrap();
    let rec = sim.imu.to_recording();
    let res = calibrate(&rec, &CalibOptions { gravity: cfg.gravity, ..Default::default() }).unwrap();
    (res, sim)
}

#[test]
fn simulated_bmi055_errors_match_reported_uncertainty() {
    let cfg = sim_config();
    let m = &cfg.imu;
    let mut za = Vec::new();
    let mut zg = Vec::new();
    let (mut worst_a, mut worst_g) = (0.0f64, 0.0f64);
    for seed in 0..20 {
        let (res, sim) = run_seed(&cfg, seed);
        let c = &res.calibration;
        // The simulator's turn-on bias is the constant part; random walk and
        // instability move it, so compare with the mean true bias of the recording.
        let mean_bias = |v: &[[f64; 3]]| -> [f64; 3] {
            let n = v.len() as f64;
            [0, 1, 2].map(|k| v.iter().map(|s| s[k]).sum::<f64>() / n)
        };
        let ba = mean_bias(&sim.imu.bias_accel);
        let n_init = sim.imu.bias_gyro.len() * 50 / (sim.imu.t.len() / 200).max(1);
        let bg = mean_bias(&sim.imu.bias_gyro[..n_init.min(sim.imu.bias_gyro.len())]);
        let (z, w) = normalized_errors(&c.accel, &m.accel.misalignment, &m.accel.scale, &ba, true);
        za.extend(z);
        worst_a = worst_a.max(w);
        let (z, w) = normalized_errors(&c.gyro, &m.gyro.misalignment, &m.gyro.scale, &bg, false);
        zg.extend(z);
        worst_g = worst_g.max(w);
        eprintln!(
            "seed {seed}: {} intervals, accel χ²/dof {:.2}, gyro χ²/dof {:.2}",
            res.intervals.len(),
            res.accel_fit.chi2_per_dof,
            res.gyro_fit.chi2_per_dof
        );
    }
    for (name, z) in [("accel", &za), ("gyro", &zg)] {
        let chi2: f64 = z.iter().map(|x| x * x).sum();
        let n = z.len() as f64;
        eprintln!("{name}: Σz² = {chi2:.1} over {n} normalized errors (95 % bound {:.1})", chi2_95(n));
        assert!(chi2 < chi2_95(n), "{name}: errors exceed their reported uncertainty: Σz² = {chi2:.1}");
        // Reported uncertainties must not be wildly pessimistic either.
        assert!(chi2 > 0.5 * n, "{name}: reported uncertainties too large: Σz² = {chi2:.1} over {n}");
    }
    // With the paper's Table 1 noise a 3-minute tumble determines misalignment
    // and scale to ≈ 1e-3 (the reported σ); the 2e-4 of the issue needs ≈ 25× more data.
    eprintln!("worst misalignment/scale error: accel {worst_a:.2e}, gyro {worst_g:.2e}");
    assert!(worst_a < 6e-3 && worst_g < 1e-2);
}

/// imu_tk's printed result on its Xsens sample data (raw counts), `calibrated = T·K·(raw − b)`.
const XSENS_ACC: ([[f64; 3]; 3], [f64; 3], [f64; 3]) = (
    [[1.0, -0.0033593, -0.00890639], [0.0, 1.0, -0.0213341], [0.0, 0.0, 1.0]],
    [0.00241278, 0.00242712, 0.00241168],
    [33124.2, 33275.2, 32364.4],
);
const XSENS_GYRO: ([[f64; 3]; 3], [f64; 3], [f64; 3]) = (
    [[1.0, 0.00593634, 0.00111101], [0.00808812, 1.0, -0.0535569], [0.0253067, -0.0025513, 1.0]],
    [2.09295e-4, 2.09899e-4, 2.09483e-4],
    [32777.1, 32459.8, 32511.8],
);

/// Largest |ΔT|, relative |ΔK| and relative |Δb| between our triad (in imu_tk's convention) and imu_tk's.
fn imu_tk_diff(ours: &Triad, theirs: &([[f64; 3]; 3], [f64; 3], [f64; 3])) -> (f64, f64, f64) {
    let (t, k, b) = ours.to_imu_tk().unwrap();
    let dt = (0..9).map(|i| (t[(i / 3, i % 3)] - theirs.0[i / 3][i % 3]).abs()).fold(0.0, f64::max);
    let dk = (0..3).map(|i| (k[i] / theirs.1[i] - 1.0).abs()).fold(0.0, f64::max);
    let db = (0..3).map(|i| (b[i] / theirs.2[i] - 1.0).abs()).fold(0.0, f64::max);
    (dt, dk, db)
}

fn read_pair(dir: &std::path::Path, acc: &str, gyr: &str, raw: bool) -> tumble::io::ImuRecording {
    use tumble::io::{AccelUnit, GyroUnit, RecordingOptions, TimeUnit};
    let mut o = RecordingOptions::default();
    o.format.time_unit = TimeUnit::S;
    if raw {
        o.format.accel_unit = AccelUnit::Counts { scale: None, offset: 0.0 };
        o.format.gyro_unit = GyroUnit::Counts { scale: None, offset: 0.0 };
    }
    o.gyro_file = Some(dir.join(gyr));
    tumble::io::open_recording(&dir.join(acc), &o).unwrap()
}

#[test]
fn xsens_agrees_with_imu_tk_and_factory_gains() {
    let Some(dir) = common::shared("imu_tk_xsens") else { return };
    let rec = read_pair(&dir, "xsens_acc.mat", "xsens_gyro.mat", true);
    let res = calibrate(&rec, &CalibOptions { gravity: 9.81744, ..Default::default() }).unwrap();
    let c = &res.calibration;
    let (dt, dk, db) = imu_tk_diff(&c.accel, &XSENS_ACC);
    eprintln!("accel vs imu_tk: |ΔT| {dt:.2e}, |ΔK|/K {dk:.2e}, |Δb|/b {db:.2e}");
    assert!(dt < 5e-4 && dk < 1e-3 && db < 1e-3);
    let (dt, dk, db) = imu_tk_diff(&c.gyro, &XSENS_GYRO);
    eprintln!("gyro vs imu_tk: |ΔT| {dt:.2e}, |ΔK|/K {dk:.2e}, |Δb|/b {db:.2e}");
    assert!(dt < 5e-4 && dk < 1e-3 && db < 1e-3);
    // Xsens factory gains [counts per SI unit] are the paper's K.
    for (k, f) in c.accel.k.iter().zip([415.0, 413.0, 415.0]) {
        assert!((k / f - 1.0).abs() < 0.01, "accel gain {k} vs factory {f}");
    }
    for (k, f) in c.gyro.k.iter().zip([4778.0, 4758.0, 4766.0]) {
        assert!((k / f - 1.0).abs() < 0.01, "gyro gain {k} vs factory {f}");
    }
    eprintln!(
        "imu_tk-style costs: accel {:.4} (100 samples per interval), gyro {:.6}",
        res.accel_fit.imu_tk_cost, res.gyro_fit.imu_tk_cost
    );
    // Its accelerometer drifts inside the poses (z ≈ 19×, the norm ≈ 11× the
    // white scatter): said, with what moves.
    let w = res.warnings.iter().find(|w| w.starts_with("inside the static poses")).expect("a stillness warning");
    assert!(w.contains("accel z") && w.contains("|accel|") && !w.contains("gyro"), "{w}");
}

#[test]
fn t265_agrees_with_imu_tk_within_uncertainty() {
    let Some(dir) = common::shared("imu_tk_t265") else { return };
    let rec = read_pair(&dir, "t265_acc.mat", "t265_gyr.mat", false);
    assert!(rec.warnings.iter().any(|w| w.contains("duplicated timestamps")));
    let res = calibrate(&rec, &CalibOptions { gravity: 9.8016, ..Default::default() }).unwrap();
    // A knock at 6.9 s tilts the IMU: the initial rest found is the longer one after it.
    let rest = &res.initial_rest;
    assert!(rest.detected && rest.start_s > 6.8 && rest.end_s - rest.start_s > 45.0, "{rest:?}");
    // The poses are axis-aligned and x never points up but once: the x misalignments are
    // at best weakly determined, and the verdict says so.
    assert_eq!(res.assessment.verdict, tumble::calib::Verdict::Weak, "{:?}", res.assessment);
    let their = |f: &str| tumble::calib::read_imu_tk_calib(&dir.join(f)).unwrap();
    for (ours, (t, k, b), name) in [
        (&res.calibration.accel, their("t265_test_imu_acc.calib"), "accel"),
        (&res.calibration.gyro, their("t265_test_imu_gyro.calib"), "gyro"),
    ] {
        let theirs = Triad::from_imu_tk(&t, &k, &b).unwrap();
        // This recording determines the scales only to ≈ 0.1 % and the misalignments
        // to ≈ 1e-2 (our reported σ; imu_tk's log gives none): agreement within 3σ
        // (scales: or 0.15 %; measured 0.07, 0.07, 0.13 % for the accelerometer).
        for i in 0..3 {
            let dk = (ours.k[i] - theirs.k[i]).abs();
            eprintln!(
                "{name} K{i}: {:.6} vs imu_tk {:.6} ({:.3} %, σ {:.3} %)",
                ours.k[i],
                theirs.k[i],
                100.0 * dk / theirs.k[i],
                100.0 * ours.k_std[i] / ours.k[i]
            );
            assert!(
                dk < (3.0 * ours.k_std[i]).max(1.5e-3 * ours.k[i]),
                "{name} K{i}: {} vs {}",
                ours.k[i],
                theirs.k[i]
            );
            assert!((ours.b[i] - theirs.b[i]).abs() < 3.0 * ours.b_std[i].max(1e-4), "{name} b{i}");
            for j in 0..3 {
                let d = (ours.t[(i, j)] - theirs.t[(i, j)]).abs();
                assert!(
                    d <= 3.0 * ours.t_std[(i, j)] + 1e-12,
                    "{name} T{i}{j}: {d:.2e} vs σ {:.2e}",
                    ours.t_std[(i, j)]
                );
            }
        }
    }
}

fn tumble_recording(seed: u64) -> tumble::io::ImuRecording {
    simulate(Scenario::Tumble, &SimConfig::default(), seed).unwrap().imu.to_recording()
}

#[track_caller]
fn error_of(rec: &tumble::io::ImuRecording) -> String {
    match calibrate(rec, &CalibOptions { gravity: 9.81, ..Default::default() }) {
        Ok(r) => panic!("calibrated a bad recording ({} intervals)", r.intervals.len()),
        Err(e) => e.to_string(),
    }
}

#[test]
fn bad_recordings_give_clear_errors() {
    let rec = tumble_recording(3);
    // No initial static period: the recording starts with the tumbling. A given
    // --init-static is checked and refused; without it the longest early hold is used.
    let tumbling = rec.slice_time(50.5, 1e9);
    let given = CalibOptions { gravity: 9.81, init_static_s: Some(5.0), ..Default::default() };
    let e = calibrate(&tumbling, &given).unwrap_err().to_string();
    assert!(e.contains("not static") && e.contains("line"), "{e}");
    let r = calibrate(&tumbling, &CalibOptions { gravity: 9.81, ..Default::default() }).unwrap();
    assert!(r.initial_rest.detected && r.initial_rest.end_s - r.initial_rest.start_s < 3.5, "{:?}", r.initial_rest);
    // Motion that never stops.
    let mut never = rec.clone();
    for i in 0..never.len() {
        let t = never.t[i];
        if t > 50.0 {
            never.accel[i][0] += (t * 7.0).sin() * 5.0;
            never.gyro[i][1] += (t * 5.0).sin() * 1.5;
        }
    }
    let e = error_of(&never);
    assert!(e.contains("usable static intervals") && e.contains("hint"), "{e}");
    // All poses alike: only the initial period and repeats of it.
    let mut alike = rec.clone();
    let n = alike.len();
    let calm = alike.accel[..n / 4].to_vec();
    let calm_g = alike.gyro[..n / 4].to_vec();
    for i in 0..n {
        alike.accel[i] = calm[i % calm.len()];
        alike.gyro[i] = calm_g[i % calm_g.len()];
        if (i / 500) % 2 == 1 && alike.t[i] > 50.0 {
            alike.accel[i][0] += ((i % 500) as f64 * 0.05).sin();
        }
    }
    let e = error_of(&alike);
    // The fits are ill-posed here; the refusal names the poses, before or after fitting.
    assert!(
        e.contains("do not excite")
            || e.contains("usable static intervals")
            || e.contains("gravity by more")
            || (e.contains("calibration failed") && e.contains("not determined by these poses")),
        "{e}"
    );
    // A NaN sample.
    let mut nan = rec.clone();
    nan.accel[1234][2] = f64::NAN;
    assert!(error_of(&nan).contains("sample 1234"));
    // Too short.
    let short = rec.slice_time(0.0, 40.0);
    assert!(error_of(&short).contains("usable static intervals"));
    let given = CalibOptions { gravity: 9.81, init_static_s: Some(50.0), ..Default::default() };
    assert!(calibrate(&short, &given).unwrap_err().to_string().contains("initial static period"));
}

#[test]
fn apply_inverts_the_model_and_files_round_trip() {
    let dir = std::env::temp_dir().join(format!("tumble-apply-{}", std::process::id()));
    let sim = simulate(Scenario::Tumble, &SimConfig::default(), 5).unwrap();
    let rec = sim.imu.to_recording();
    let opts = CalibOptions { gravity: 9.81, ..Default::default() };
    let res = calibrate(&rec, &opts).unwrap();
    let files = res.write_all(&rec, &opts, &dir).unwrap();
    assert_eq!(files.len(), 5);
    // calibration.json reads back bit for bit (serde_json's `float_roundtrip`:
    // its default parser may miss by an ulp, which a VIO run amplifies).
    let back = ImuCalibration::read(&dir.join("calibration.json")).unwrap();
    for (a, b) in [(&back.accel, &res.calibration.accel), (&back.gyro, &res.calibration.gyro)] {
        assert_eq!((a.t, a.k, a.b), (b.t, b.k, b.b));
    }
    let yaml = ImuCalibration::read(&dir.join("calibration.yaml")).unwrap();
    assert!((yaml.gyro.k - res.calibration.gyro.k).amax() < 1e-12);
    // Eq. 16 undoes eq. 1 for a noise-free sample.
    let m = &sim.config.imu.gyro;
    let t = Matrix3::from_fn(|r, c| m.misalignment[r][c]);
    let w = Vector3::new(0.3, -0.2, 0.5);
    let raw = t * Matrix3::from_diagonal(&Vector3::from(m.scale)) * w + res.calibration.gyro.b;
    let corrected = res.calibration.corrector().unwrap().gyro([raw.x, raw.y, raw.z]);
    assert!((Vector3::from(corrected) - w).amax() < 5e-3, "{corrected:?}");
    // Bad calibration files are refused with the file named.
    std::fs::write(dir.join("bad.json"), "{\"T_a\": 3}").unwrap();
    let e = ImuCalibration::read(&dir.join("bad.json")).unwrap_err().to_string();
    assert!(e.contains("bad.json"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A tumble with other settings, seeds 1..=n, calibrated with the defaults.
fn tumble_with(
    settings: tumble::sim::TumbleSettings,
    seeds: u64,
) -> Vec<(tumble::sim::Simulation, Result<CalibrationResult, tumble::calib::CalibError>)> {
    let cfg = SimConfig { tumble: settings, ..SimConfig::default() };
    (1..=seeds)
        .map(|seed| {
            let sim = simulate(Scenario::Tumble, &cfg, seed).unwrap();
            let r = calibrate(&sim.imu.to_recording(), &CalibOptions { gravity: cfg.gravity, ..Default::default() });
            (sim, r)
        })
        .collect()
}

/// Σz² of the scales and misalignments against the simulator's truth, and their count.
fn scale_errors(
    sims: &[(tumble::sim::Simulation, Result<CalibrationResult, tumble::calib::CalibError>)],
) -> (f64, f64) {
    let m = &SimConfig::default().imu;
    let mut z = Vec::new();
    for (_, r) in sims {
        let c = &r.as_ref().unwrap().calibration;
        for (est, truth) in [(&c.accel, &m.accel), (&c.gyro, &m.gyro)] {
            for a in 0..3 {
                z.push((est.k[a] - truth.scale[a]) / est.k_std[a]);
                for b in 0..3 {
                    if a != b && est.t_std[(a, b)] > 0.0 {
                        z.push((est.t[(a, b)] - truth.misalignment[a][b]) / est.t_std[(a, b)]);
                    }
                }
            }
        }
    }
    (z.iter().map(|x| x * x).sum(), z.len() as f64)
}

#[test]
fn axis_aligned_poses_report_what_they_cannot_determine() {
    // Six faces up and down, quarter turns about the body axes (Ferraris et al.):
    // gravity's norm cannot separate the accelerometer's misalignments from its scales.
    let settings =
        tumble::sim::TumbleSettings { initial_static_s: 10.0, poses: 30, axis_aligned: true, ..Default::default() };
    let sims = tumble_with(settings, 4);
    for (sim, r) in &sims {
        let r = r.as_ref().unwrap_or_else(|e| panic!("seed {}: {e}", sim.seed));
        let a = &r.assessment;
        eprintln!("seed {}: {} {:?}", sim.seed, a.verdict, a.reasons);
        assert_eq!(a.verdict, tumble::calib::Verdict::Weak);
        for name in ["accelerometer T[0][1]", "accelerometer T[0][2]", "accelerometer T[1][2]"] {
            assert!(a.not_determined.iter().any(|n| n == name), "{name} not reported: {:?}", a.not_determined);
        }
        // Near the prior of no misalignment, with about the prior's σ.
        let (t, sd) = (&r.calibration.accel.t, &r.calibration.accel.t_std);
        assert!(t[(0, 1)].abs() < 2.0 * sd[(0, 1)] && (0.025..0.06).contains(&sd[(0, 1)]), "{t} ± {sd}");
        // The gyro does not wander to an alias of its scale.
        let k = r.calibration.gyro.k;
        assert!((k - Vector3::from(SimConfig::default().imu.gyro.scale)).amax() < 0.05, "gyro K {k}");
    }
    let (chi2, n) = scale_errors(&sims);
    eprintln!("axis-aligned: Σz² = {chi2:.1} over {n}");
    assert!(chi2 < chi2_95(n), "errors exceed their reported uncertainty: Σz² = {chi2:.1} over {n}");
}

#[test]
fn slow_turns_are_not_taken_for_poses() {
    // A careful hand: turns at 0.5 rad/s on average (a quarter turn in 3 s). Mid-turn
    // the rate is flat and the accelerometer moves slowly, so the windowed variances
    // stay low; measured by their norm, which the noisiest axis rules (the BMI055's
    // gyro z is 5× as noisy as its x and y), a turn that the other axes saw hid under
    // it, and turns were counted as poses (12 seeds: Σz² 191 over 180 now).
    let settings = tumble::sim::TumbleSettings { turn_rate: 0.5, ..Default::default() };
    let sims = tumble_with(settings.clone(), 12);
    for (sim, r) in &sims {
        let r = r.as_ref().unwrap_or_else(|e| panic!("seed {}: {e}", sim.seed));
        assert_eq!(r.intervals.len(), settings.poses + 1, "seed {}", sim.seed);
    }
    let (chi2, n) = scale_errors(&sims);
    eprintln!("slow turns: Σz² = {chi2:.1} over {n}");
    assert!(chi2 < chi2_95(n), "errors exceed their reported uncertainty: Σz² = {chi2:.1} over {n}");
}

#[test]
fn short_holds_and_a_short_initial_rest_calibrate_with_warnings() {
    // Holds of 0.6–0.9 s (the paper asks ≥ 1 s) after a 4 s initial rest.
    let settings = tumble::sim::TumbleSettings { initial_static_s: 4.0, hold_s: [0.6, 0.9], ..Default::default() };
    let sims = tumble_with(settings, 4);
    for (sim, r) in &sims {
        let r = r.as_ref().unwrap_or_else(|e| panic!("seed {}: {e}", sim.seed));
        assert_ne!(r.assessment.verdict, tumble::calib::Verdict::Failed);
        assert!(r.warnings.iter().any(|w| w.contains("poses were held")), "{:?}", r.warnings);
        assert!(r.warnings.iter().any(|w| w.contains("initial rest lasts")), "{:?}", r.warnings);
        let rest = &r.initial_rest;
        // Half a window (0.25 s) is cut where the first turn starts slowly.
        assert!(rest.detected && rest.start_s == 0.0 && (3.4..4.0).contains(&rest.end_s), "{rest:?}");
    }
    let (chi2, n) = scale_errors(&sims);
    eprintln!("short holds: Σz² = {chi2:.1} over {n}");
    assert!(chi2 < chi2_95(n), "errors exceed their reported uncertainty: Σz² = {chi2:.1} over {n}");
}

#[test]
fn a_knock_in_the_initial_rest_does_not_end_it() {
    let mut rec = tumble_recording(2);
    // A knock at 20 s: 50 ms of shaking at 2 g that leaves the IMU where it was.
    for i in 0..rec.len() {
        if (20.0..20.05).contains(&rec.t[i]) {
            rec.accel[i][0] += 20.0 * ((rec.t[i] - 20.0) * 300.0).sin();
            rec.gyro[i][1] += 0.3 * ((rec.t[i] - 20.0) * 300.0).sin();
        }
    }
    let r = calibrate(&rec, &CalibOptions { gravity: 9.81, ..Default::default() }).unwrap();
    let rest = &r.initial_rest;
    assert!(rest.detected && rest.start_s == 0.0 && (rest.end_s - 50.0).abs() < 0.5, "{rest:?}");
    let span = ((rest.end_s - rest.start_s) * 200.0).round() as usize + 1;
    assert!(rest.samples + 10 < span, "the knock is cut out: {rest:?}");
}

#[test]
fn a_failed_calibration_is_an_error_with_a_diagnosis_and_no_loadable_file() {
    // A gyro in deg/s read as rad/s: no scale near 1 explains the turns.
    let mut rec = tumble_recording(4);
    for g in &mut rec.gyro {
        *g = g.map(|x| x.to_degrees());
    }
    let e = calibrate(&rec, &CalibOptions { gravity: 9.81, ..Default::default() }).unwrap_err();
    assert!(e.message.contains("calibration failed") && e.message.contains("gyroscope"), "{}", e.message);
    let d = e.diagnosis.expect("a diagnosis");
    assert_eq!(d.assessment.verdict, tumble::calib::Verdict::Failed);
    let dir = std::env::temp_dir().join(format!("tumble-failed-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let files = d.write_all(&rec, &CalibOptions { gravity: 9.81, ..Default::default() }, &dir).unwrap();
    let names: Vec<String> = files.iter().map(|f| f.file_name().unwrap().to_string_lossy().into_owned()).collect();
    assert_eq!(names, ["diagnosis.json", "static_detection.png"]);
    assert!(!dir.join("calibration.json").exists() && !dir.join("imu_tk_gyro.calib").exists());
    // Renamed, it is still refused.
    let renamed = dir.join("calibration.json");
    std::fs::copy(dir.join("diagnosis.json"), &renamed).unwrap();
    let e = ImuCalibration::read(&renamed).unwrap_err().to_string();
    assert!(e.contains("failed its verdict"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The recording checks itself: on clean simulated tumbles the halves agree
/// as honest σ predict (RMS normalized difference near 1, nothing flagged);
/// with a temperature warm-up hidden in the sensor (its scales move along the
/// recording, which the model lacks) the halves disagree, the σ of what
/// they disagree on widen, and the verdict says so. (Smaller warm-ups — the
/// temperature bias ×3 or ×10, the scale ×5 — stay within the σ, which the
/// fits' χ²/dof already widen, and are not flagged.)
#[test]
fn the_halves_of_a_recording_check_its_sigma() {
    let cfg = sim_config();
    let mut rms = Vec::new();
    for seed in 0..4 {
        let (res, _) = run_seed(&cfg, seed);
        let split = res.split.as_ref().expect("a simulated tumble has enough poses for the check");
        println!("clean seed {seed}: halves' RMS z {:.2}, {:?}", split.rms_z(), split.describe_disagreements());
        assert!(split.disagreements().is_empty(), "seed {seed}: {:?}", split.describe_disagreements());
        rms.push(split.rms_z());
    }
    let mean = rms.iter().sum::<f64>() / rms.len() as f64;
    assert!((0.5..1.6).contains(&mean), "mean RMS z of clean halves {mean}");
    let mut warm = sim_config();
    // The temperature scale coefficients ×20: the warm-up moves the gyro's x
    // scale by ≈ 1.2 % between the halves.
    tumble::sim::hide_effect(&mut warm, "temperature_scale", 20.0).unwrap();
    let (res, _) = run_seed(&warm, 1);
    let split = res.split.as_ref().unwrap();
    let widest = split.parameters.iter().map(|p| p.sigma_after / p.sigma_before).fold(1.0, f64::max);
    println!(
        "warm-up: halves' RMS z {:.2}, σ widened up to {widest:.1}×, {:?}",
        split.rms_z(),
        split.describe_disagreements()
    );
    assert!(widest > 2.0, "{split:?}");
    assert!(split.disagreements().iter().any(|p| p.parameter.starts_with("gyroscope scale")), "{split:?}");
    assert!(res.assessment.reasons.iter().any(|r| r.contains("the halves disagree")), "{:?}", res.assessment);
}

/// The same recording gives the same calibration, to the last bit, however
/// the threads happen to split the work: every sum over turns is taken in the
/// turns' order (a parallel reduce grouped its terms differently from run to
/// run, and the demo's walk then closed anywhere between 0.32 and 0.41 m).
#[test]
fn repeated_calibrations_are_identical() {
    let rec = tumble_recording(3);
    let opts = CalibOptions { gravity: 9.81, ..Default::default() };
    // Debug prints every f64 in its shortest exact form: equal strings, equal bits.
    let runs: Vec<String> = (0..6).map(|_| format!("{:?}", calibrate(&rec, &opts).unwrap())).collect();
    assert!(runs.iter().all(|r| *r == runs[0]), "the calibrations of one recording differ between runs");
}

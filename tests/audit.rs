//! The model-discrepancy audit on simulated tumble recordings with a hidden
//! effect: it must name the effect first and shrink the gap by ≥ 80 % on 10
//! seeds (different motions) each; add nothing on ≥ 95 % of clean recordings;
//! find both of two hidden effects; and refuse bad input with clear errors.
//!
//! Effect sizes: the simulator's BMI055 coefficients times a strength chosen so
//! the effect matters in a 4-minute tumble (see `tumble::sim::hide_effect`).

use tumble::audit::{audit, Audit, AuditOptions, Effect};
use tumble::calib::{calibrate, CalibOptions, ImuCalibration};
use tumble::sim::{hide_effect, simulate, Scenario, SimConfig};
use tumble::vio::ImuNoise;

fn run(hidden: &[(&str, f64)], seed: u64) -> (Audit, SimConfig) {
    let mut cfg = SimConfig::default();
    for (e, s) in hidden {
        hide_effect(&mut cfg, e, *s).unwrap();
    }
    let sim = simulate(Scenario::Tumble, &cfg, seed).unwrap();
    let rec = sim.imu.to_recording();
    let cal = calibrate(&rec, &CalibOptions { gravity: cfg.gravity, ..Default::default() }).unwrap();
    let opts = AuditOptions { noise: Some(ImuNoise::from_model(&cfg.imu)), ..Default::default() };
    (audit(&rec, &cal.calibration, &opts).unwrap(), cfg)
}

fn finds(name: &str, strength: f64, effect: Effect) {
    let mut failures = Vec::new();
    for seed in 100..110 {
        let (a, _) = run(&[(name, strength)], seed);
        let found = a.effects_added();
        let (g0, g1) = (a.base.gap(), a.iterations.first().map(|i| i.gap_after).unwrap_or(a.base.gap()));
        let shrink = if g0 > 0.0 { 1.0 - g1 / g0 } else { 0.0 };
        println!("{name} ×{strength} seed {seed}: {found:?}, gap {g0:.3} → {g1:.3} ({:.0} %)", 100.0 * shrink);
        if found.first() != Some(&effect) || shrink < 0.8 {
            failures.push(format!("seed {seed}: found {found:?}, gap {g0:.3} → {g1:.3}"));
        }
    }
    assert!(failures.is_empty(), "{name}: {failures:?}");
}

#[test]
fn finds_gyro_g_sensitivity() {
    finds("g_sensitivity", 2.0, Effect::GyroGSensitivity);
}

#[test]
fn finds_temperature_bias() {
    finds("temperature_bias", 2.0, Effect::TemperatureBias);
}

#[test]
fn finds_temperature_scale() {
    finds("temperature_scale", 5.0, Effect::TemperatureScale);
}

#[test]
fn finds_gyro_scale_nonlinearity() {
    finds("gyro_nonlinearity", 4.0, Effect::GyroScaleNonlinearity);
}

#[test]
fn finds_accel_scale_nonlinearity() {
    finds("accel_nonlinearity", 2.0, Effect::AccelScaleNonlinearity);
}

#[test]
fn finds_bias_drift() {
    finds("bias_drift", 3.0, Effect::BiasDrift);
}

#[test]
fn adds_nothing_to_clean_recordings() {
    let seeds: Vec<u64> = (200..220).collect();
    let mut added = Vec::new();
    for &seed in &seeds {
        let (a, _) = run(&[], seed);
        println!("clean seed {seed}: {}", a.verdict());
        if !a.iterations.is_empty() {
            added.push((seed, a.effects_added()));
        }
    }
    // ≥ 95 %: at most one of 20.
    assert!(added.len() <= seeds.len() / 20, "effects added on clean data: {added:?}");
}

#[test]
fn finds_two_hidden_effects_and_fits_their_size() {
    for seed in [300, 301, 302] {
        let (a, cfg) = run(&[("g_sensitivity", 2.0), ("accel_nonlinearity", 1.0)], seed);
        let found = a.effects_added();
        println!("seed {seed}: {}", a.verdict());
        assert!(
            found.contains(&Effect::GyroGSensitivity) && found.contains(&Effect::AccelScaleNonlinearity),
            "{found:?}"
        );
        assert!(a.final_fit().gap() < 0.2 * a.base.gap());
        // The fitted g-sensitivity is the simulator's (in the calibrated frame, M_g·G ≈ G).
        let it = a.iterations.iter().find(|i| i.effect == Effect::GyroGSensitivity).unwrap();
        let truth = cfg.imu.g_sensitivity.as_flattened();
        let j = a.final_fit().layout.effects.iter().position(|e| *e == Effect::GyroGSensitivity).unwrap();
        let fitted = a.final_fit().effect(j);
        for (k, (v, t)) in fitted.iter().zip(truth).enumerate() {
            let s = it.score.params_std[k];
            assert!((v - t).abs() < 5.0 * s + 2e-5, "G[{k}] = {v:.2e} ± {s:.1e}, truth {t:.2e}");
        }
    }
}

#[test]
fn calibration_with_effects_round_trips_and_corrects_samples() {
    let (a, cfg) = run(&[("g_sensitivity", 2.0)], 400);
    assert_eq!(a.effects_added(), vec![Effect::GyroGSensitivity]);
    let dir = std::env::temp_dir().join(format!("tumble_audit_{}", std::process::id()));
    let files = tumble::audit::report::write(&a, &dir).unwrap();
    for f in ["audit.json", "audit.md", "calibration.json", "audit_gap.png", "audit_gyro_g_sensitivity.png"] {
        assert!(files.iter().any(|x| x == f) && dir.join(f).metadata().unwrap().len() > 0, "{f}");
    }
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("audit.json")).unwrap()).unwrap();
    assert_eq!(json["effects_added"][0], "gyro_g_sensitivity");
    assert!(json["iterations"][0]["gap_before"].as_f64().unwrap() > json["final_gap"].as_f64().unwrap());
    assert!(json["iterations"][0]["params"]["G_xx"].is_number());
    let cal = ImuCalibration::read(&dir.join("calibration.json")).unwrap();
    assert_eq!(cal.effect_ids(), vec!["gyro_g_sensitivity".to_string()]);
    // A static sample: with the effect the corrected rate loses G·a.
    let corr = cal.corrector().unwrap();
    assert!(corr.has_effects());
    let g = cfg.imu.g_sensitivity;
    let raw_a = [0.0, 0.0, 9.81];
    let raw_g = [cal.gyro.b.x + g[0][2] * 9.81, cal.gyro.b.y + g[1][2] * 9.81, cal.gyro.b.z + g[2][2] * 9.81];
    let (_, plain) = (corr.accel(raw_a), corr.gyro(raw_g));
    let (_, full) = corr.sample(raw_a, raw_g, None, 0.0);
    let norm = |v: [f64; 3]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
    assert!(norm(plain) > 1.5e-3, "{plain:?}");
    assert!(norm(full) < 0.5 * norm(plain), "{full:?} vs {plain:?}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn bad_input_gives_clear_errors() {
    let cfg = SimConfig::default();
    let sim = simulate(Scenario::Tumble, &cfg, 7).unwrap();
    let rec = sim.imu.to_recording();
    let cal = calibrate(&rec, &CalibOptions { gravity: 9.81, ..Default::default() }).unwrap().calibration;
    // Accelerometer misalignment that is not upper triangular.
    let mut bad = cal.clone();
    bad.accel.t[(2, 0)] = 0.05;
    let e = audit(&rec, &bad, &AuditOptions::default()).err().expect("lower-triangular T_a must be refused");
    assert!(e.0.contains("upper triangular"), "{e}");
    // A recording that is all static: no intervals to compare.
    let still = simulate(Scenario::Static, &SimConfig { duration_s: Some(120.0), ..SimConfig::default() }, 1).unwrap();
    let e =
        audit(&still.imu.to_recording(), &cal, &AuditOptions::default()).err().expect("a static log cannot be audited");
    assert!(e.0.contains("static intervals"), "{e}");
    // Non-finite temperature.
    let mut hot = SimConfig::default();
    hide_effect(&mut hot, "temperature_bias", 1.0).unwrap();
    let sim = simulate(Scenario::Tumble, &hot, 7).unwrap();
    let mut rec = sim.imu.to_recording();
    let cal = calibrate(&rec, &CalibOptions { gravity: 9.81, ..Default::default() }).unwrap().calibration;
    rec.temperature.as_mut().unwrap()[20_000] = f64::NAN;
    let e = audit(&rec, &cal, &AuditOptions::default()).err().expect("NaN temperature must be refused");
    assert!(e.0.contains("temperature") && e.0.contains("not finite"), "{e}");
    // A constant temperature column: the temperature effects cannot be tested, and it says so.
    let sim = simulate(Scenario::Tumble, &cfg, 7).unwrap();
    let mut flat = sim.imu.to_recording();
    flat.temperature = Some(vec![25.0; flat.len()]);
    let cal7 = calibrate(&flat, &CalibOptions { gravity: 9.81, ..Default::default() }).unwrap().calibration;
    let a = audit(&flat, &cal7, &AuditOptions::default()).unwrap();
    assert!(a.notes.iter().any(|n| n.contains("varies by only")), "{:?}", a.notes);
    // Unknown effects in a calibration file name the effect.
    let dir = std::env::temp_dir().join(format!("tumble_audit_bad_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mut file = serde_json::to_value(tumble::calib::model::CalibrationFile::from(&cal)).unwrap();
    file["effects"] = serde_json::json!({"reference_temperature_c": 20.0, "reference_time_s": 0.0,
        "effects": [{"id": "gyro_warp_drive", "params": {"x": 1.0}}]});
    let p = dir.join("calibration.json");
    std::fs::write(&p, serde_json::to_string(&file).unwrap()).unwrap();
    let e = ImuCalibration::read(&p).expect_err("unknown effect must be refused").to_string();
    assert!(e.contains("gyro_warp_drive") && e.contains("calibration.json"), "{e}");
    file["effects"]["effects"][0] = serde_json::json!({"id": "bias_drift", "params": {"accel_x": 1.0}});
    std::fs::write(&p, serde_json::to_string(&file).unwrap()).unwrap();
    let e = ImuCalibration::read(&p).expect_err("missing parameters must be refused").to_string();
    assert!(e.contains("lacks parameter"), "{e}");
    std::fs::remove_dir_all(&dir).ok();
}

/// The demo chain (shortened): calibrate → allan → audit → vio on simulated data.
#[test]
fn demo_chain_finds_the_hidden_effect() {
    let opts = tumble::demo::DemoOptions { static_s: 1200.0, walk_s: 40.0, ..Default::default() };
    let mut stages = Vec::new();
    let dir = std::env::temp_dir().join(format!("tumble_demo_test_{}", std::process::id()));
    let r = tumble::demo::run(&opts, &dir, &mut |s| stages.push(s.to_string())).unwrap();
    assert_eq!(stages.len(), 5, "{stages:?}");
    let report = std::fs::read_to_string(&r.report).unwrap();
    assert!(report.contains("![audit/audit_gyro_g_sensitivity.png]") && report.contains("ATE"), "{report}");
    assert_eq!(r.found, vec!["gyro_g_sensitivity".to_string()]);
    assert!(r.gap.1 < 0.2 * r.gap.0, "{:?}", r.gap);
    assert!(r.walk.0 > 1.0 && r.walk.1.is_finite());
    let table = r.table();
    assert!(table.contains("gyro_g_sensitivity") && table.contains("accel K_x"), "{table}");
    // The audited calibration is closer to the truth than eq. (1) alone for the gyro biases.
    let err = |rows: &[tumble::demo::Row], audited: bool| -> f64 {
        rows.iter()
            .filter(|r| r.name.starts_with("gyro b_"))
            .map(|r| (if audited { r.audited.unwrap().0 } else { r.estimate } - r.truth).powi(2))
            .sum::<f64>()
    };
    assert!(err(&r.calibration, true) < err(&r.calibration, false));
    std::fs::remove_dir_all(&dir).ok();
    // The walk is a room or a corridor; anything else is refused before any work.
    let flight = tumble::demo::DemoOptions { walk: tumble::sim::Scenario::Flight, ..opts };
    let e = tumble::demo::run(&flight, &dir, &mut |_| {}).expect_err("a flight is no walk").to_string();
    assert!(e.contains("room or a corridor"), "{e}");
}

//! One sensor, several recordings (`tumble calibrate --inputs`): simulated
//! tumbles of one IMU with a different power-on bias each, pooled against
//! the truth; a recording whose sensor differs is flagged; bad inputs; the
//! joint audit (`tumble audit --inputs`) telling an effect of the sensor from
//! one recording's.

use tumble::calib::{calibrate_recordings, CalibOptions, RecordingsResult, Verdict};
use tumble::io::ImuRecording;
use tumble::sim::{simulate, Scenario, SimConfig};

/// Recording `i` of the default simulated IMU: its own seed and power-on
/// biases; `gyro_scale_y` changes that one scale (1: the same sensor).
fn recording(i: u64, gyro_scale_y: f64) -> ImuRecording {
    let mut cfg = SimConfig::default();
    let shift = [0.02, -0.03, 0.01].map(|s| s * (i as f64 + 1.0));
    for (k, s) in shift.iter().enumerate() {
        cfg.imu.accel.bias[k] += s;
        cfg.imu.gyro.bias[k] += 1e-3 * s;
    }
    cfg.imu.gyro.scale[1] *= gyro_scale_y;
    simulate(Scenario::Tumble, &cfg, 40 + i).unwrap().imu.to_recording()
}

fn pool(recs: &[ImuRecording]) -> RecordingsResult {
    let names: Vec<String> = (1..=recs.len()).map(|i| format!("day {i}")).collect();
    calibrate_recordings(recs, &names, &CalibOptions { gravity: 9.81, ..Default::default() }).unwrap()
}

#[test]
fn recordings_of_one_sensor_pool_to_its_truth() {
    let recs: Vec<ImuRecording> = (0..3).map(|i| recording(i, 1.0)).collect();
    let r = pool(&recs);
    let truth = SimConfig::default().imu;
    eprint!("{}", r.summary_table());
    assert!(r.check.disagreements().is_empty(), "{:?}", r.check.disagreement_lines());
    assert!(r.check.rms_pairwise_z() < 2.0, "RMS pairwise z {:.2}", r.check.rms_pairwise_z());
    let c = &r.calibration;
    let mut z2 = Vec::new();
    for k in 0..3 {
        z2.push(((c.accel.k[k] - truth.accel.scale[k]) / c.accel.k_std[k]).powi(2));
        z2.push(((c.gyro.k[k] - truth.gyro.scale[k]) / c.gyro.k_std[k]).powi(2));
        // The pool knows more than any one recording.
        let each_best = r.each.iter().map(|e| e.calibration.gyro.k_std[k]).fold(f64::INFINITY, f64::min);
        assert!(c.gyro.k_std[k] < each_best, "gyro scale {k}: pooled σ {:.2e} vs {each_best:.2e}", c.gyro.k_std[k]);
    }
    for (r_, c_) in [(0, 1), (0, 2), (1, 2), (1, 0), (2, 0), (2, 1)] {
        if c.gyro.t_std[(r_, c_)] > 0.0 {
            z2.push(((c.gyro.t[(r_, c_)] - truth.gyro.misalignment[r_][c_]) / c.gyro.t_std[(r_, c_)]).powi(2));
        }
    }
    let rms = (z2.iter().sum::<f64>() / z2.len() as f64).sqrt();
    eprintln!("pooled scales and gyro misalignments against the truth: RMS z {rms:.2} over {}", z2.len());
    assert!(rms < 2.0 && z2.iter().all(|z| *z < 16.0), "{z2:?}");
    // The biases: their consensus with the spread between power-ons in its σ.
    let spread = r.biases.get("accelerometer bias y").unwrap();
    assert!(spread.tau > 0.01 && c.accel.b_std[1] >= spread.tau, "{spread:?}");
    let dir = std::env::temp_dir().join(format!("tumble-recordings-{}", std::process::id()));
    let names: Vec<String> = (1..=3).map(|i| format!("day {i}")).collect();
    let files = r.write_all(&recs, &names, &CalibOptions { gravity: 9.81, ..Default::default() }, &dir).unwrap();
    for f in ["calibration.json", "recordings.md", "recordings.png", "recording_2_day_2/calibration.json"] {
        assert!(dir.join(f).is_file() && files.contains(&dir.join(f)), "{f} not written");
    }
    let read = tumble::calib::ImuCalibration::read(&dir.join("calibration.json")).unwrap();
    assert!((read.gyro.k[1] - c.gyro.k[1]).abs() < 1e-9);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_recording_of_another_scale_is_flagged_and_covered() {
    let recs = [recording(0, 1.0), recording(1, 1.0), recording(2, 1.01)];
    let r = pool(&recs);
    let lines = r.check.disagreement_lines();
    eprintln!("{lines:#?}");
    assert!(lines.iter().any(|l| l.starts_with("gyroscope scale y")), "{lines:?}");
    assert_eq!(r.assessment.verdict.max(Verdict::Weak), r.assessment.verdict);
    let p = r.check.get("gyroscope scale y").unwrap();
    // The widened σ covers the recordings it pools.
    let worst = p.values.iter().map(|v| (v - p.value).abs()).fold(0.0, f64::max);
    assert!(p.tau > 0.0 && worst < 3.0 * p.sigma.hypot(p.tau), "{p:?}");
}

#[test]
fn what_cannot_be_pooled_is_refused() {
    let one = [recording(0, 1.0)];
    let e = calibrate_recordings(&one, &["a".into()], &CalibOptions { gravity: 9.81, ..Default::default() });
    assert!(e.unwrap_err().message.contains("1 given"));
    let mut counts = recording(1, 1.0);
    counts.gyro_units = tumble::io::Stored::RawCounts;
    let two = [recording(0, 1.0), counts];
    let e = calibrate_recordings(&two, &["a".into(), "b".into()], &CalibOptions::default()).unwrap_err();
    assert!(e.message.contains("one raw unit"), "{}", e.message);
}

/// Recording `seed` of the default IMU, with its g-sensitivity on (`hidden`)
/// or off, and the simulator's configuration.
fn tumble_with_g_sensitivity(seed: u64, hidden: bool) -> (ImuRecording, SimConfig) {
    let mut cfg = SimConfig::default();
    if hidden {
        tumble::sim::hide_effect(&mut cfg, "g_sensitivity", 2.0).unwrap();
    }
    (simulate(Scenario::Tumble, &cfg, seed).unwrap().imu.to_recording(), cfg)
}

/// `tumble audit --inputs`: each recording audited with its own calibration.
fn joint_audit(recs: &[ImuRecording]) -> tumble::audit::RecordingsAudit {
    let r = pool(recs);
    let names: Vec<String> = (1..=recs.len()).map(|i| format!("day {i}")).collect();
    let cals: Vec<_> = r.each.iter().map(|e| e.calibration.clone()).collect();
    let opts = tumble::audit::AuditOptions::default();
    tumble::audit::audit_recordings(recs, &cals, &names, &r.calibration, &opts, &mut |_| {}).unwrap()
}

#[test]
fn an_effect_of_the_sensor_repeats_and_an_accident_of_one_recording_does_not() {
    let (a, cfg) = tumble_with_g_sensitivity(5, true);
    let (b, _) = tumble_with_g_sensitivity(6, true);
    let (c, _) = tumble_with_g_sensitivity(7, false);
    // In both recordings: repeats, added with pooled coefficients near the truth.
    let both = joint_audit(&[a.clone(), b]);
    eprintln!("{:#?}", both.verdict_lines());
    let g = both.effects.iter().find(|e| e.effect == "gyro_g_sensitivity").expect("found");
    assert!(g.repeats && g.added_in == [true, true], "{:?}", both.verdict_lines());
    let term = &both.calibration.effects.as_ref().unwrap().effects[0];
    assert_eq!(term.id, "gyro_g_sensitivity");
    let z: Vec<f64> = ["x", "y", "z"]
        .iter()
        .enumerate()
        .flat_map(|(r, rn)| {
            let term = &term;
            let truth = cfg.imu.g_sensitivity[r];
            ["x", "y", "z"].iter().enumerate().map(move |(c, cn)| {
                let k = format!("G_{rn}{cn}");
                (term.params[&k] - truth[c]) / term.std[&k]
            })
        })
        .collect();
    eprintln!("pooled G against the truth, z: {z:.2?}");
    assert!(z.iter().all(|z| z.abs() < 4.0), "{z:?}");
    // In one recording of two: the other's coefficient says it is not there; not added.
    let one = joint_audit(&[a, c]);
    eprintln!("{:#?}", one.verdict_lines());
    let g = one.effects.iter().find(|e| e.effect == "gyro_g_sensitivity").expect("found");
    assert!(!g.repeats && !g.agree && g.added_in == [true, false], "{:?}", one.verdict_lines());
    assert!(one.calibration.effects.is_none());
}

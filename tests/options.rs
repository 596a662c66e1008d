//! Options are validated once, in the library, before any work: a bad value
//! is refused with the option named, never silently changed.

use tumble::calib::{calibrate, CalibOptions};
use tumble::io::{open_recording, RecordingOptions};
use tumble::sim::{simulate, Scenario, SimConfig};
use tumble::vio::VioOptions;

#[test]
fn min_intervals_means_what_it_says() {
    let sim = simulate(Scenario::Tumble, &SimConfig::default(), 1).unwrap();
    let rec = sim.imu.to_recording();
    let e = calibrate(&rec, &CalibOptions { gravity: 9.81, min_intervals: 6, ..Default::default() }).unwrap_err();
    assert!(e.to_string().contains("--min-intervals must be at least 10"), "{e}");
    assert!(CalibOptions { min_intervals: 10, ..Default::default() }.validate().is_ok());
}

#[test]
fn a_nominal_rate_must_be_a_positive_number() {
    let dir = scratch("rate");
    let f = dir.join("imu.csv");
    std::fs::write(&f, "0,0,0,0,0,0,9.81\n5000000,0,0,0,0,0,9.81\n10000000,0,0,0,0,0,9.81\n").unwrap();
    for rate in [0.0, -200.0, f64::NAN, f64::INFINITY] {
        let mut o = RecordingOptions::default();
        o.format.validate.nominal_rate = Some(rate);
        let e = open_recording(&f, &o).unwrap_err().to_string();
        assert!(e.contains("--rate must be a positive number of Hz") && e.contains("imu.csv"), "{rate}: {e}");
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_simulation_too_large_to_hold_is_refused_before_any_work() {
    let cfg = SimConfig { duration_s: Some(1e12), ..SimConfig::default() };
    let e = simulate(Scenario::Static, &cfg, 1).err().unwrap().to_string();
    assert!(e.contains("samples") && e.contains("simulate shorter"), "{e}");
}

#[test]
fn estimator_options_name_what_is_wrong() {
    let mut o = VioOptions::default();
    o.noise.pixel_sigma = 0.0;
    assert!(o.validate().unwrap_err().to_string().contains("--pixel-sigma must be positive"));
    let mut o = VioOptions::default();
    o.window.size = 0;
    assert!(o.validate().unwrap_err().to_string().contains("--window"));
    // The YAML of the defaults reads back to the defaults.
    let dir = scratch("vio");
    let p = dir.join("vio.yaml");
    std::fs::write(&p, VioOptions::default().to_yaml().unwrap()).unwrap();
    assert_eq!(VioOptions::read(&p).unwrap(), VioOptions::default());
    std::fs::write(&p, "window:\n  size: 1\n").unwrap();
    let e = VioOptions::read(&p).unwrap_err().to_string();
    assert!(e.contains("vio.yaml") && e.contains("--window"), "{e}");
    std::fs::write(&p, "windw: {}\n").unwrap();
    assert!(VioOptions::read(&p).is_err(), "unknown keys are refused");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn gravity_must_be_earths() {
    for g in [0.0, -9.81, 1.0, 98.1, f64::NAN] {
        let e = CalibOptions { gravity: g, ..Default::default() }.validate().unwrap_err().to_string();
        assert!(e.contains("--gravity must be the local gravity"), "{g}: {e}");
    }
    assert!(tumble::calib::local_gravity(None, Some(45.0), 1e6).unwrap_err().to_string().contains("--height"));
    for g in [-9.81, 0.0, 3.71, 12.0] {
        let mut o = tumble::vio::VioOptions::default();
        o.noise.gravity = g;
        let e = o.validate().unwrap_err().to_string();
        assert!(e.contains("--gravity must be"), "{g}: {e}");
    }
    let g = tumble::calib::local_gravity(None, Some(45.0), 3000.0).unwrap();
    assert!((9.79..9.81).contains(&g.value) && g.note.is_none());
}

#[test]
fn a_pose_graph_without_edges_is_refused() {
    let dir = scratch("g2o");
    let p = dir.join("lonely.g2o");
    std::fs::write(&p, "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\n").unwrap();
    let e = tumble::io::g2o::read_g2o(&p, &Default::default()).err().unwrap().to_string();
    assert!(e.contains("lonely.g2o") && e.contains("no edges"), "{e}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn apply_never_overwrites_its_input() {
    let dir = scratch("apply");
    let f = dir.join("imu.csv");
    let text = "0,0,0,0,0,0,9.81\n5000000,0,0,0,0,0,9.81\n10000000,0,0,0,0,0,9.81\n";
    std::fs::write(&f, text).unwrap();
    let o = RecordingOptions::default();
    let rec = open_recording(&f, &o).unwrap();
    let e = tumble::calib::write_like_input(&rec, &f, &o, &dir).unwrap_err().to_string();
    assert!(e.contains("is the input"), "{e}");
    assert_eq!(std::fs::read_to_string(&f).unwrap(), text, "the input is untouched");
    let out = dir.join("out");
    assert!(tumble::calib::write_like_input(&rec, &f, &o, &out).is_ok());
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn allan_on_constant_data_is_refused_with_the_axis_named() {
    let dir = scratch("allan");
    let f = dir.join("const.csv");
    let text: String = (0..2000i64).map(|i| format!("{},0.01,0.02,0.03,0.1,0.2,9.81\n", i * 5_000_000)).collect();
    std::fs::write(&f, text).unwrap();
    let rec = open_recording(&f, &RecordingOptions::default()).unwrap();
    let e = tumble::allan::run_allan(&rec, &Default::default()).unwrap_err().to_string();
    assert!(e.contains("gyro x axis reads 0.01 in every sample"), "{e}");
    std::fs::remove_dir_all(&dir).ok();
}

/// An empty folder of this test process for test `name`.
fn scratch(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("tumble_options_{name}_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

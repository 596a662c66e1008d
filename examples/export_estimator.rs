//! Calibrate a simulated hand tumble and write the result as another
//! estimator's configuration, through the library: calibrate → export. The
//! noise is the simulated sensor's; a real run takes it from `tumble allan`
//! (`ExportInputs::gather` reads a results folder).
//!
//! ```sh
//! cargo run --example export_estimator [-- openvins|basalt|kalibr OUT_DIR]
//! ```

use tumble::calib::{calibrate, CalibOptions};
use tumble::export::{export, ExportInputs, Inflation, Target};
use tumble::io::ImuNoise;
use tumble::sim::{simulate, Scenario, SimConfig};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let target: Target = args.next().unwrap_or_else(|| "openvins".into()).parse()?;
    let out =
        args.next().map(std::path::PathBuf::from).unwrap_or_else(|| std::env::temp_dir().join("tumble-export-example"));
    let cfg = SimConfig::default();
    let sim = simulate(Scenario::Tumble, &cfg, 7)?;
    let rec = sim.imu.to_recording();
    let result =
        calibrate(&rec, &CalibOptions { gravity: cfg.gravity, ..Default::default() }).map_err(|e| e.message)?;
    let inputs = ExportInputs {
        noise: ImuNoise::from_model(&cfg.imu),
        rate_hz: rec.mean_rate(),
        imu_topic: "/imu0".into(),
        calibration: Some(result.calibration),
        inflation: Inflation::none("simulated sensor: its own noise, not inflated"),
        cameras: Vec::new(),
        rig_time_offset_s: None,
        sources: vec!["the simulated tumble of examples/export_estimator.rs".into()],
    };
    let report = export(target, &inputs, &out)?;
    for n in &report.notes {
        println!("note: {n}");
    }
    for f in &report.files {
        println!("==> {} <==\n{}", f.display(), std::fs::read_to_string(f)?);
    }
    Ok(())
}

//! Run the estimator on real EuRoC V1_01 data: EqVIO's processed file (real IMU
//! and real feature tracks, first 30 s) against the EuRoC ground truth.
//!
//! `cargo run --example vio_euroc -- [eqvio.csv] [groundtruth.csv]` (default:
//! the files under `$TUMBLE_DATA/euroc`, docs/datasets.md)

use std::path::PathBuf;
use tumble::io::datasets::dataset;
use tumble::vio::{read_eqvio, run, summarize, VioOptions};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let (csv, gt) = match (args.get(1), args.get(2)) {
        (Some(csv), gt) => (PathBuf::from(csv), gt.map(PathBuf::from).unwrap_or_default()),
        (None, _) => match (dataset("euroc/eqvio_V1_01_30s.csv"), dataset("euroc/groundtruth/V1_01_easy.csv")) {
            (Some(csv), Some(gt)) => (csv, gt),
            _ => return,
        },
    };
    let input = match read_eqvio(&csv, gt.is_file().then_some(gt.as_path())) {
        Ok(i) => i,
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(1);
        }
    };
    // EqVIO's tuned pixel noise for this file (σ² = 3.72 px²).
    let opts = VioOptions::with_pixel_sigma(1.93);
    let out = match run(&input, &opts, None) {
        Ok(o) => o,
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(1);
        }
    };
    let s = summarize(&input, &opts, &out, 10.0);
    println!("{}: {} IMU samples, {} frames", input.name, input.imu.t.len(), input.frames.len());
    println!("{}", s.table());
    for w in &out.warnings {
        println!("warning: {w}");
    }
}

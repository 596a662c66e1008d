//! Speed of the visual frontend on 752×480 images on one core, against the
//! target of 6 ms per frame (≈ 167 frames/s; the measurement of
//! another frontend on rendered images was 9.7 ms). VINS-Mono's feature tracker (C++, ROS)
//! cannot be built here, so the peer figure is the target rate. Two
//! sequences: the 95 real V1_01 cam0 images (the MAV still on the ground, so
//! few new corners are needed), and 300 frames of a 752×480 window moving over
//! a reflected-border copy of the first image (features leave, new corners are
//! detected every frame). Image decoding is timed apart.
//!
//! `cargo run --release -p tumble-bench --features opencv --example bench_frontend [-- --repeat N]`

use opencv::core::{self, Mat};
use std::time::Instant;
use tumble::io::asl::read_asl;
use tumble::io::image::read_gray;
use tumble::vio::frontend::{moving_window, FrontendOptions, KltTracker};

/// 6 ms per 752×480 frame.
const TARGET_FPS: f64 = 1000.0 / 6.0;

fn track_all(
    frames: &[Mat],
    model: tumble::factors::camera::CameraModel,
    opts: &FrontendOptions,
    repeat: usize,
) -> (f64, String) {
    let mut best = f64::INFINITY;
    let mut line = String::new();
    for _ in 0..repeat {
        let mut t = KltTracker::new(model, opts.clone());
        let start = Instant::now();
        for f in frames {
            t.track(f).expect("track");
        }
        let s = start.elapsed().as_secs_f64();
        if s < best {
            best = s;
            line = t.stats().line();
        }
    }
    (frames.len() as f64 / best, line)
}

fn main() {
    let usage = "usage: bench_frontend [--repeat N (3)]";
    let repeat = (tumble_bench::numeric_args(usage, &[("--repeat", 3.0)])[0] as usize).max(1);
    core::set_num_threads(1).expect("opencv threads");
    let Some(micro) = tumble::io::datasets::dataset("euroc/V1_01_easy_micro") else {
        return;
    };
    let ds = read_asl(&micro, &Default::default()).expect("dataset");
    let cam = &ds.cameras[0];
    let model = cam.model.expect("intrinsics");
    let start = Instant::now();
    let images: Vec<Mat> =
        cam.frames.iter().filter(|f| f.1.is_file()).map(|f| read_gray(&f.1).expect("image")).collect();
    let decode_ms = 1e3 * start.elapsed().as_secs_f64() / images.len() as f64;
    println!(
        "OpenCV {} on {} thread; PNG decoding {decode_ms:.2} ms/frame (not counted below)",
        core::get_version_string().unwrap_or_default(),
        core::get_num_threads().unwrap_or(0)
    );
    let mut base = Mat::default();
    core::copy_make_border(&images[0], &mut base, 160, 160, 240, 240, core::BORDER_REFLECT, core::Scalar::default())
        .expect("border");
    let (moving, _) = moving_window(&base, [752, 480], 300, [0.6, -0.3], 0.02).expect("window");
    let variants = [
        ("", FrontendOptions::default()),
        (", frame to frame (--no-anchors)", FrontendOptions { anchored: false, ..FrontendOptions::default() }),
        (", CLAHE", FrontendOptions { equalize: true, ..FrontendOptions::default() }),
    ];
    for (variant, opts) in &variants {
        for (name, frames) in [("V1_01 cam0, 95 real images", &images), ("moving 752×480 window, 300 frames", &moving)]
        {
            let (fps, line) = track_all(frames, model, opts, repeat);
            println!("{name}{variant}:");
            println!("  {line}");
            println!(
                "  speed on one core: {fps:.0} frames/s vs target {TARGET_FPS:.0} → ratio {:.2}",
                fps / TARGET_FPS
            );
        }
    }
}

//! Rendering speed of `tumble sim <scenario> --images` against the target of
//! 20 frames per second at 752×480 on a 2-core machine (a 30 s stereo
//! recording rendered in well under a minute). No peer renders these
//! scenes, so the figure is compared with the target rate. For each scene
//! (the flight's room, the corridor walk): the frames of a simulated
//! recording rendered and written as PNG on every core, as `--images` does,
//! then a single frame's parts on one core (the radiance with its motion
//! blur and the sensor; the rest of the first figure is the PNG encoding
//! and writing).
//!
//! `cargo run --release -p tumble-bench --example bench_render [-- --duration S (20)]`

use std::time::Instant;
use tumble::sim::images::{render_scene, write_images};
use tumble::sim::render::{lens::RayTable, render_frame, ImageSettings};
use tumble::sim::{simulate, Scenario, SimConfig};

/// Frames per second the issue asks for.
const TARGET_FPS: f64 = 20.0;

/// Frames timed one by one on one core (spread evenly over the recording).
const ONE_CORE_FRAMES: usize = 20;

fn main() {
    let usage = "usage: bench_render [--duration S (20)]";
    let duration = tumble_bench::numeric_args(usage, &[("--duration", 20.0)])[0].max(20.0);
    let root = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../target/bench-data/render");
    let settings = ImageSettings::default();
    println!(
        "{} threads; 752×480 frames, default exposure (3 ms, blur sampled every ≤ 1 px)",
        rayon::current_num_threads()
    );
    for scenario in [Scenario::Flight, Scenario::Corridor] {
        let cfg = SimConfig { duration_s: Some(duration), ..SimConfig::default() };
        let sim = match simulate(scenario, &cfg, 1) {
            Ok(sim) => sim,
            Err(e) => {
                eprintln!("error: {e}");
                std::process::exit(1);
            }
        };
        let out = root.join(format!("{scenario:?}").to_lowercase());
        let _ = std::fs::remove_dir_all(&out);
        let mut frames = 0;
        let start = Instant::now();
        if let Err(e) = write_images(&sim, &settings, &out, &mut |_, total| frames = total) {
            eprintln!("error: {e}");
            std::process::exit(1);
        }
        let seconds = start.elapsed().as_secs_f64();
        let fps = frames as f64 / seconds;
        println!(
            "{scenario:?}, {duration} s: {frames} frames rendered and written in {seconds:.1} s: {fps:.1} frames/s vs target {TARGET_FPS:.0} → ratio {:.2}",
            fps / TARGET_FPS
        );
        one_core(&sim, &settings);
        let _ = std::fs::remove_dir_all(&out);
    }
}

/// One core's time per frame for the radiance and sensor (`render_frame`),
/// over frames spread evenly over the recording (its motion varies).
fn one_core(sim: &tumble::sim::Simulation, settings: &ImageSettings) {
    let scene = render_scene(sim);
    let c = &sim.config.camera;
    let model = c.model();
    let [w, h] = c.resolution.map(|x| x as usize);
    let lens = RayTable::new(&model, w, h);
    let body_from_camera = c.body_from_camera();
    let Some(tracks) = sim.tracks.as_ref() else { return };
    let (mut render_s, mut n) = (0.0, 0);
    let every = (tracks.frames.len() / ONE_CORE_FRAMES).max(1);
    for &t in tracks.frames.iter().step_by(every) {
        let start = Instant::now();
        let pixels = render_frame(
            &scene,
            &lens,
            model.fx.max(model.fy),
            sim.motion.as_ref(),
            &body_from_camera,
            t + c.time_offset_s,
            1.0,
            settings,
            n as u64,
        );
        render_s += start.elapsed().as_secs_f64();
        assert_eq!(pixels.len(), w * h, "a frame of {w} × {h}");
        n += 1;
    }
    println!(
        "  one core, {n} frames over the recording: {:.1} ms per frame rendered (not written)",
        1e3 * render_s / n.max(1) as f64
    );
}

//! Recording a VIO run for the rerun viewer: what is written is read back from
//! the .rrd file. Without the `rerun` feature, asking for a recording is a
//! clear error.

use std::path::PathBuf;
use tumble::sim::{simulate, Scenario, SimConfig};
use tumble::vio::{run_recorded, VioInput, VioOptions};

fn temp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("tumble_rerun_{name}_{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// The first `seconds` of frames of a 40 s simulated walk (shorter walks are
/// refused by the simulator).
fn walk(seconds: f64) -> (SimConfig, VioInput) {
    let cfg = SimConfig { duration_s: Some(40.0), ..SimConfig::default() };
    let sim = simulate(Scenario::Walk, &cfg, 1).unwrap();
    let mut input = VioInput::from_simulation(&sim).unwrap();
    input.frames.retain(|f| f.t < seconds);
    (cfg, input)
}

#[cfg(not(feature = "rerun"))]
#[test]
fn asking_for_a_recording_without_the_feature_says_how_to_get_it() {
    let (cfg, input) = walk(11.0);
    let path = temp_dir("off").join("walk.rrd");
    let err = run_recorded(&input, &VioOptions::for_simulation(&cfg), None, Some(&path)).unwrap_err().to_string();
    assert!(err.contains("--features rerun") && err.contains("walk.rrd"), "{err}");
    assert!(!path.exists());
    assert!(tumble::vio::rerun_available(&path).is_err());
}

#[cfg(feature = "rerun")]
mod recording {
    use super::*;
    use tumble::vio::read_rrd;

    /// A real PNG of `w`×`h` pixels.
    fn png(path: &std::path::Path, w: u32, h: u32) {
        use plotters::prelude::*;
        let area = BitMapBackend::new(path, (w, h)).into_drawing_area();
        area.fill(&WHITE).unwrap();
        area.present().unwrap();
    }

    #[test]
    fn a_vio_run_is_recorded_and_reads_back() {
        let (cfg, mut input) = walk(12.0);
        let dir = temp_dir("walk");
        // Images for the first ten frames, as an image folder would give them.
        for f in input.frames.iter().take(10) {
            let t_ns = input.t0_ns + (f.t * 1e9).round() as i64;
            let file = dir.join(format!("{t_ns}.png"));
            png(&file, 64, 48);
            input.images.push((t_ns, file));
        }
        let path = dir.join("walk.rrd");
        let (result, written) = run_recorded(&input, &VioOptions::for_simulation(&cfg), None, Some(&path)).unwrap();
        assert_eq!(written.as_deref(), Some(path.as_path()));
        let c = read_rrd(&path).unwrap();
        let n = result.estimates.len() as u64;
        assert!(n > 100, "{n} estimates");
        for entity in [
            "world/body",
            "world/window",
            "world/landmarks",
            "world/body/camera/image/features",
            "biases/accel/x",
            "biases/gyro/z",
            "biases/gyro_truth/x",
            "status/landmarks",
        ] {
            assert_eq!(c.rows_of(entity), n, "{entity}: {:?}", c.rows);
        }
        // Images only where files were given; those before initialization are not logged.
        let imaged = input
            .images
            .iter()
            .filter(|(t, _)| result.estimates.iter().any(|e| input.t0_ns + (e.t * 1e9).round() as i64 == *t));
        assert_eq!(c.rows_of("world/body/camera/image"), imaged.count() as u64);
        // The trajectory strip once per second, the static parts once.
        let seconds = result.estimates.last().unwrap().t - result.estimates[0].t;
        let strips = c.rows_of("world/trajectory");
        assert!(strips as f64 >= seconds.floor() && strips as f64 <= seconds.ceil() + 1.0, "{strips} strips");
        assert_eq!(c.rows_of("world/groundtruth"), 1);
        assert_eq!(c.rows_of("status/events"), 0, "nothing withdrawn");
        // The scale's σ bound at each keyframe that reached far enough.
        let windows = result
            .estimates
            .iter()
            .filter(|e| e.window_length.is_some_and(|w| w.length_m >= tumble::vio::WINDOW_MIN_LENGTH_M))
            .count() as u64;
        assert!(windows > 10 && c.rows_of("status/window_length_sigma_pct") == windows, "{windows}: {:?}", c.rows);
        assert!(c.rows_of("world/body/camera") >= 1);
        // The landmarks logged are the window's: some, in metres, near the walk.
        assert!(result.estimates.iter().any(|e| e.landmarks > 20));
        std::fs::remove_dir_all(&dir).ok();
    }

    /// A walk whose gyro reads 2 rad/s too much over 20–21 s: the estimator
    /// withdraws what followed and starts again at the origin; the recording
    /// says so once per withdrawal, begins the strip again and aligns the
    /// truth again at the new piece.
    #[test]
    fn withdrawn_estimates_are_marked_and_a_new_piece_drawn_by_itself() {
        let cfg = SimConfig { duration_s: Some(40.0), ..SimConfig::default() };
        let sim = simulate(Scenario::Walk, &cfg, 3).unwrap();
        let mut input = VioInput::from_simulation(&sim).unwrap();
        for (t, g) in input.imu.t.iter().zip(input.imu.gyro.iter_mut()) {
            if *t > 20.0 && *t < 21.0 {
                g.x += 2.0;
            }
        }
        let path = temp_dir("shock").join("walk.rrd");
        let (result, _) = run_recorded(&input, &VioOptions::for_simulation(&cfg), None, Some(&path)).unwrap();
        let withdrawn = result.warnings.iter().filter(|w| w.contains("estimates are withdrawn")).count() as u64;
        assert!(withdrawn >= 1 && result.starts.len() >= 2, "{:?}", result.warnings);
        let c = read_rrd(&path).unwrap();
        assert_eq!(c.rows_of("status/events"), withdrawn, "{:?}", c.rows);
        // Aligned again at each new start, withdrawn later or not.
        assert_eq!(c.rows_of("world/groundtruth"), withdrawn + 1);
        std::fs::remove_dir_all(path.parent().unwrap()).ok();
    }

    #[test]
    fn unreadable_files_are_errors_naming_the_file() {
        let dir = temp_dir("bad");
        let bad = dir.join("not.rrd");
        std::fs::write(&bad, b"this is not a rerun file").unwrap();
        let err = read_rrd(&bad).unwrap_err().to_string();
        assert!(err.contains("not.rrd"), "{err}");
        let err = read_rrd(&dir.join("missing.rrd")).unwrap_err().to_string();
        assert!(err.contains("missing.rrd"), "{err}");
        // A missing image file: the run goes on, with a warning naming it.
        let (cfg, mut input) = walk(11.0);
        let t_ns = input.t0_ns + (input.frames.last().unwrap().t * 1e9).round() as i64;
        input.images.push((t_ns, dir.join("gone.png")));
        let (result, _) =
            run_recorded(&input, &VioOptions::for_simulation(&cfg), None, Some(&dir.join("x.rrd"))).unwrap();
        assert!(result.warnings.iter().any(|w| w.contains("gone.png")), "{:?}", result.warnings);
        // The recording's folder is created; a path that cannot be one is an error before the run.
        let nested = dir.join("new/folder/x.rrd");
        run_recorded(&input, &VioOptions::for_simulation(&cfg), None, Some(&nested)).unwrap();
        assert!(nested.is_file());
        std::fs::write(dir.join("afile"), b"").unwrap();
        let err = run_recorded(&input, &VioOptions::for_simulation(&cfg), None, Some(&dir.join("afile/x.rrd")))
            .unwrap_err()
            .to_string();
        assert!(err.contains("afile"), "{err}");
        std::fs::remove_dir_all(&dir).ok();
    }
}

//! `tumble eval`: alignments recover known transforms, the error figures equal
//! what was put into simulated estimates, bias errors follow the ground truth's
//! columns, the real EuRoC run is evaluated, and bad input is refused clearly.

use nalgebra::{Rotation3, UnitQuaternion, Vector3};
use std::path::PathBuf;
use tumble::eval::{align, evaluate, write_report, Alignment, EvalOptions};
use tumble::io::biases::{read_biases, write_biases, BiasTrack};
use tumble::io::trajectory::{read_trajectory, write_tum, Trajectory};

mod common;

fn tmp(name: &str, text: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("tumble-eval-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

/// A small deterministic generator (xorshift) of standard normal numbers.
struct Normal(u64);
impl Normal {
    fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
    fn sample(&mut self) -> f64 {
        let (u, v) = (self.uniform().max(1e-300), self.uniform());
        (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    }
}

/// A 60 s, 100 Hz ground truth moving on a 3-D curve with turning attitude and slowly varying biases.
fn groundtruth() -> Trajectory {
    let n = 6000;
    let mut gt = Trajectory { bias_gyro: Some(Vec::new()), bias_accel: Some(Vec::new()), ..Default::default() };
    for i in 0..n {
        let t = i as f64 * 0.01;
        gt.t_ns.push(1_000_000_000_000 + i as i64 * 10_000_000);
        gt.p.push([2.0 * (0.3 * t).cos(), 1.5 * (0.2 * t).sin(), 0.5 * (0.5 * t).sin()]);
        let q = UnitQuaternion::from_euler_angles(0.1 * (0.7 * t).sin(), 0.05 * t.cos(), 0.3 * t);
        gt.q.push([q.w, q.i, q.j, q.k]);
        gt.bias_gyro.as_mut().unwrap().push([1e-3 * (0.1 * t).sin(), -2e-3, 5e-4]);
        gt.bias_accel.as_mut().unwrap().push([0.02, 0.05 * (0.05 * t).cos(), -0.01]);
    }
    gt
}

/// Every 5th ground-truth pose, moved by `s·R·x + t` (the inverse is what alignment must find).
fn moved(gt: &Trajectory, r: Rotation3<f64>, t: Vector3<f64>, s: f64, noise: f64, seed: u64) -> Trajectory {
    let mut rng = Normal(seed);
    let mut est = Trajectory::default();
    let rq = UnitQuaternion::from_rotation_matrix(&r);
    for i in (0..gt.len()).step_by(5) {
        let p = Vector3::from(gt.p[i]);
        let n = Vector3::new(rng.sample(), rng.sample(), rng.sample()) * noise;
        let q = rq
            * UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
                gt.q[i][0], gt.q[i][1], gt.q[i][2], gt.q[i][3],
            ));
        est.t_ns.push(gt.t_ns[i]);
        est.p.push((r * p * s + t + n).into());
        est.q.push([q.w, q.i, q.j, q.k]);
    }
    est
}

#[test]
fn alignments_recover_known_transforms() {
    let gt = groundtruth();
    let pg: Vec<Vector3<f64>> = gt.p.iter().map(|p| Vector3::from(*p)).collect();
    let t = Vector3::new(3.0, -1.0, 0.5);
    for (kind, r, s) in [
        (Alignment::Se3, Rotation3::from_euler_angles(0.3, -0.2, 1.1), 1.0),
        (Alignment::Sim3, Rotation3::from_euler_angles(-0.4, 0.1, 2.0), 1.7),
        (Alignment::PosYaw, Rotation3::from_euler_angles(0.0, 0.0, -0.8), 1.0),
    ] {
        let pe: Vec<Vector3<f64>> = pg.iter().map(|p| r * p * s + t).collect();
        let sim = align(&pe, &pg, kind).unwrap();
        let worst = pe.iter().zip(&pg).map(|(e, g)| (sim.apply(e) - g).norm()).fold(0.0, f64::max);
        assert!(worst < 1e-9, "{kind:?}: residual {worst}");
        assert!((sim.scale - 1.0 / s).abs() < 1e-12, "{kind:?}: scale {}", sim.scale);
    }
    // A roll error cannot be removed by the 4-DOF alignment, but can by SE(3).
    let r = Rotation3::from_euler_angles(0.05, 0.0, 0.4);
    let pe: Vec<Vector3<f64>> = pg.iter().map(|p| r * p).collect();
    let rms = |kind| {
        let sim = align(&pe, &pg, kind).unwrap();
        (pe.iter().zip(&pg).map(|(e, g)| (sim.apply(e) - g).norm_squared()).sum::<f64>() / pe.len() as f64).sqrt()
    };
    assert!(rms(Alignment::PosYaw) > 1e-2 && rms(Alignment::Se3) < 1e-9);
}

#[test]
fn ate_equals_the_noise_put_in_and_rpe_sees_scale() {
    let gt = groundtruth();
    let sigma = 0.02;
    let est = moved(&gt, Rotation3::from_euler_angles(0.0, 0.0, 0.6), Vector3::new(1.0, 2.0, 0.0), 1.0, sigma, 7);
    for kind in [Alignment::PosYaw, Alignment::Se3, Alignment::Sim3] {
        let e = evaluate(&est, None, &gt, &EvalOptions { alignment: kind, ..Default::default() }).unwrap();
        let expected = sigma * 3f64.sqrt();
        println!("{kind:?}: ATE {:.5} m (expected ≈ {expected:.5})", e.metrics.ate_rmse_m);
        assert!((e.metrics.ate_rmse_m / expected - 1.0).abs() < 0.05, "{kind:?}: {}", e.metrics.ate_rmse_m);
        assert_eq!(e.metrics.matched, est.len());
        // Only the alignment's own small error (from the noisy positions) remains in rotation.
        assert!(e.metrics.rotation_rmse_deg < 0.1, "{}", e.metrics.rotation_rmse_deg);
        // Default distances: 10–50 % of the path.
        assert_eq!(e.metrics.rpe.len(), 5);
    }
    // A 2 % scale error: SE(3)'s relative errors are 2 % of the chord between the poses, a little
    // less of the path travelled along the curve; Sim(3) removes them.
    let scaled = moved(&gt, Rotation3::identity(), Vector3::zeros(), 1.02, 0.0, 1);
    let opts = |alignment| EvalOptions { alignment, rpe_distances: vec![0.2, 4.0], ..Default::default() };
    let se3 = evaluate(&scaled, None, &gt, &opts(Alignment::Se3)).unwrap();
    for r in &se3.metrics.rpe {
        println!("se3 RPE {} m: {:.3} %", r.distance_m, r.trans_mean_percent);
        assert!(r.trans_mean_percent <= 2.0 + 1e-9, "{}", r.trans_mean_percent);
    }
    assert!((se3.metrics.rpe[0].trans_mean_percent - 2.0).abs() < 0.02, "{}", se3.metrics.rpe[0].trans_mean_percent);
    let sim3 = evaluate(&scaled, None, &gt, &opts(Alignment::Sim3)).unwrap();
    assert!((sim3.metrics.scale - 1.0 / 1.02).abs() < 1e-9 && sim3.metrics.ate_rmse_m < 1e-9);
    assert!(sim3.metrics.rpe.iter().all(|r| r.trans_rmse_m < 1e-9));
}

/// The rotation RMSE with the alignment's rotation from the orientations
/// holds no alignment error: exact orientations under noisy positions give 0
/// there, while the positions' alignment turns them by its own error.
#[test]
fn the_rotation_aligned_by_the_orientations_holds_no_alignment_error() {
    let gt = groundtruth();
    for (kind, r) in [
        (Alignment::Se3, Rotation3::from_euler_angles(0.3, -0.2, 1.1)),
        (Alignment::PosYaw, Rotation3::from_euler_angles(0.0, 0.0, -0.8)),
    ] {
        let est = moved(&gt, r, Vector3::new(1.0, 2.0, 0.0), 1.0, 0.3, 3);
        let e = evaluate(&est, None, &gt, &EvalOptions { alignment: kind, ..Default::default() }).unwrap();
        let m = &e.metrics;
        println!(
            "{kind:?}: rotation RMSE {:.4}°, aligned by the orientations {:.2e}°",
            m.rotation_rmse_deg, m.rotation_rmse_oriented_deg
        );
        assert!(m.rotation_rmse_oriented_deg < 1e-6, "{kind:?}: {}", m.rotation_rmse_oriented_deg);
        assert!(m.rotation_rmse_deg > 1e-3, "{kind:?}: {}", m.rotation_rmse_deg);
    }
}

#[test]
fn bias_errors_against_the_ground_truth_columns() {
    let gt = groundtruth();
    let est = moved(&gt, Rotation3::identity(), Vector3::zeros(), 1.0, 0.0, 1);
    let offset_g = [1e-3, -2e-3, 2e-3];
    let mut b = BiasTrack::default();
    for (k, &t) in est.t_ns.iter().enumerate() {
        let i = k * 5;
        let late = t >= gt.t_ns[0] + 20_000_000_000;
        // Before 20 s the estimate is far off (convergence); after, a constant offset.
        let g = gt.bias_gyro.as_ref().unwrap()[i];
        let a = gt.bias_accel.as_ref().unwrap()[i];
        b.t_ns.push(t);
        b.gyro.push(if late { [g[0] + offset_g[0], g[1] + offset_g[1], g[2] + offset_g[2]] } else { [1.0; 3] });
        b.accel.push(if late { a } else { [1.0; 3] });
    }
    let opts = EvalOptions { bias_after_s: 20.0, ..Default::default() };
    let e = evaluate(&est, Some(&b), &gt, &opts).unwrap();
    let expected = (offset_g.iter().map(|x| x * x).sum::<f64>()).sqrt();
    let m = &e.metrics;
    assert!((m.bias_rmse_gyro.unwrap() - expected).abs() < 1e-12, "{:?}", m.bias_rmse_gyro);
    assert!(m.bias_rmse_accel.unwrap() < 1e-12);
    assert!((m.bias_rmse_gyro_axes.unwrap()[2] - 2e-3).abs() < 1e-12);
    // Without σ columns no normalized errors; with σ = 1e-3 on every axis,
    // (offset/σ)² per axis: 1, 4, 4 (gyro) and 0 (accel). A NaN σ (no
    // covariance yet) leaves its sample out.
    assert!(m.bias_nees_gyro_axes.is_none() && m.bias_nees_accel_axes.is_none());
    let n = b.t_ns.len();
    b.gyro_std = Some((0..n).map(|k| if k == n / 2 { [f64::NAN; 3] } else { [1e-3; 3] }).collect());
    b.accel_std = Some(vec![[0.01; 3]; n]);
    let m = evaluate(&est, Some(&b), &gt, &opts).unwrap().metrics;
    let g = m.bias_nees_gyro_axes.unwrap();
    assert!((g[0] - 1.0).abs() < 1e-9 && (g[1] - 4.0).abs() < 1e-9 && (g[2] - 4.0).abs() < 1e-9, "{g:?}");
    assert!(m.bias_nees_accel_axes.unwrap().iter().all(|x| x.abs() < 1e-12));
    assert!(m.table().contains("gyro 1.00 4.00 4.00"), "{}", m.table());
    // Without the ground truth's bias columns: a warning, no figure.
    let mut bare = gt.clone();
    bare.bias_gyro = None;
    let e = evaluate(&est, Some(&b), &bare, &opts).unwrap();
    assert!(e.metrics.bias_rmse_gyro.is_none() && e.metrics.warnings.iter().any(|w| w.contains("no bias columns")));
}

#[test]
fn files_round_trip_and_the_report_is_written() {
    let gt = groundtruth();
    let est = moved(&gt, Rotation3::identity(), Vector3::new(0.1, 0.0, 0.0), 1.0, 0.01, 3);
    let dir = std::env::temp_dir().join(format!("tumble-eval-report-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let traj = dir.join("trajectory.txt");
    write_tum(&traj, &est).unwrap();
    let back = read_trajectory(&traj).unwrap();
    assert_eq!(back.t_ns, est.t_ns);
    let mut b = BiasTrack {
        t_ns: est.t_ns.clone(),
        accel: vec![[0.01, 0.02, 0.03]; est.len()],
        gyro: vec![[1e-3, 0.0, -1e-3]; est.len()],
        accel_std: Some(vec![[0.1; 3]; est.len()]),
        gyro_std: Some(vec![[1e-2; 3]; est.len()]),
        keyframe: Some((0..est.len()).map(|i| i % 3 == 0).collect()),
    };
    // An unknown σ (first frame) is NaN and survives the round trip.
    b.gyro_std.as_mut().unwrap()[0] = [f64::NAN; 3];
    let bp = dir.join("biases.csv");
    write_biases(&bp, &b).unwrap();
    let rb = read_biases(&bp).unwrap();
    assert!(rb.gyro_std.as_ref().unwrap()[0][0].is_nan());
    assert_eq!(rb.keyframe, b.keyframe);
    assert_eq!(rb.accel, b.accel);
    let e = evaluate(&back, Some(&rb), &gt, &EvalOptions::default()).unwrap();
    let files = write_report(&dir.join("eval"), &e).unwrap();
    for name in ["metrics.json", "trajectory_top.png", "errors.png", "rpe.png", "bias_gyro.png", "bias_accel.png"] {
        assert!(files.iter().any(|f| f.ends_with(name)) && dir.join("eval").join(name).metadata().unwrap().len() > 0);
    }
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("eval/metrics.json")).unwrap()).unwrap();
    for key in ["ate_rmse_m", "rpe", "bias_rmse_gyro", "bias_rmse_accel"] {
        assert!(json.get(key).is_some(), "metrics.json lacks {key}");
    }
    assert_eq!(json["alignment"], "posyaw");
}

/// An estimate in pieces (a run that started again in a frame of its own)
/// is aligned piece by piece when the pieces are given: each piece's error is
/// what was put into it, and relative errors never span two frames.
#[test]
fn an_estimate_in_pieces_is_aligned_piece_by_piece() {
    let gt = groundtruth();
    let a = moved(&gt, Rotation3::from_euler_angles(0.0, 0.0, 0.6), Vector3::new(1.0, 2.0, 0.0), 1.0, 0.01, 7);
    let b = moved(&gt, Rotation3::from_euler_angles(0.0, 0.0, -2.0), Vector3::new(-4.0, 0.5, 0.0), 1.0, 0.01, 8);
    let split = gt.t_ns[gt.len() / 2];
    let mut est = Trajectory::default();
    for (from, to) in [(&a, true), (&b, false)] {
        for i in (0..from.len()).filter(|&i| (from.t_ns[i] < split) == to) {
            est.t_ns.push(from.t_ns[i]);
            est.p.push(from.p[i]);
            est.q.push(from.q[i]);
        }
    }
    let whole = evaluate(&est, None, &gt, &EvalOptions::default()).unwrap();
    let opts = EvalOptions { piece_starts_s: vec![split as f64 * 1e-9], ..Default::default() };
    let e = evaluate(&est, None, &gt, &opts).unwrap();
    println!(
        "as one: ATE {:.3} m; in pieces: ATE {:.4} m, {:?}",
        whole.metrics.ate_rmse_m, e.metrics.ate_rmse_m, e.metrics.pieces
    );
    assert!(whole.metrics.ate_rmse_m > 1.0);
    assert_eq!(e.metrics.pieces.len(), 2);
    assert_eq!(e.similarities.len(), 2);
    let expected = 0.01 * 3f64.sqrt();
    for p in &e.metrics.pieces {
        assert!((p.ate_rmse_m / expected - 1.0).abs() < 0.1, "{p:?}");
    }
    assert!(e.metrics.rotation_rmse_deg < 0.1 && e.metrics.rotation_rmse_oriented_deg < 0.1);
    assert!(e.metrics.rpe.iter().all(|r| r.trans_rmse_m < 0.05), "{:?}", e.metrics.rpe);
    assert!(e.metrics.warnings.iter().any(|w| w.contains("2 pieces")), "{:?}", e.metrics.warnings);
    // A piece of two poses cannot be aligned: left out, counted and said.
    let late = (est.t_ns[est.len() - 2] - 1) as f64 * 1e-9;
    let opts = EvalOptions { piece_starts_s: vec![split as f64 * 1e-9, late], ..Default::default() };
    let e = evaluate(&est, None, &gt, &opts).unwrap();
    assert_eq!((e.metrics.pieces.len(), e.metrics.unmatched), (2, 2));
    assert!(e.metrics.warnings.iter().any(|w| w.contains("left out")), "{:?}", e.metrics.warnings);
    // Pieces out of order are refused before any work.
    let bad = EvalOptions { piece_starts_s: vec![2.0, 1.0], ..Default::default() };
    assert!(evaluate(&est, None, &gt, &bad).unwrap_err().to_string().contains("--pieces"));
}

#[test]
fn bad_input_is_refused_clearly() {
    let gt = groundtruth();
    // Different clocks: estimate in seconds from 0.
    let mut est = moved(&gt, Rotation3::identity(), Vector3::zeros(), 1.0, 0.0, 1);
    let shift = est.t_ns[0];
    est.t_ns.iter_mut().for_each(|t| *t -= shift);
    let err = evaluate(&est, None, &gt, &EvalOptions::default()).unwrap_err().to_string();
    assert!(err.contains("same clock"), "{err}");
    // Partly outside: counted and warned.
    let mut late = moved(&gt, Rotation3::identity(), Vector3::zeros(), 1.0, 0.0, 1);
    late.t_ns.iter_mut().for_each(|t| *t += 30_000_000_000);
    let e = evaluate(&late, None, &gt, &EvalOptions::default()).unwrap();
    assert!(e.metrics.unmatched > 0 && e.metrics.warnings.iter().any(|w| w.contains("outside")));
    // Degenerate geometry: a straight line for SE(3), a vertical line for position+yaw.
    let mut line = gt.clone();
    line.p.iter_mut().enumerate().for_each(|(i, p)| *p = [i as f64 * 0.01, 0.0, 0.0]);
    let est = moved(&line, Rotation3::identity(), Vector3::zeros(), 1.0, 0.0, 1);
    let err = evaluate(&est, None, &line, &EvalOptions { alignment: Alignment::Se3, ..Default::default() })
        .unwrap_err()
        .to_string();
    assert!(err.contains("collinear"), "{err}");
    line.p.iter_mut().enumerate().for_each(|(i, p)| *p = [0.0, 0.0, i as f64 * 0.01]);
    let est = moved(&line, Rotation3::identity(), Vector3::zeros(), 1.0, 0.0, 1);
    let err = evaluate(&est, None, &line, &EvalOptions::default()).unwrap_err().to_string();
    assert!(err.contains("yaw"), "{err}");
    assert!(evaluate(&Trajectory::default(), None, &gt, &EvalOptions::default()).is_err());
    // Bias tracks: wrong column count, NaN bias, time going back, negative σ.
    let head = "#timestamp [ns],b_a_x,b_a_y,b_a_z,b_g_x,b_g_y,b_g_z\n";
    for (name, text, want) in [
        ("cols.csv", format!("{head}1000,0,0,0,0,0\n"), "7, 13 or 14 columns"),
        ("nan.csv", format!("{head}1000,0,0,0,0,0,0\n2000,0,NaN,0,0,0,0\n"), "nan.csv:3:"),
        ("back.csv", format!("{head}2000,0,0,0,0,0,0\n1000,0,0,0,0,0,0\n"), "back.csv:3:"),
        ("neg.csv", format!("{head}1000,0,0,0,0,0,0,0.1,0.1,-0.1,0.1,0.1,0.1\n"), "negative"),
        ("inf.csv", format!("{head}1000,0,0,0,0,0,0,0.1,0.1,inf,0.1,0.1,0.1\n"), "inf.csv:2:"),
    ] {
        let err = read_biases(&tmp(name, &text)).unwrap_err().to_string();
        assert!(err.contains(want), "{name}: {err}");
    }
    // A TUM estimate with a bad number names the file and line.
    let err = read_trajectory(&tmp("est.txt", "1.0 0 0 0 0 0 0 1\n1.1 0 x 0 0 0 0 1\n")).unwrap_err().to_string();
    assert!(err.contains("est.txt:2:"), "{err}");
    // Nanosecond stamps counted from a start (fewer than 13 digits) are not
    // read as seconds 50 million seconds apart.
    let ns = "# t x y z qx qy qz qw\n0 0 0 0 0 0 0 1\n50000000 0 0 0 0 0 0 1\n";
    let err = read_trajectory(&tmp("rel_ns.txt", ns)).unwrap_err().to_string();
    assert!(err.contains("rel_ns.txt:3:") && err.contains("seconds"), "{err}");
    // Absolute nanoseconds (19 digits) are read as such.
    let abs = "1403636579000000000 0 0 0 0 0 0 1\n1403636579050000000 0 0 0 0 0 0 1\n";
    let tr = read_trajectory(&tmp("abs_ns.txt", abs)).unwrap();
    assert_eq!(tr.t_ns[1] - tr.t_ns[0], 50_000_000);
}

/// The real EuRoC V1_01 run (EqVIO tracks) evaluated against its ground truth.
#[test]
fn euroc_v1_01_is_evaluated() {
    let (Some(tracks), Some(gt_path)) =
        (common::shared("euroc/eqvio_V1_01_30s.csv"), common::shared("euroc/groundtruth/V1_01_easy.csv"))
    else {
        return;
    };
    let input = tumble::vio::read_eqvio(&tracks, Some(&gt_path)).unwrap();
    let opts = tumble::vio::VioOptions::with_pixel_sigma(1.93);
    let out = tumble::vio::run(&input, &opts, None).unwrap();
    let gt = read_trajectory(&gt_path).unwrap();
    let est = tumble::vio::trajectory(&input, &out);
    let biases = tumble::vio::bias_track(&input, &out);
    for kind in [Alignment::PosYaw, Alignment::Se3] {
        let e = evaluate(
            &est,
            Some(&biases),
            &gt,
            &EvalOptions { alignment: kind, bias_after_s: 10.0, ..Default::default() },
        )
        .unwrap();
        print!("V1_01 30 s, {}:\n{}", kind.name(), e.metrics.table());
        assert!(e.metrics.ate_rmse_m < 0.1 && e.metrics.bias_rmse_gyro.unwrap() < 5e-3);
    }
}

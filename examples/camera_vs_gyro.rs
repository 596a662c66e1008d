//! Does a camera calibration agree with the gyro? A check that needs no
//! reference calibration, on EuRoC's `imu_april` (or another ASL folder with
//! `camN/corners.csv` and a target).
//!
//! `cargo run --release --example camera_vs_gyro -- [DATA_DIR] [--rig DIR]` (default
//! `$TUMBLE_DATA/euroc`, docs/datasets.md: `imu_april/` and EuRoC's published calibration in
//! `V1_01_easy_micro/`). `--rig DIR`: tumble's calibration read from what
//! `tumble calibrate-rig` wrote there (`camN/sensor.yaml`) instead of calibrated again.
//!
//! Each frame's pose comes from its corners alone (PnP with the calibration's
//! intrinsics), turned into the body frame by its `T_BC`. Over two frames
//! 0.25 s apart (`SPAN_S`) the rotation it gives is compared with the gyro's,
//! integrated between their stamps: `e = Log(ΔR_gyro⁻¹ ΔR_camera)`, fitted by
//! least squares (to first order) as `e ≈ Σ_k R_k⁻¹ (b + M ω_k) Δt_k` over
//! the gyro's samples `k`, `R_k` the gyro's rotation from sample `k` to the
//! pair's end: `b` the gyro bias and `M` an apparent scale and misalignment
//! of the gyro against the camera. Its antisymmetric part is a rotation of
//! `T_BC`; its symmetric part is not a rotation at all. A gyro's own scale
//! errors are ~0.1 % (EuRoC's ADIS16448 against the motion capture in flight,
//! `imu_in_flight`); a camera model that is off — principal point,
//! distortion, focal length — biases each frame's pose by where the target
//! sits in the image, so the camera's rotations differ from the gyro's in
//! proportion to the motion, and `M` shows it. Pairs are disjoint so that
//! their errors are independent; each axis is weighted by its residuals'
//! scatter (a first, unweighted pass), and the σ come from that scatter.
//!
//! The calibrations compared: EuRoC's published one (Kalibr's), and
//! tumble's own of this recording (`calibrate-rig`, intrinsics estimated).

use nalgebra::{Isometry3, Matrix3, UnitQuaternion, Vector3};
use std::error::Error;
use std::path::{Path, PathBuf};
use tumble::rig::init::refine_view_pose;
use tumble::rig::View;
use tumble::rig::{calibrate_rig, RigInput, RigOptions};
use tumble::vio::{TARGET_TRUTH_MAX_RMS_PX, TARGET_TRUTH_MIN_CORNERS};
use tumble_factors::camera::CameraModel;

/// Largest RMS reprojection of a frame's PnP pose \[px\]: twice the PnP
/// ground truth's ([`TARGET_TRUTH_MAX_RMS_PX`]), so that a camera model that
/// is off, whose residuals are larger, still gets its frames posed.
const MAX_RMS_PX: f64 = 2.0 * TARGET_TRUTH_MAX_RMS_PX;

/// Time between a pair's two frames \[s\]: the rotation grows with it while
/// the frames' PnP errors do not (the gyro's over it stays far below them).
const SPAN_S: f64 = 0.25;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let rig_dir = match args.iter().position(|a| a == "--rig") {
        Some(i) => Some(PathBuf::from(args.get(i + 1).ok_or("--rig needs the folder `tumble calibrate-rig` wrote")?)),
        None => None,
    };
    let positional = args.iter().enumerate().find(|(i, a)| !a.starts_with("--") && (*i == 0 || args[i - 1] != "--rig"));
    let root = match positional {
        Some((_, dir)) => PathBuf::from(dir),
        None => match tumble::io::datasets::dataset("euroc") {
            Some(dir) => dir,
            None => return Ok(()),
        },
    };
    let seq = root.join("imu_april");
    let micro = root.join("V1_01_easy_micro/mav0");
    if !seq.is_dir() || !micro.is_dir() {
        println!("skipped: {} or {} is absent", seq.display(), micro.display());
        return Ok(());
    }
    let opts = RigOptions { resolution: Some([752, 480]), ..RigOptions::default() };
    let input = RigInput::from_asl(&seq, &seq.join("target.yaml"), Some(&micro.join("imu0/sensor.yaml")), None, &opts)?;
    let ours = match &rig_dir {
        Some(dir) => read_calibration(dir, &input)?,
        None => {
            eprintln!("calibrating the rig on the recording (intrinsics estimated) …");
            let rig = calibrate_rig(&input, &opts, &mut |_| {})?;
            rig.cameras.iter().map(|c| (c.name.clone(), c.model, c.t_bc)).collect()
        }
    };
    println!("Gyro against each frame pair's camera rotation (disjoint pairs; M in %, ± 1σ):\n");
    for cam in &input.cameras {
        let (euroc, t_bs, _, _) = tumble::io::asl::read_camera_sensor(&micro.join(&cam.name).join("sensor.yaml"))?;
        let euroc_t_bc = t_bs.ok_or("EuRoC's sensor.yaml without T_BS")?;
        let (_, model, t_bc) = ours.iter().find(|c| c.0 == cam.name).ok_or("camera missing from the result")?;
        for (label, model, t_bc) in [("EuRoC's", euroc, euroc_t_bc), ("tumble's", *model, *t_bc)] {
            let fit = fit(&cam.views, &model, &t_bc.rotation, &input)?;
            println!("{} with {label} calibration ({} pairs, residual RMS {:.3}°):", cam.name, fit.pairs, fit.rms_deg);
            for r in 0..3 {
                let row: Vec<String> = (0..3)
                    .map(|c| format!("{:+6.2} ± {:.2}", 100.0 * fit.m[(r, c)], 100.0 * fit.sigma[(r, c)]))
                    .collect();
                println!("  {}", row.join("   "));
            }
            let skew = 0.5 * (fit.m - fit.m.transpose());
            let sym = 0.5 * (fit.m + fit.m.transpose());
            println!(
                "  scale x y z {:+.2} {:+.2} {:+.2} %; rotation part {:.3}°; largest |M| / σ {:.1}\n",
                100.0 * sym[(0, 0)],
                100.0 * sym[(1, 1)],
                100.0 * sym[(2, 2)],
                Vector3::new(skew[(2, 1)], skew[(0, 2)], skew[(1, 0)]).norm().to_degrees(),
                fit.m.component_div(&fit.sigma).abs().max()
            );
        }
    }
    Ok(())
}

/// A camera's name, model and `T_BC`.
type Calibrated = (String, CameraModel, Isometry3<f64>);

/// Each camera's name, model and `T_BC` as `tumble calibrate-rig` wrote them in `dir`.
fn read_calibration(dir: &Path, input: &RigInput) -> Result<Vec<Calibrated>, Box<dyn Error>> {
    input
        .cameras
        .iter()
        .map(|cam| {
            let file = dir.join(&cam.name).join("sensor.yaml");
            let (model, t_bs, _, _) = tumble::io::asl::read_camera_sensor(&file)?;
            let t_bc = t_bs.ok_or_else(|| format!("{}: no T_BS", file.display()))?;
            Ok((cam.name.clone(), model, t_bc))
        })
        .collect()
}

/// `M` with its σ, the pairs used and the residual RMS.
struct Fit {
    m: Matrix3<f64>,
    sigma: Matrix3<f64>,
    pairs: usize,
    rms_deg: f64,
}

/// One frame pair: the design rows (bias then `M` column-major) and `e`.
struct Pair {
    design: nalgebra::SMatrix<f64, 3, 12>,
    e: Vector3<f64>,
}

/// Fit `e ≈ Σ_k R_k⁻¹ (b + M ω_k) Δt_k` over disjoint pairs of posed frames
/// [`SPAN_S`] apart, `R_k` the gyro's rotation from sample `k` to the pair's
/// end (first order in `b` and `M`); weighted per axis by the residuals'
/// scatter of an unweighted first pass.
fn fit(
    views: &[View],
    model: &CameraModel,
    r_bc: &UnitQuaternion<f64>,
    input: &RigInput,
) -> Result<Fit, Box<dyn std::error::Error>> {
    // Body orientation (target ← body) per posed frame, by time [s on the IMU's axis].
    let mut posed: Vec<(f64, UnitQuaternion<f64>)> = Vec::new();
    for v in views.iter().filter(|v| v.corners.len() >= TARGET_TRUTH_MIN_CORNERS) {
        let Some((t_ct, rms)) = refine_view_pose(v, model) else { continue };
        if rms > MAX_RMS_PX {
            continue;
        }
        let (r, _) = tumble::model::geometry::parts(&t_ct);
        let r_ct = UnitQuaternion::from_matrix(&r);
        posed.push(((v.t_ns - input.imu_t0_ns) as f64 * 1e-9, r_ct.inverse() * r_bc.inverse()));
    }
    let (t_imu, gyro) = (&input.imu.t, &input.imu.gyro);
    let mut pairs = Vec::new();
    let mut i = 0;
    while i < posed.len() {
        let (t0, q0) = posed[i];
        // The frame SPAN_S later (within half a frame), else move on.
        let Some(j) = (i + 1..posed.len()).find(|&j| posed[j].0 - t0 >= SPAN_S - 0.025) else { break };
        let (t1, q1) = posed[j];
        if t1 - t0 > SPAN_S + 0.025 || t0 < t_imu[0] || t1 > t_imu[t_imu.len() - 1] {
            i += 1;
            continue;
        }
        pairs.push(pair(t_imu, gyro, t0, t1, &(q0.inverse() * q1)));
        i = j + 1;
    }
    let n = pairs.len();
    if n < 20 {
        return Err(format!("only {n} frame pairs with a pose: nothing to fit").into());
    }
    // Unweighted, then weighted by each axis's residual variance.
    let mut w = Vector3::repeat(1.0);
    let mut out = None;
    for _ in 0..2 {
        let mut h = nalgebra::SMatrix::<f64, 12, 12>::zeros();
        let mut g = nalgebra::SVector::<f64, 12>::zeros();
        for p in &pairs {
            let d = Matrix3::from_diagonal(&w.map(|x| 1.0 / x));
            h += p.design.transpose() * d * p.design;
            g += p.design.transpose() * d * p.e;
        }
        let cov = h.try_inverse().ok_or("the pairs do not determine M (no rotation?)")?;
        let beta = cov * g;
        let mut ss = Vector3::zeros();
        for p in &pairs {
            let r = p.e - p.design * beta;
            ss += r.component_mul(&r);
        }
        let var = ss / (n as f64 - 4.0);
        // χ²/dof of the weighted fit scales the covariance (1 after the reweighting).
        let chi2: f64 = (0..3).map(|a| ss[a] / w[a]).sum::<f64>() / (3.0 * n as f64 - 12.0);
        let m = Matrix3::from_fn(|r, c| beta[3 + 3 * c + r]);
        let sigma = Matrix3::from_fn(|r, c| (chi2 * cov[(3 + 3 * c + r, 3 + 3 * c + r)]).sqrt());
        out = Some(Fit { m, sigma, pairs: n, rms_deg: (ss.sum() / (3 * n) as f64).sqrt().to_degrees() });
        w = var;
    }
    out.ok_or_else(|| "no fit".into())
}

/// The pair from `t0` to `t1` \[s\] with the camera's rotation `camera`:
/// the gyro integrated by the midpoint rule (end intervals cut at `t0` and
/// `t1`), `e = Log(ΔR_gyro⁻¹ camera)` and the design of `b` and `M`.
fn pair(t: &[f64], gyro: &[Vector3<f64>], t0: f64, t1: f64, camera: &UnitQuaternion<f64>) -> Pair {
    // Per step: its rate × duration, and the rotation from its start.
    let mut steps: Vec<(Vector3<f64>, f64, UnitQuaternion<f64>)> = Vec::new();
    let mut r = UnitQuaternion::identity();
    let first = t.partition_point(|&s| s <= t0).saturating_sub(1);
    for k in first..t.len() - 1 {
        if t[k] >= t1 {
            break;
        }
        let (a, b) = (t[k].max(t0), t[k + 1].min(t1));
        if b > a {
            let w = 0.5 * (gyro[k] + gyro[k + 1]);
            steps.push((w, b - a, r));
            r *= UnitQuaternion::from_scaled_axis(w * (b - a));
        }
    }
    let total = r;
    let mut design = nalgebra::SMatrix::<f64, 3, 12>::zeros();
    for (w, dt, start) in &steps {
        // Rotation from the end of this step to the pair's end, as a matrix
        // taking vectors of this step's frame into the end's.
        let after = (start * UnitQuaternion::from_scaled_axis(w * *dt)).inverse() * total;
        let p = after.inverse().to_rotation_matrix().into_inner();
        for c in 0..3 {
            design.fixed_view_mut::<3, 1>(0, c).axpy(*dt, &p.column(c), 1.0);
            for r in 0..3 {
                // M's column c (rate component c) into row r of M ω.
                let mut e_r = Vector3::zeros();
                e_r[r] = w[c] * dt;
                design.fixed_view_mut::<3, 1>(0, 3 + 3 * c + r).axpy(1.0, &(p * e_r), 1.0);
            }
        }
    }
    Pair { design, e: (total.inverse() * camera).scaled_axis() }
}

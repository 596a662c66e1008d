//! `tumble export`: every target's files written from one results folder and
//! parsed back — keys, noise convention and inflation, frames (the intrinsics
//! and extrinsics reproduce tumble's model on a test vector).

use nalgebra::{Isometry3, Matrix3, Translation3, UnitQuaternion, Vector3};
use serde::Deserialize;
use std::path::{Path, PathBuf};
use tumble::export::{export, ExportInputs, ExportSources, Target};
use tumble::model::calibration::{CalibrationFile, EffectTerm, ImuCalibration, ModelEffects, TimeOffsets, Triad};
use tumble_factors::imu_effects::Effect;

const RATE: f64 = 200.0;
const GN: f64 = 1.7e-4;
const AN: f64 = 2.0e-3;
const GW: f64 = 1.9e-5;
const AW: f64 = 3.0e-3;

fn calibration() -> ImuCalibration {
    let mut c = ImuCalibration::identity();
    c.accel = Triad {
        t: Matrix3::new(1.0, -0.011, -0.0078, 0.0, 1.0, 0.015, 0.0, 0.0, 1.0),
        k: Vector3::new(0.995, 1.002, 0.9999),
        b: Vector3::new(0.008, 0.12, -0.019),
        ..Triad::identity()
    };
    c.gyro = Triad {
        t: Matrix3::new(1.0, -0.0098, -0.0166, 0.0084, 1.0, 0.0037, 0.0163, 0.0070, 1.0),
        k: Vector3::new(0.994, 0.999, 0.9954),
        b: Vector3::new(-3.7e-4, 1.8e-4, -6e-4),
        ..Triad::identity()
    };
    let g = [3.8e-4, 1.4e-4, -3.8e-5, -8.8e-5, 3.3e-4, 1.1e-4, 1e-4, -1.5e-4, 9.8e-5];
    c.effects = Some(ModelEffects {
        reference_temperature_c: 25.0,
        reference_time_s: 0.0,
        effects: vec![EffectTerm::new(Effect::GyroGSensitivity, &g, None)],
    });
    c.time_offsets = Some(TimeOffsets { camera_imu_s: 0.0031, ..Default::default() });
    c
}

fn t_bs(q: UnitQuaternion<f64>, t: [f64; 3]) -> Isometry3<f64> {
    Isometry3::from_parts(Translation3::new(t[0], t[1], t[2]), q)
}

fn yaml_4x4(m: &Isometry3<f64>) -> String {
    let h = m.to_homogeneous();
    let d: Vec<String> = (0..4).flat_map(|i| (0..4).map(move |j| format!("{:?}", h[(i, j)]))).collect();
    format!("T_BS:\n  cols: 4\n  rows: 4\n  data: [{}]\n", d.join(", "))
}

/// A results folder (calibration, noise, audit) and an ASL folder with two cameras.
fn setup(name: &str) -> (PathBuf, PathBuf, [Isometry3<f64>; 2]) {
    let d = std::env::temp_dir().join(format!("tumble-export-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    let res = d.join("results");
    std::fs::create_dir_all(res.join("allan")).unwrap();
    std::fs::create_dir_all(res.join("calibrate")).unwrap();
    std::fs::create_dir_all(res.join("audit")).unwrap();
    let file = CalibrationFile::from(&calibration());
    std::fs::write(res.join("calibrate/calibration.json"), serde_json::to_string_pretty(&file).unwrap()).unwrap();
    let keys = tumble::model::noise::kalibr_keys([GN, AN, GW, AW], RATE);
    std::fs::write(res.join("allan/imu.yaml"), format!("rostopic: /bmi088/imu\n{keys}")).unwrap();
    // In motion the gyro residuals are 2.25× (variance) what the noise predicts: ×1.5 on its density.
    // The gyro walk the audit assumed (1e-4, scale ≈ 1) with chi2/n 0.02 implies 1.4e-5 < imu.yaml's: ×1.
    // The accelerometer's assumed 1e-3 with chi2/n 16 implies 4e-3 > imu.yaml's 3e-3: ×4/3.
    let audit = r#"{"final_groups": {"rotation": {"chi2": 225.0, "residuals": 100},
        "accel_norm": {"chi2": 40.0, "residuals": 50}, "gyro_bias_walk": {"chi2": 3.0, "residuals": 150},
        "accel_bias_walk": {"chi2": 2400.0, "residuals": 150}},
        "random_walk_raw": {"gyro": 0.0000996, "accel": 0.0009988}}"#;
    std::fs::write(res.join("audit/audit.json"), audit).unwrap();
    let asl = d.join("asl/mav0");
    let cams = [
        t_bs(UnitQuaternion::from_euler_angles(-1.57, 0.01, -1.55), [-0.0216, -0.0647, 0.0098]),
        t_bs(UnitQuaternion::from_euler_angles(-1.56, 0.02, -1.56), [-0.0198, 0.0454, 0.0079]),
    ];
    std::fs::create_dir_all(asl.join("imu0")).unwrap();
    std::fs::write(asl.join("imu0/sensor.yaml"), "sensor_type: imu\nrate_hz: 200\n").unwrap();
    for (i, t) in cams.iter().enumerate() {
        std::fs::create_dir_all(asl.join(format!("cam{i}"))).unwrap();
        let y = format!(
            "%YAML:1.0\nsensor_type: camera\n{}rate_hz: 20\nresolution: [752, 480]\ncamera_model: pinhole\nintrinsics: [458.654, 457.296, 367.215, 248.375]\ndistortion_model: radial-tangential\ndistortion_coefficients: [-0.2834, 0.0740, 0.00019, 1.76e-05]\n",
            yaml_4x4(t)
        );
        std::fs::write(asl.join(format!("cam{i}/sensor.yaml")), y).unwrap();
    }
    (res, d.join("asl"), cams)
}

fn inputs(res: &Path, asl: &Path) -> ExportInputs {
    ExportInputs::gather(&ExportSources {
        results: Some(res.to_path_buf()),
        asl: Some(asl.to_path_buf()),
        ..Default::default()
    })
    .unwrap()
}

fn read(p: &Path) -> String {
    std::fs::read_to_string(p).unwrap()
}

fn parse<T: for<'de> Deserialize<'de>>(p: &Path) -> T {
    tumble::io::yaml::parse_yaml(p, &read(p)).unwrap()
}

#[derive(Deserialize)]
struct CvMatrix {
    rows: usize,
    cols: usize,
    data: Vec<f64>,
}

impl CvMatrix {
    fn iso(&self) -> Isometry3<f64> {
        assert_eq!((self.rows, self.cols), (4, 4));
        let m = nalgebra::Matrix4::from_row_slice(&self.data);
        let r = nalgebra::Rotation3::from_matrix_unchecked(m.fixed_view::<3, 3>(0, 0).into_owned());
        Isometry3::from_parts(
            Translation3::new(m[(0, 3)], m[(1, 3)], m[(2, 3)]),
            UnitQuaternion::from_rotation_matrix(&r),
        )
    }
}

fn m3(rows: &[Vec<f64>]) -> Matrix3<f64> {
    Matrix3::from_row_slice(&rows.concat())
}

fn iso_rows(rows: &[Vec<f64>]) -> Isometry3<f64> {
    CvMatrix { rows: 4, cols: 4, data: rows.concat() }.iso()
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-12 * a.abs().max(b.abs()).max(1e-300)
}

fn same_pose(a: &Isometry3<f64>, b: &Isometry3<f64>) -> bool {
    (a.to_homogeneous() - b.to_homogeneous()).norm() < 1e-9
}

/// tumble's forward model: raw readings for a true rate and specific force.
fn raw(c: &ImuCalibration, w: Vector3<f64>, a: Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
    let ma = c.accel.t * Matrix3::from_diagonal(&c.accel.k);
    let mg = c.gyro.t * Matrix3::from_diagonal(&c.gyro.k);
    let g = Matrix3::from_row_slice(&[3.8e-4, 1.4e-4, -3.8e-5, -8.8e-5, 3.3e-4, 1.1e-4, 1e-4, -1.5e-4, 9.8e-5]);
    (mg * (w + g * a) + c.gyro.b, ma * a + c.accel.b)
}

#[test]
fn kalibr_and_openvins_files_parse_back_with_tumbles_model() {
    let (res, asl, cams) = setup("ov");
    let inp = inputs(&res, &asl);
    assert!((inp.inflation.gyro_noise - 1.5).abs() < 1e-12 && inp.inflation.accel_noise == 1.0);
    assert_eq!(inp.inflation.gyro_walk, 1.0);
    let k_a = (0.995 + 1.002 + 0.9999) / 3.0;
    assert!((inp.inflation.accel_walk - 0.0009988 / k_a * 4.0 / AW).abs() < 1e-12, "{:?}", inp.inflation);
    // Kalibr.
    let out = res.parent().unwrap().join("kalibr");
    let r = export(Target::Kalibr, &inp, &out).unwrap();
    assert_eq!(r.files.len(), 2);
    #[derive(Deserialize)]
    struct Imu {
        accelerometer_noise_density: f64,
        gyroscope_noise_density: f64,
        gyroscope_random_walk: f64,
        rostopic: String,
        update_rate: f64,
    }
    let k: Imu = parse(&out.join("imu.yaml"));
    assert!(close(k.gyroscope_noise_density, 1.5 * GN) && close(k.accelerometer_noise_density, AN));
    assert!(close(k.gyroscope_random_walk, GW) && k.rostopic == "/bmi088/imu" && k.update_rate == RATE);
    #[derive(Deserialize)]
    struct KCam {
        #[serde(rename = "T_cam_imu")]
        t_cam_imu: Vec<Vec<f64>>,
        intrinsics: Vec<f64>,
        distortion_model: String,
        timeshift_cam_imu: f64,
    }
    #[derive(Deserialize)]
    struct Chain {
        cam0: KCam,
        cam1: KCam,
    }
    let ch: Chain = parse(&out.join("camchain-imucam.yaml"));
    assert!(same_pose(&iso_rows(&ch.cam0.t_cam_imu), &cams[0].inverse()));
    assert!(same_pose(&iso_rows(&ch.cam1.t_cam_imu), &cams[1].inverse()));
    assert_eq!(
        (ch.cam0.intrinsics[0], ch.cam0.distortion_model.as_str(), ch.cam0.timeshift_cam_imu),
        (458.654, "radtan", 0.0031)
    );
    // OpenVINS: w_m = Tw R_IMUtoGYRO w + Tg a + b_g, a_m = Ta R_IMUtoACC a + b_a.
    let out = res.parent().unwrap().join("openvins");
    export(Target::OpenVins, &inp, &out).unwrap();
    #[derive(Deserialize)]
    #[allow(non_snake_case)]
    struct OvImu {
        Tw: Vec<Vec<f64>>,
        R_IMUtoGYRO: Vec<Vec<f64>>,
        Ta: Vec<Vec<f64>>,
        R_IMUtoACC: Vec<Vec<f64>>,
        Tg: Vec<Vec<f64>>,
        model: String,
        gyroscope_noise_density: f64,
    }
    #[derive(Deserialize)]
    struct Ov {
        imu0: OvImu,
    }
    let ov: Ov = parse(&out.join("kalibr_imu_chain.yaml"));
    let o = ov.imu0;
    assert_eq!(o.model, "rpng");
    assert!(close(o.gyroscope_noise_density, 1.5 * GN));
    let (tw, rg, ta, ra, tg) = (m3(&o.Tw), m3(&o.R_IMUtoGYRO), m3(&o.Ta), m3(&o.R_IMUtoACC), m3(&o.Tg));
    assert!(tw[(1, 0)] == 0.0 && tw[(2, 0)] == 0.0 && tw[(2, 1)] == 0.0 && ta[(1, 0)] == 0.0);
    let c = calibration();
    for (w, a) in [
        (Vector3::new(0.3, -1.2, 0.7), Vector3::new(1.0, 9.0, -2.0)),
        (Vector3::new(-2.0, 0.1, 0.5), Vector3::new(0.0, 0.0, 9.81)),
    ] {
        let (wr, ar) = raw(&c, w, a);
        assert!((tw * rg * w + tg * a + c.gyro.b - wr).norm() < 1e-12, "gyro");
        assert!((ta * ra * a + c.accel.b - ar).norm() < 1e-12, "accel");
    }
    #[derive(Deserialize)]
    #[allow(non_snake_case)]
    struct OvCam {
        T_imu_cam: Vec<Vec<f64>>,
        timeshift_cam_imu: f64,
    }
    #[derive(Deserialize)]
    struct OvCams {
        cam0: OvCam,
    }
    let oc: OvCams = parse(&out.join("kalibr_imucam_chain.yaml"));
    assert!(same_pose(&iso_rows(&oc.cam0.T_imu_cam), &cams[0]) && oc.cam0.timeshift_cam_imu == 0.0031);
}

/// The output folder of `tumble calibrate-rig` as the cameras: its time
/// offset (rig.json) wins over the calibration's audited one.
#[test]
fn a_rig_calibrations_time_offset_is_exported() {
    let (res, asl, _) = setup("rig");
    let rig = res.parent().unwrap().join("rig");
    for cam in ["cam0", "cam1"] {
        std::fs::create_dir_all(rig.join(cam)).unwrap();
        std::fs::copy(asl.join("mav0").join(cam).join("sensor.yaml"), rig.join(cam).join("sensor.yaml")).unwrap();
    }
    std::fs::write(rig.join("rig.json"), r#"{"timeshift_cam_imu_s": 0.0042}"#).unwrap();
    let inp = inputs(&res, &rig);
    assert_eq!(inp.rig_time_offset_s, Some(0.0042));
    assert!(inp.sources.iter().any(|s| s.contains("rig.json")), "{:?}", inp.sources);
    let out = res.parent().unwrap().join("vins-rig");
    export(Target::VinsMono, &inp, &out).unwrap();
    #[derive(Deserialize)]
    struct Td {
        td: f64,
    }
    let v: Td = parse(&out.join("vins_mono_config.yaml"));
    assert_eq!(v.td, 0.0042);
}

#[test]
fn vins_and_orbslam3_files_parse_back_in_their_conventions() {
    let (res, asl, cams) = setup("vins");
    let inp = inputs(&res, &asl);
    let s = RATE.sqrt();
    // VINS-Mono: discrete per-sample sigmas; extrinsics camera → IMU.
    let out = res.parent().unwrap().join("vins-mono");
    let r = export(Target::VinsMono, &inp, &out).unwrap();
    assert!(r.notes.iter().any(|n| n.contains("tumble apply") && n.contains("gyro_g_sensitivity")), "{:?}", r.notes);
    #[derive(Deserialize)]
    #[allow(non_snake_case)]
    struct Vins {
        acc_n: f64,
        gyr_n: f64,
        acc_w: f64,
        gyr_w: f64,
        td: f64,
        image_width: u32,
        extrinsicRotation: CvMatrix,
        extrinsicTranslation: CvMatrix,
        imu_topic: String,
    }
    let v: Vins = parse(&out.join("vins_mono_config.yaml"));
    let aw = AW * inp.inflation.accel_walk;
    assert!(close(v.gyr_n, 1.5 * GN * s) && close(v.acc_n, AN * s) && close(v.gyr_w, GW * s) && close(v.acc_w, aw * s));
    assert_eq!((v.td, v.image_width, v.imu_topic.as_str()), (0.0031, 752, "/bmi088/imu"));
    let rot = Matrix3::from_row_slice(&v.extrinsicRotation.data);
    assert!((rot - cams[0].rotation.to_rotation_matrix().into_inner()).norm() < 1e-12);
    assert!((Vector3::from_row_slice(&v.extrinsicTranslation.data) - cams[0].translation.vector).norm() < 1e-12);
    // VINS-Fusion: main file plus one per camera.
    let out = res.parent().unwrap().join("vins-fusion");
    let r = export(Target::VinsFusion, &inp, &out).unwrap();
    assert_eq!(r.files.len(), 3);
    #[derive(Deserialize)]
    #[allow(non_snake_case)]
    struct Fusion {
        num_of_cam: u32,
        cam1_calib: String,
        body_T_cam1: CvMatrix,
        acc_n: f64,
    }
    let f: Fusion = parse(&out.join("vins_fusion_config.yaml"));
    assert_eq!((f.num_of_cam, f.cam1_calib.as_str()), (2, "cam1.yaml"));
    assert!(same_pose(&f.body_T_cam1.iso(), &cams[1]) && close(f.acc_n, AN * s));
    #[derive(Deserialize)]
    struct Proj {
        fx: f64,
        cy: f64,
    }
    #[derive(Deserialize)]
    struct Cam {
        model_type: String,
        projection_parameters: Proj,
    }
    let c: Cam = parse(&out.join("cam1.yaml"));
    assert_eq!(
        (c.model_type.as_str(), c.projection_parameters.fx, c.projection_parameters.cy),
        ("PINHOLE", 458.654, 248.375)
    );
    // ORB-SLAM3: continuous densities; T_b_c1 is IMU ← camera.
    let out = res.parent().unwrap().join("orbslam3");
    export(Target::OrbSlam3, &inp, &out).unwrap();
    #[derive(Deserialize)]
    struct Orb {
        #[serde(rename = "File.version")]
        version: String,
        #[serde(rename = "Camera.type")]
        kind: String,
        #[serde(rename = "Camera1.k1")]
        k1: f64,
        #[serde(rename = "IMU.T_b_c1")]
        t_b_c1: CvMatrix,
        #[serde(rename = "IMU.NoiseGyro")]
        noise_gyro: f64,
        #[serde(rename = "IMU.AccWalk")]
        acc_walk: f64,
        #[serde(rename = "IMU.Frequency")]
        frequency: f64,
    }
    let o: Orb = parse(&out.join("orbslam3_settings.yaml"));
    assert_eq!((o.version.as_str(), o.kind.as_str(), o.k1, o.frequency), ("1.0", "PinHole", -0.2834, RATE));
    let aw = AW * inp.inflation.accel_walk;
    assert!(close(o.noise_gyro, 1.5 * GN) && close(o.acc_walk, aw) && same_pose(&o.t_b_c1.iso(), &cams[0]));
}

#[test]
fn basalt_calibration_reproduces_tumbles_correction_in_its_frame() {
    let (res, asl, cams) = setup("basalt");
    let inp = inputs(&res, &asl);
    let out = res.parent().unwrap().join("basalt");
    export(Target::Basalt, &inp, &out).unwrap();
    let j: serde_json::Value = serde_json::from_str(&read(&out.join("calibration.json"))).unwrap();
    let v = &j["value0"];
    let f = |x: &serde_json::Value| x.as_f64().unwrap();
    let a: Vec<f64> = v["calib_accel_bias"].as_array().unwrap().iter().map(f).collect();
    let g: Vec<f64> = v["calib_gyro_bias"].as_array().unwrap().iter().map(f).collect();
    // Basalt: a_c = (I + S_a) a_raw − b_a, S_a lower triangular from [s1..s6] column-wise.
    let sa = Matrix3::new(a[3], 0.0, 0.0, a[4], a[6], 0.0, a[5], a[7], a[8]);
    let ca = Matrix3::identity() + sa;
    let cg = Matrix3::identity() + Matrix3::from_column_slice(&g[3..12]);
    let c = calibration();
    let tq = &v["T_imu_cam"][0];
    let basalt_cam = Isometry3::from_parts(
        Translation3::new(f(&tq["px"]), f(&tq["py"]), f(&tq["pz"])),
        UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
            f(&tq["qw"]),
            f(&tq["qx"]),
            f(&tq["qy"]),
            f(&tq["qz"]),
        )),
    );
    // The frame rotation Q: Basalt's camera pose = Q · tumble's.
    let q = (basalt_cam * cams[0].inverse()).rotation;
    assert!((basalt_cam.translation.vector - q * cams[0].translation.vector).norm() < 1e-12);
    // Without g-sensitivity (Basalt has none) the corrected readings are Q · truth.
    let mut plain = c.clone();
    plain.effects = None;
    for (w, acc) in [
        (Vector3::new(0.3, -1.2, 0.7), Vector3::new(1.0, 9.0, -2.0)),
        (Vector3::new(-1.0, 0.2, 0.0), Vector3::new(0.0, 0.5, 9.8)),
    ] {
        let ma = plain.accel.t * Matrix3::from_diagonal(&plain.accel.k);
        let mg = plain.gyro.t * Matrix3::from_diagonal(&plain.gyro.k);
        let (wr, ar) = (mg * w + plain.gyro.b, ma * acc + plain.accel.b);
        let ab = ca * ar - Vector3::new(a[0], a[1], a[2]);
        let wb = cg * wr - Vector3::new(g[0], g[1], g[2]);
        assert!((ab - q * acc).norm() < 1e-10, "accel {ab} vs {}", q * acc);
        assert!((wb - q * w).norm() < 1e-10, "gyro");
    }
    assert_eq!(v["cam_time_offset_ns"].as_i64(), Some(3_100_000));
    let aw = AW * inp.inflation.accel_walk;
    assert!(close(f(&v["gyro_noise_std"][2]), 1.5 * GN) && close(f(&v["accel_bias_std"][0]), aw));
    assert_eq!(v["intrinsics"][0]["camera_type"], "pinhole-radtan8");
}

#[test]
fn missing_inputs_are_named() {
    let d = std::env::temp_dir().join(format!("tumble-export-{}-empty", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    let e = ExportInputs::gather(&ExportSources { results: Some(d.clone()), ..Default::default() }).unwrap_err();
    assert!(e.to_string().contains("no imu.yaml"), "{e}");
    let (res, _, _) = setup("nocam");
    let inp = ExportInputs::gather(&ExportSources { results: Some(res.clone()), ..Default::default() }).unwrap();
    let e = export(Target::VinsMono, &inp, &res.join("out")).unwrap_err().to_string();
    assert!(e.contains("needs a camera") && e.contains("--asl"), "{e}");
    assert!(!res.join("out").join("vins_mono_config.yaml").exists());
    assert!("vins".parse::<Target>().unwrap_err().contains("vins-mono"));
}

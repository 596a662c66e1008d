//! Recording readers: real datasets load with the right counts and units, and
//! every bad input gives an error naming file and line (or a warning), never a panic.

use std::path::{Path, PathBuf};
use tumble::io::asl::{read_asl, read_camera_sensor, read_imu_sensor};
use tumble::io::trajectory::{read_trajectory, write_asl_groundtruth, write_tum, Trajectory};
use tumble::io::validate::{Duplicates, ValidateOptions};
use tumble::io::{read_imu_text, read_imu_tk, AccelUnit, GyroUnit, ImuColumns, ImuTextFormat, Stored, TimeUnit};

mod common;
use common::shared;

fn tmp(name: &str, text: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("tumble-io-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

/// A static 200 Hz recording in EuRoC CSV layout with the given values.
fn euroc_csv(n: usize, gyro: [f64; 3], accel: [f64; 3]) -> String {
    let mut s = String::from("#timestamp [ns],wx,wy,wz,ax,ay,az\n");
    for i in 0..n {
        let t = 1_000_000_000_000i64 + i as i64 * 5_000_000;
        let jitter = (i % 7) as f64 * 1e-4;
        s.push_str(&format!(
            "{t},{},{},{},{},{},{}\n",
            gyro[0] + jitter,
            gyro[1],
            gyro[2],
            accel[0] + jitter,
            accel[1],
            accel[2]
        ));
    }
    s
}

#[test]
fn euroc_folder_loads_from_dataset_or_mav0() {
    let Some(ds) = shared("euroc/V1_01_easy_micro") else { return };
    for p in [ds.clone(), ds.join("mav0")] {
        let d = read_asl(&p, &ImuTextFormat::default()).unwrap();
        assert_eq!(d.imu.len(), 29_120);
        assert!((d.imu.mean_rate() - 200.0).abs() < 0.5, "{}", d.imu.mean_rate());
        assert_eq!(d.imu.t0_ns, 1_403_715_273_262_142_976);
        assert_eq!(d.cameras.len(), 2);
        assert_eq!(d.cameras[0].frames.len(), 95);
        let m = d.cameras[0].model.unwrap();
        assert_eq!((m.fx, m.cy), (458.654, 248.375));
        assert!((d.cameras[1].t_bs.unwrap().translation.vector.y - 0.0453689425024).abs() < 1e-12);
        let s = d.imu_sensor.as_ref().unwrap();
        assert_eq!(s.gyroscope_noise_density, Some(1.6968e-04));
        assert!(d.cameras[0].frames[0].1.is_file());
    }
}

#[test]
fn euroc_groundtruth_with_biases() {
    let Some(ds) = shared("euroc/V1_02_medium_40s") else { return };
    let d = read_asl(&ds, &ImuTextFormat::default()).unwrap();
    let gt = d.groundtruth.expect("gt0");
    assert!(gt.len() > 1000);
    assert_eq!(gt.bias_gyro.as_ref().unwrap()[0], [-0.002153, 0.020744, 0.075806]);
    let Some(f) = shared("euroc/groundtruth/V1_01_easy.csv") else { return };
    let gt = read_trajectory(&f).unwrap();
    assert!(gt.bias_accel.is_some() && gt.len() > 2000);
}

#[test]
fn imu_tk_xsens_counts_and_t265_duplicates() {
    let checks = ValidateOptions::default();
    if let Some(d) = shared("imu_tk_xsens") {
        let counts = AccelUnit::Counts { scale: None, offset: 0.0 };
        let gcounts = GyroUnit::Counts { scale: None, offset: 0.0 };
        let r = read_imu_tk(&d.join("xsens_acc.mat"), &d.join("xsens_gyro.mat"), TimeUnit::S, counts, gcounts, &checks)
            .unwrap();
        assert_eq!(r.len(), 51_175);
        assert_eq!(r.accel_units, Stored::RawCounts);
        assert_eq!(r.accel[0], [33108.0, 33329.0, 36429.0]);
        assert!((r.duration() - 511.7).abs() < 0.5);
    }
    if let Some(d) = shared("imu_tk_t265") {
        let r = read_imu_tk(
            &d.join("t265_acc.mat"),
            &d.join("t265_gyr.mat"),
            TimeUnit::S,
            AccelUnit::MetersPerS2,
            GyroUnit::RadPerS,
            &checks,
        )
        .unwrap();
        let w = r.warnings.join("\n");
        assert!(w.contains("duplicated timestamps") && w.contains("re-stamped"), "{w}");
        assert!((r.mean_rate() - 200.0).abs() < 2.0, "{}", r.mean_rate());
        assert!(r.t.windows(2).all(|w| w[1] > w[0]));
        let strict = ValidateOptions { duplicates: Duplicates::Error, ..checks };
        let e = read_imu_tk(
            &d.join("t265_acc.mat"),
            &d.join("t265_gyr.mat"),
            TimeUnit::S,
            AccelUnit::MetersPerS2,
            GyroUnit::RadPerS,
            &strict,
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("t265_acc.mat:") && e.contains("duplicated"), "{e}");
    }
}

#[test]
fn plain_csv_with_units_and_temperature() {
    let mut s = String::from("time_ms,ax,ay,az,gx,gy,gz,temperature [degC]\n");
    for i in 0..400 {
        s.push_str(&format!("{},0.01,0.0,1.0,0.1,0.2,{},25.5\n", i * 5, (i % 3) as f64 * 0.05));
    }
    let p = tmp("plain.csv", &s);
    let fmt = ImuTextFormat {
        columns: ImuColumns::parse("t,ax,ay,az,gx,gy,gz").unwrap(),
        time_unit: TimeUnit::Ms,
        gyro_unit: GyroUnit::DegPerS,
        accel_unit: AccelUnit::G,
        ..ImuTextFormat::default()
    };
    let r = read_imu_text(&p, &fmt).unwrap();
    assert_eq!(r.len(), 400);
    assert!((r.accel[0][2] - 9.80665).abs() < 1e-12);
    assert!((r.gyro[0][1] - 0.2f64.to_radians()).abs() < 1e-15);
    assert_eq!(r.temperature.as_ref().unwrap()[3], 25.5);
    assert!((r.t[1] - 0.005).abs() < 1e-12);
    assert!(r.warnings.is_empty(), "{:?}", r.warnings);
    // The overview PNG: three panels with the temperature, taller than two.
    let png = p.with_extension("png");
    tumble::inspect::write_overview_png(&r, &png).unwrap();
    let size = |p: &Path| {
        let b = std::fs::read(p).unwrap();
        assert_eq!(&b[1..4], b"PNG");
        u32::from_be_bytes([b[20], b[21], b[22], b[23]])
    };
    assert_eq!(size(&png), 1150);
    let mut no_temp = r.clone();
    no_temp.temperature = None;
    tumble::inspect::write_overview_png(&no_temp, &png).unwrap();
    assert_eq!(size(&png), 900);
    let empty = tumble::io::ImuRecording::default();
    assert!(tumble::inspect::write_overview_png(&empty, &png).unwrap_err().to_string().contains("no samples"));
}

fn err_of(text: &str, fmt: &ImuTextFormat) -> String {
    let p = tmp("bad.csv", text);
    match read_imu_text(&p, fmt) {
        Ok(r) => panic!("accepted bad input; warnings {:?}", r.warnings),
        Err(e) => e.to_string(),
    }
}

#[test]
fn bad_recordings_give_located_errors() {
    let f = ImuTextFormat::default();
    let good = euroc_csv(400, [0.001, 0.0, 0.0], [0.0, 0.0, 9.81]);
    let mut lines: Vec<&str> = good.lines().collect();
    // Unsorted.
    lines.swap(10, 11);
    let e = err_of(&lines.join("\n"), &f);
    assert!(e.contains("bad.csv:12:") && e.contains("backwards"), "{e}");
    // Non-finite.
    let e = err_of(&good.replacen(",9.81\n", ",inf\n", 1), &f);
    assert!(e.contains("bad.csv:2:") && e.contains("not finite"), "{e}");
    // Truncated last line.
    let trunc = &good[..good.len() - 20];
    let e = err_of(trunc, &f);
    assert!(e.contains("bad.csv:401:") && e.contains("truncated"), "{e}");
    // Empty.
    let e = err_of("", &f);
    assert!(e.contains("no data rows"), "{e}");
    let e = err_of("#timestamp\n", &f);
    assert!(e.contains("no data rows"), "{e}");
    // Accelerometer in g read as m/s².
    let e = err_of(&euroc_csv(400, [0.001, 0.0, 0.0], [0.0, 0.0, 1.0]), &f);
    assert!(e.contains("1 g") && e.contains("hint: declare the accelerometer unit as g"), "{e}");
    // Gyro in deg/s read as rad/s (bias of 2 deg/s).
    let e = err_of(&euroc_csv(400, [2.0, -1.5, 0.5], [0.0, 0.0, 9.81]), &f);
    assert!(e.contains("rad/s") && e.contains("deg/s"), "{e}");
    // Raw counts as m/s².
    let e = err_of(&euroc_csv(400, [0.0, 0.0, 0.0], [32768.0, 32768.0, 36000.0]), &f);
    assert!(e.contains("raw counts"), "{e}");
}

#[test]
fn gaps_and_saturation_are_warned_and_located() {
    let good = euroc_csv(600, [0.001, 0.0, 0.0], [0.0, 0.0, 9.81]);
    let mut lines: Vec<String> = good.lines().map(String::from).collect();
    lines.drain(300..320); // a 20-sample gap after data line 299
    for l in lines.iter_mut().skip(400).take(8) {
        // gyro z flat at its extreme for 8 samples
        let mut f: Vec<String> = l.split(',').map(String::from).collect();
        f[3] = "8.7".into();
        *l = f.join(",");
    }
    let p = tmp("gappy.csv", &lines.join("\n"));
    let r = read_imu_text(&p, &ImuTextFormat::default()).unwrap();
    let w = r.warnings.join("\n");
    assert!(w.contains("1 gaps longer than 2 nominal periods") && w.contains("line 301"), "{w}");
    assert!(w.contains("gyro z is flat at 8.7") && w.contains("8 samples from line 401"), "{w}");
}

#[test]
fn column_maps_and_units_parse_with_clear_errors() {
    assert!(ImuColumns::parse("t,gx,gy").unwrap_err().to_string().contains("all three axes"));
    assert!(ImuColumns::parse("t,gx,gy,gz,gx").unwrap_err().to_string().contains("named twice"));
    assert_eq!(ImuColumns::parse("gx,gy,gz").unwrap().time, None);
    assert!(ImuColumns::parse("t,foo").unwrap_err().to_string().contains("unknown column name 'foo'"));
    assert_eq!(GyroUnit::parse("counts:0.001:32768"), Ok(GyroUnit::Counts { scale: Some(0.001), offset: 32768.0 }));
    assert!(AccelUnit::parse("furlongs").is_err());
    // A zero, infinite or missing-number scale would make every sample 0 or NaN.
    for bad in ["counts:0", "counts:-0", "counts:inf", "counts:1:nan", "counts:1:2:3", "counts:x"] {
        assert!(GyroUnit::parse(bad).is_err(), "{bad}");
        assert!(AccelUnit::parse(bad).is_err(), "{bad}");
    }
    assert!(GyroUnit::parse("counts:0").unwrap_err().to_string().contains("non-zero"));
    assert_eq!(GyroUnit::parse("counts:-0.5"), Ok(GyroUnit::Counts { scale: Some(-0.5), offset: 0.0 }));
    // Counts with a scale convert to SI.
    let mut s = String::new();
    for i in 0..300 {
        s.push_str(&format!("{} 100 100 1100\n", i as f64 * 0.01));
    }
    let p = tmp("counts.txt", &s);
    let fmt = ImuTextFormat {
        columns: ImuColumns::parse("t,ax,ay,az").unwrap(),
        time_unit: TimeUnit::S,
        accel_unit: AccelUnit::Counts { scale: Some(0.01), offset: 100.0 },
        ..ImuTextFormat::default()
    };
    let r = read_imu_text(&p, &fmt).unwrap();
    assert_eq!(r.accel[0], [0.0, 0.0, 10.0]);
    assert!(r.gyro.is_empty());
}

#[test]
fn imu_tk_pair_with_other_stamps_is_merged_onto_the_gyro() {
    let a = tmp("a.txt", "0 1 2 3\n0.01 1 4 3\n0.02 1 2 3\n");
    let c = AccelUnit::Counts { scale: None, offset: 0.0 };
    let gc = GyroUnit::Counts { scale: None, offset: 0.0 };
    // A gyro line missing, and a gyro sample after the accelerometer's last: dropped, not extrapolated.
    let g = tmp("g2.txt", "0 1 2 3\n0.005 1 2 3\n0.05 1 2 3\n");
    let r = read_imu_tk(&a, &g, TimeUnit::S, c, gc, &ValidateOptions::default()).unwrap();
    assert_eq!(r.t, vec![0.0, 0.005]);
    assert_eq!(r.accel[1], [1.0, 3.0, 3.0]);
    assert!(r
        .warnings
        .iter()
        .any(|w| w.contains("merged onto the gyro's stamps") && w.contains("1 gyro samples outside")));
    let g = tmp("g3.txt", "5 1 2 3\n5.01 1 2 3\n");
    let e = read_imu_tk(&a, &g, TimeUnit::S, c, gc, &ValidateOptions::default()).unwrap_err().to_string();
    assert!(e.contains("g3.txt") && e.contains("do not overlap"), "{e}");
}

#[test]
fn sensor_yaml_errors() {
    let good = "%YAML:1.0\nsensor_type: camera\nT_BS:\n  cols: 4\n  rows: 4\n  data: [1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1]\nrate_hz: 20\nresolution: [752, 480]\ncamera_model: pinhole\nintrinsics: [458.6, 457.3, 367.2, 248.4]\ndistortion_model: equidistant\ndistortion_coefficients: [0.1, 0.01, 0.0, 0.0]\n";
    let (m, t, r, _) = read_camera_sensor(&tmp("cam.yaml", good)).unwrap();
    assert!(matches!(m.distortion, tumble_factors::camera::Distortion::Equidistant { .. }));
    assert!(t.is_some() && r == Some([752, 480]));
    for (text, what) in [
        (good.replace("intrinsics: [458.6, 457.3, 367.2, 248.4]\n", ""), "missing intrinsics"),
        (good.replace("[0.1, 0.01, 0.0, 0.0]", "[0.1]"), "needs 4"),
        (good.replace("equidistant", "kb8"), "not supported"),
        (good.replace("data: [1,0,0,0,", "data: [2,0,0,0,"), "not a rotation"),
        (good.replace("rate_hz: 20", "rate_hz: [20"), "cam.yaml:"),
    ] {
        let e = read_camera_sensor(&tmp("cam.yaml", &text)).unwrap_err().to_string();
        assert!(e.contains(what) && e.contains("cam.yaml"), "{what}: {e}");
    }
    let e = read_imu_sensor(&tmp("imu.yaml", "rate_hz: -5\n")).unwrap_err().to_string();
    assert!(e.contains("rate_hz must be positive"), "{e}");
    let axes = "rate_hz: 200\naxes:\n  accelerometer_noise_density: [0.02, 0.02, 0.04]\n  accelerometer_random_walk: [3e-4, 3e-4, 3e-4]\n  gyroscope_noise_density: [1e-3, 1e-3, 5e-3]\n  gyroscope_random_walk: [2e-5, 2e-5, 2e-5]\n";
    assert_eq!(read_imu_sensor(&tmp("imu.yaml", axes)).unwrap().axes.unwrap().gyroscope_noise_density[2], 5e-3);
    let e = read_imu_sensor(&tmp("imu.yaml", &axes.replace("[1e-3, 1e-3, 5e-3]", "[1e-3, .nan, 5e-3]")))
        .unwrap_err()
        .to_string();
    assert!(e.contains("imu.yaml") && e.contains("axes.gyroscope_noise_density"), "{e}");
    let e =
        read_imu_sensor(&tmp("imu.yaml", &axes.replace("[2e-5, 2e-5, 2e-5]", "[2e-5, 2e-5]"))).unwrap_err().to_string();
    assert!(e.contains("imu.yaml:6") && e.contains("length 3"), "{e}");
    let e = read_asl(Path::new("/nonexistent/folder"), &ImuTextFormat::default()).unwrap_err().to_string();
    assert!(e.contains("does not exist"), "{e}");
    let e = read_asl(&std::env::temp_dir(), &ImuTextFormat::default()).unwrap_err().to_string();
    assert!(e.contains("not an ASL dataset"), "{e}");
}

#[test]
fn trajectories_round_trip_in_both_formats() {
    let tr = Trajectory {
        t_ns: vec![1_403_715_273_262_142_976, 1_403_715_273_312_143_104],
        p: vec![[1.0, 2.0, 3.0], [1.5, -2.0, 0.25]],
        q: vec![[1.0, 0.0, 0.0, 0.0], [0.5, 0.5, -0.5, 0.5]],
        v: Some(vec![[0.1, 0.2, 0.3], [0.0, 0.0, 0.0]]),
        bias_gyro: Some(vec![[1e-3, 2e-3, 3e-3]; 2]),
        bias_accel: Some(vec![[0.01, -0.02, 0.03]; 2]),
    };
    let p = tmp("gt.csv", "");
    write_asl_groundtruth(&p, &tr).unwrap();
    assert_eq!(read_trajectory(&p).unwrap(), tr);
    let p = tmp("traj.txt", "");
    write_tum(&p, &tr).unwrap();
    let back = read_trajectory(&p).unwrap();
    assert_eq!(back.p, tr.p);
    assert_eq!(back.q, tr.q);
    for (a, b) in back.t_ns.iter().zip(&tr.t_ns) {
        assert!((a - b).abs() < 1000, "{a} {b}");
    }
    // TUM with nanosecond stamps (as some tools write it): TUM's column order, not ASL's.
    let ns = tmp("tum_ns.txt", "1403715273262142976 1 2 3 0.5 0.5 -0.5 0.5\n1403715273312143104 1 2 3 0 0 0 1\n");
    let back = read_trajectory(&ns).unwrap();
    assert_eq!(back.t_ns[0], 1_403_715_273_262_142_976);
    assert_eq!(back.q[0], [0.5, 0.5, 0.5, -0.5]);
    assert_eq!(back.q[1], [1.0, 0.0, 0.0, 0.0]);
    let e = read_trajectory(&tmp("badq.txt", "0 0 0 0 0 0 0 2\n")).unwrap_err().to_string();
    assert!(e.contains("badq.txt:1:") && e.contains("quaternion norm"), "{e}");
    let e = read_trajectory(&tmp("dupt.txt", "0 0 0 0 0 0 0 1\n0 0 0 0 0 0 0 1\n")).unwrap_err().to_string();
    assert!(e.contains("dupt.txt:2:") && e.contains("repeats"), "{e}");
}

/// A ROS 1 `sensor_msgs/Imu` message.
fn ros1_imu(t_ns: i64, w: [f64; 3], a: [f64; 3]) -> Vec<u8> {
    let mut b = Vec::new();
    b.extend(0u32.to_le_bytes());
    b.extend(((t_ns / 1_000_000_000) as u32).to_le_bytes());
    b.extend(((t_ns % 1_000_000_000) as u32).to_le_bytes());
    b.extend(3u32.to_le_bytes());
    b.extend(b"imu");
    let mut f = vec![0.0; 13];
    f.extend(w);
    f.extend([0.0; 9]);
    f.extend(a);
    f.extend([0.0; 9]);
    f.iter().for_each(|v| b.extend(v.to_le_bytes()));
    b
}

/// A bag record: header fields (name, value bytes) and data.
fn bag_record(fields: &[(&str, Vec<u8>)], data: &[u8]) -> Vec<u8> {
    let mut h = Vec::new();
    for (name, value) in fields {
        h.extend(((name.len() + 1 + value.len()) as u32).to_le_bytes());
        h.extend(name.as_bytes());
        h.push(b'=');
        h.extend(value);
    }
    let mut r = (h.len() as u32).to_le_bytes().to_vec();
    r.extend(h);
    r.extend((data.len() as u32).to_le_bytes());
    r.extend(data);
    r
}

/// A minimal uncompressed ROS 1 bag (v2.0) with one IMU topic.
fn ros1_bag(n: usize, index_pos_override: Option<u64>) -> Vec<u8> {
    let conn_data = bag_record(
        &[
            ("topic", b"/imu0".to_vec()),
            ("type", b"sensor_msgs/Imu".to_vec()),
            ("md5sum", b"6a62c6daae103f4ff57a132d6f95cec2".to_vec()),
            ("message_definition", b"...".to_vec()),
        ],
        &[],
    );
    // A connection record's data is the field block alone (no lengths around it).
    let conn_fields = &conn_data[4..conn_data.len() - 4];
    let mut chunk = bag_record(
        &[("op", vec![7]), ("conn", 0u32.to_le_bytes().to_vec()), ("topic", b"/imu0".to_vec())],
        conn_fields,
    );
    for i in 0..n {
        let t = 1_600_000_000_000_000_000i64 + i as i64 * 5_000_000;
        let time = [((t / 1_000_000_000) as u32).to_le_bytes(), ((t % 1_000_000_000) as u32).to_le_bytes()].concat();
        let msg = ros1_imu(t, [0.01, -0.02, 0.001 * (i % 3) as f64], [0.1, 0.2, 9.8]);
        chunk.extend(bag_record(&[("op", vec![2]), ("conn", 0u32.to_le_bytes().to_vec()), ("time", time)], &msg));
    }
    let chunk_rec = bag_record(
        &[("op", vec![5]), ("compression", b"none".to_vec()), ("size", (chunk.len() as u32).to_le_bytes().to_vec())],
        &chunk,
    );
    let mut out = b"#ROSBAG V2.0\n".to_vec();
    let header_len = bag_record(
        &[
            ("op", vec![3]),
            ("index_pos", 0u64.to_le_bytes().to_vec()),
            ("conn_count", 1u32.to_le_bytes().to_vec()),
            ("chunk_count", 1u32.to_le_bytes().to_vec()),
        ],
        &[],
    )
    .len();
    let index_pos = index_pos_override.unwrap_or((out.len() + header_len + chunk_rec.len()) as u64);
    out.extend(bag_record(
        &[
            ("op", vec![3]),
            ("index_pos", index_pos.to_le_bytes().to_vec()),
            ("conn_count", 1u32.to_le_bytes().to_vec()),
            ("chunk_count", 1u32.to_le_bytes().to_vec()),
        ],
        &[],
    ));
    out.extend(chunk_rec);
    out
}

#[test]
fn ros1_bag_imu_topic_reads_and_bad_bags_are_refused() {
    let opts = tumble::io::RecordingOptions::default();
    let dir = std::env::temp_dir().join(format!("tumble-io-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join("imu.bag");
    std::fs::write(&p, ros1_bag(400, None)).unwrap();
    let r = tumble::io::open_recording(&p, &opts).unwrap();
    assert_eq!(r.len(), 400);
    assert_eq!(r.t0_ns, 1_600_000_000_000_000_000);
    assert!((r.mean_rate() - 200.0).abs() < 1e-6);
    assert_eq!(r.gyro[2], [0.01, -0.02, 0.002]);
    assert_eq!(r.accel[0], [0.1, 0.2, 9.8]);
    let wrong = tumble::io::RecordingOptions {
        topics: tumble::io::ros::ImuTopics { imu: Some("/imu1".into()), ..Default::default() },
        ..Default::default()
    };
    let e = tumble::io::open_recording(&p, &wrong).unwrap_err().to_string();
    assert!(e.contains("no sensor_msgs/Imu topic '/imu1'") && e.contains("/imu0"), "{e}");
    // index_pos beyond the file, inside the header record, or too close to the end for a record.
    let len = ros1_bag(10, None).len() as u64;
    for at in [1 << 40, 20, 40, len - 3] {
        std::fs::write(&p, ros1_bag(10, Some(at))).unwrap();
        let e = tumble::io::open_recording(&p, &opts).unwrap_err().to_string();
        assert!(e.contains("index_pos") && e.contains("does not point past the header record"), "{at}: {e}");
    }
    let good = ros1_bag(400, None);
    std::fs::write(&p, &good[..good.len() / 2]).unwrap();
    assert!(tumble::io::open_recording(&p, &opts).is_err());
    std::fs::write(&p, b"not a bag").unwrap();
    assert!(tumble::io::open_recording(&p, &opts).unwrap_err().to_string().contains("not a ROS 1 bag"));
}

/// A CDR `sensor_msgs/msg/Imu`.
fn cdr_imu(t_ns: i64, w: [f64; 3], a: [f64; 3]) -> Vec<u8> {
    let mut b = vec![0u8, 1, 0, 0];
    b.extend(((t_ns / 1_000_000_000) as i32).to_le_bytes());
    b.extend(((t_ns % 1_000_000_000) as u32).to_le_bytes());
    b.extend(5u32.to_le_bytes());
    b.extend(b"imu0\0");
    while (b.len() - 4) % 8 != 0 {
        b.push(0);
    }
    let mut f = vec![0.0, 0.0, 0.0, 1.0];
    f.extend([0.0; 9]);
    f.extend(w);
    f.extend([0.0; 9]);
    f.extend(a);
    f.extend([0.0; 9]);
    f.iter().for_each(|v| b.extend(v.to_le_bytes()));
    b
}

#[test]
fn mcap_imu_topic_reads() {
    let dir = std::env::temp_dir().join(format!("tumble-io-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join("imu.mcap");
    {
        let mut w = mcap::Writer::new(std::io::BufWriter::new(std::fs::File::create(&p).unwrap())).unwrap();
        let schema = w.add_schema("sensor_msgs/msg/Imu", "ros2msg", b"...").unwrap();
        let ch = w.add_channel(schema, "/imu", "cdr", &Default::default()).unwrap();
        let other = w.add_channel(schema, "/imu_raw", "cdr", &Default::default()).unwrap();
        for i in 0..300u32 {
            let t = 1_700_000_000_000_000_000i64 + i64::from(i) * 10_000_000;
            for c in [ch, other] {
                let h = mcap::records::MessageHeader {
                    channel_id: c,
                    sequence: i,
                    log_time: t as u64,
                    publish_time: t as u64,
                };
                w.write_to_known_channel(&h, &cdr_imu(t, [0.003, 0.0, -0.001], [0.0, 0.5, 9.79])).unwrap();
            }
        }
        w.finish().unwrap();
    }
    let e = tumble::io::open_recording(&p, &Default::default()).unwrap_err().to_string();
    assert!(e.contains("several") && e.contains("/imu_raw"), "{e}");
    let opts = tumble::io::RecordingOptions {
        topics: tumble::io::ros::ImuTopics { imu: Some("/imu".into()), ..Default::default() },
        ..Default::default()
    };
    let r = tumble::io::open_recording(&p, &opts).unwrap();
    assert_eq!(r.len(), 300);
    assert!((r.mean_rate() - 100.0).abs() < 1e-6);
    assert_eq!(r.accel[5], [0.0, 0.5, 9.79]);
    std::fs::write(&p, b"\x89MCAP0\r\n garbage").unwrap();
    assert!(tumble::io::open_recording(&p, &opts).unwrap_err().to_string().contains("MCAP"));
}

/// Phone logger exports: columns found by name (Sensor Logger writes z, y, x), the
/// accelerometer merged onto the gyro's stamps, gravity-free files refused.
#[test]
fn phone_logger_exports_read_by_column_name() {
    let dir = std::env::temp_dir().join(format!("tumble-io-phone-{}", std::process::id()));
    let sl = dir.join("sensor_logger");
    let ph = dir.join("phyphox");
    for d in [&sl, &ph] {
        std::fs::create_dir_all(d).unwrap();
    }
    let (mut g, mut a) = (String::from("time,seconds_elapsed,z,y,x\n"), String::from("time,seconds_elapsed,z,y,x\n"));
    let (mut pg, mut pa) = (
        String::from("\"Time (s)\",\"Gyroscope x (rad/s)\",\"Gyroscope y (rad/s)\",\"Gyroscope z (rad/s)\"\n"),
        String::from(
            "\"Time (s)\",\"Acceleration x (m/s^2)\",\"Acceleration y (m/s^2)\",\"Acceleration z (m/s^2)\",\"Absolute acceleration (m/s^2)\"\n",
        ),
    );
    for i in 0..1000i64 {
        let t = 1_700_000_000_000_000_000 + i * 5_000_000;
        let s = i as f64 * 0.005;
        g.push_str(&format!("{t},{s},0.03,0.02,0.01\n"));
        pg.push_str(&format!("{s},0.01,0.02,0.03\n"));
    }
    for i in 0..400i64 {
        let t = 1_700_000_000_002_000_000 + i * 10_000_000;
        let s = 0.002 + i as f64 * 0.01;
        a.push_str(&format!("{t},{s},9.8,{},0.1\n", s));
        pa.push_str(&format!("{s},0.1,{s},9.8,9.8\n"));
    }
    std::fs::write(sl.join("Gyroscope.csv"), &g).unwrap();
    std::fs::write(sl.join("Accelerometer.csv"), &a).unwrap();
    let e = tumble::io::open_recording(&sl, &Default::default()).unwrap_err().to_string();
    assert!(e.contains("TotalAcceleration.csv") && e.contains("gravity removed"), "{e}");
    std::fs::write(sl.join("TotalAcceleration.csv"), &a).unwrap();
    std::fs::write(ph.join("Gyroscope.csv"), &pg).unwrap();
    std::fs::write(ph.join("Accelerometer.csv"), &pa).unwrap();
    for d in [&sl, &ph] {
        let r = tumble::io::open_recording(d, &Default::default()).unwrap();
        assert_eq!(r.gyro[0], [0.01, 0.02, 0.03], "{}", d.display());
        assert!(r.warnings.iter().any(|w| w.contains("200.0 Hz") && w.contains("100.0 Hz")), "{:?}", r.warnings);
        assert!((r.mean_rate() - 200.0).abs() < 1e-6);
        // The accelerometer's y is its own seconds_elapsed: interpolated at the gyro's stamps.
        for i in 0..r.len() {
            let s = 0.005 * (i + 1) as f64; // the gyro's first stamp precedes the accelerometer's
            assert!((r.accel[i][1] - s).abs() < 1e-9 && r.accel[i][0] == 0.1 && r.accel[i][2] == 9.8, "{i}");
        }
    }
}

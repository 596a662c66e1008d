//! ROS 2 recordings: rosbag2 folders (SQLite and MCAP storage) and bare
//! `.db3` files read exactly like the same samples written as text; split
//! accelerometer/gyro topics and text files merged onto the gyro's stamps;
//! a temperature topic joined; bad bags refused by name.

mod common;

use common::cdr;
use std::path::{Path, PathBuf};
use tumble::io::{open_recording, ImuColumns, RecordingOptions, TimeUnit};

fn dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("tumble-ros2-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// 2000 samples at ≈ 200 Hz with jittered stamps and values that use every digit.
fn samples() -> Vec<(i64, [f64; 3], [f64; 3], f64)> {
    (0..2000i64)
        .map(|i| {
            let t = 1_700_000_000_123_456_789 + i * 5_000_000 + (i * 7919 % 13) * 1000;
            let x = i as f64;
            let w = [0.01 * (x * 0.01).sin(), -0.02 + 1e-5 * x, 0.003 * (x * 0.3).cos()];
            let a = [0.1 + 1e-4 * (x * 0.7).sin(), 0.2 / 3.0, 9.81 - 1e-3 * (x * 0.05).cos()];
            (t, w, a, 25.0 + x * 1e-3)
        })
        .collect()
}

fn imu_messages(topic: &str) -> Vec<cdr::BagMessage> {
    samples()
        .iter()
        .map(|&(t, w, a, _)| (topic.to_string(), "sensor_msgs/msg/Imu".to_string(), t + 300_000, cdr::imu(t, w, a)))
        .collect()
}

fn text_twin(path: &Path) {
    let mut s = String::from("# t gx gy gz ax ay az temp\n");
    for (t, w, a, c) in samples() {
        s.push_str(&format!("{t} {} {} {} {} {} {} {c}\n", w[0], w[1], w[2], a[0], a[1], a[2]));
    }
    std::fs::write(path, s).unwrap();
}

fn text_options() -> RecordingOptions {
    let mut o = RecordingOptions::default();
    o.format.columns = ImuColumns::parse("t,gx,gy,gz,ax,ay,az,temp").unwrap();
    o.format.time_unit = TimeUnit::Ns;
    o
}

#[test]
fn rosbag2_folders_and_db3_read_exactly_like_text() {
    let d = dir("exact");
    let txt = d.join("imu.txt");
    text_twin(&txt);
    let want = open_recording(&txt, &text_options()).unwrap();
    let mut msgs = imu_messages("/imu0");
    // A temperature topic at the IMU's stamps, an image topic and a pose topic that the IMU reader skips.
    for (t, _, _, c) in samples() {
        msgs.push(("/imu0/temperature".into(), "sensor_msgs/msg/Temperature".into(), t, cdr::temperature(t, c)));
    }
    msgs.push(("/cam0/image_raw".into(), "sensor_msgs/msg/Image".into(), 0, cdr::image_mono8(0, 2, 1, &[0, 255])));
    msgs.sort_by_key(|m| m.2);
    for storage in ["sqlite3", "mcap"] {
        let bag = d.join(format!("bag_{storage}"));
        cdr::write_rosbag2(&bag, storage, &msgs);
        let got = open_recording(&bag, &RecordingOptions::default()).unwrap();
        assert_eq!(got.t0_ns, want.t0_ns, "{storage}");
        assert_eq!(got.t, want.t, "{storage}");
        assert_eq!(got.gyro, want.gyro, "{storage}");
        assert_eq!(got.accel, want.accel, "{storage}");
        assert_eq!(got.temperature, want.temperature, "{storage}");
        assert_eq!(got.topic.as_deref(), Some("/imu0"));
        assert!(got.warnings.iter().any(|w| w.contains("temperature from /imu0/temperature")), "{:?}", got.warnings);
    }
    // A bare .db3, and its folder without metadata.yaml (a recording cut short).
    let db3 = d.join("bag_sqlite3").join("bag_sqlite3_0.db3");
    let got = open_recording(&db3, &RecordingOptions::default()).unwrap();
    assert_eq!((&got.t, &got.gyro), (&want.t, &want.gyro));
    std::fs::remove_file(d.join("bag_sqlite3").join("metadata.yaml")).unwrap();
    let got = open_recording(&d.join("bag_sqlite3"), &RecordingOptions::default()).unwrap();
    assert_eq!((got.t, got.gyro), (want.t, want.gyro));
}

#[test]
fn bad_rosbag2_inputs_are_refused_by_name() {
    let d = dir("bad");
    let bag = d.join("bag");
    cdr::write_rosbag2(&bag, "sqlite3", &imu_messages("/imu0"));
    let o = RecordingOptions::default();
    // A topic that is not there.
    let mut wrong = o.clone();
    wrong.topics.imu = Some("/imu1".into());
    let e = open_recording(&bag, &wrong).unwrap_err().to_string();
    assert!(e.contains("no sensor_msgs/Imu topic '/imu1'") && e.contains("/imu0"), "{e}");
    // metadata.yaml naming a missing file.
    std::fs::rename(bag.join("bag_0.db3"), d.join("moved.db3")).unwrap();
    let e = open_recording(&bag, &o).unwrap_err().to_string();
    assert!(e.contains("metadata.yaml") && e.contains("bag_0.db3"), "{e}");
    // Not SQLite at all.
    std::fs::write(d.join("junk.db3"), b"not a database, just text").unwrap();
    let e = open_recording(&d.join("junk.db3"), &o).unwrap_err().to_string();
    assert!(e.contains("junk.db3") && e.contains("rosbag2 SQLite"), "{e}");
    // A truncated CDR message names its topic.
    let mut short = imu_messages("/imu0");
    short[5].3.truncate(40);
    cdr::write_db3(&d.join("short.db3"), &short);
    let e = open_recording(&d.join("short.db3"), &o).unwrap_err().to_string();
    assert!(e.contains("/imu0") && e.contains("too short"), "{e}");
    // Compressed bags are named as such.
    std::fs::write(d.join("x.db3.zstd"), b"").unwrap();
    let e = open_recording(&d.join("x.db3.zstd"), &o).unwrap_err().to_string();
    assert!(e.contains("zstd"), "{e}");
}

/// RealSense-style split topics: the gyro at 400 Hz, the accelerometer at 250 Hz, each in a
/// `sensor_msgs/Imu` with the other sensor's fields zero.
/// A malformed MCAP file on which the `mcap` crate panics ("capacity
/// overflow" while decompressing a chunk; the input the `mcap` fuzz target
/// found, kept in tests/fixtures/) is an error naming the file.
#[test]
fn a_malformed_mcap_chunk_is_an_error_not_a_crash() {
    let d = dir("mcap_chunk");
    let file = d.join("bad.mcap");
    std::fs::write(&file, include_bytes!("fixtures/mcap_capacity_overflow.mcap")).unwrap();
    let e = open_recording(&file, &RecordingOptions::default()).unwrap_err().to_string();
    assert!(e.contains("bad.mcap") && e.contains("MCAP reader failed"), "{e}");
}

#[test]
fn realsense_split_topics_are_merged_onto_the_gyro() {
    let d = dir("split");
    let mut msgs = Vec::new();
    for i in 0..2000i64 {
        let t = 1_000_000_000 + i * 2_500_000;
        msgs.push((
            "/camera/gyro/sample".into(),
            "sensor_msgs/msg/Imu".into(),
            t,
            cdr::imu(t, [0.1, 0.0, 0.0], [0.0; 3]),
        ));
    }
    for i in 0..1250i64 {
        let t = 1_000_000_000 + 1_000_000 + i * 4_000_000;
        let a = [0.0, 0.0, 9.8 + 1e-9 * (t - 1_000_000_000) as f64];
        msgs.push(("/camera/accel/sample".into(), "sensor_msgs/msg/Imu".into(), t, cdr::imu(t, [0.0; 3], a)));
    }
    msgs.sort_by_key(|m| m.2);
    let db3 = d.join("d435i.db3");
    cdr::write_db3(&db3, &msgs);
    let r = open_recording(&db3, &RecordingOptions::default()).unwrap();
    assert_eq!(r.topic.as_deref(), Some("/camera/accel/sample + /camera/gyro/sample"));
    assert!(r.warnings.iter().any(|w| w.contains("400.0 Hz") && w.contains("250.0 Hz")), "{:?}", r.warnings);
    assert!((r.mean_rate() - 400.0).abs() < 0.01);
    for (i, a) in r.accel.iter().enumerate() {
        let t = r.t_ns(i) - 1_000_000_000;
        assert!((a[2] - (9.8 + 1e-9 * t as f64)).abs() < 1e-9, "{i}");
        assert_eq!(r.gyro[i], [0.1, 0.0, 0.0]);
    }
    // Asked by name, the same; one of the two alone is refused.
    let mut o = RecordingOptions::default();
    o.topics.gyro = Some("/camera/gyro/sample".into());
    assert!(open_recording(&db3, &o).unwrap_err().to_string().contains("--gyro-topic"));
    o.topics.accel = Some("/camera/accel/sample".into());
    assert_eq!(open_recording(&db3, &o).unwrap().len(), r.len());
}

/// imu_tk-style text pair with different stamps: merged the same way.
#[test]
fn text_pair_with_different_stamps_is_merged() {
    let d = dir("pair");
    let mut acc = String::new();
    let mut gyr = String::new();
    for i in 0..1000 {
        gyr.push_str(&format!("{} 0.01 0.02 0.03\n", i as f64 * 0.0025));
    }
    for i in 0..600 {
        let t = 0.001 + i as f64 * 0.004;
        acc.push_str(&format!("{t} 0 {} 9.8\n", t));
    }
    std::fs::write(d.join("acc.txt"), acc).unwrap();
    std::fs::write(d.join("gyr.txt"), gyr).unwrap();
    let src = tumble::io::recording::RecordingSource::new(
        None,
        Some((d.join("acc.txt"), d.join("gyr.txt"))),
        true,
        RecordingOptions::default(),
        tumble::io::recording::Declared { time_unit: false, units: true },
    )
    .unwrap();
    let r = src.open().unwrap();
    assert!(r.warnings.iter().any(|w| w.contains("merged onto the gyro's stamps")), "{:?}", r.warnings);
    for i in 0..r.len() {
        let t = r.t_ns(i) as f64 * 1e-9;
        assert!((r.accel[i][1] - t).abs() < 1e-9, "{i}: {} vs {t}", r.accel[i][1]);
    }
}

/// A simulated hand tumble whose accelerometer is stamped at its own, lower rate (every
/// second sample, half a period late) and merged back onto the gyro calibrates like the
/// single stream: every parameter within its σ of the single-stream result.
#[test]
fn split_streams_calibrate_within_sigma_of_the_single_stream() {
    use tumble::calib::{calibrate, CalibOptions};
    use tumble::sim::{simulate, Scenario, SimConfig};
    let rec = simulate(Scenario::Tumble, &SimConfig::default(), 11).unwrap().imu.to_recording();
    let t_ns: Vec<i64> = (0..rec.len()).map(|i| rec.t_ns(i)).collect();
    let gyro = tumble::io::split::Stream { t_ns: t_ns.clone(), v: rec.gyro.clone() };
    // The accelerometer at half the rate, each sample the mean of two (as a decimating filter would) stamped between them.
    let accel = tumble::io::split::Stream {
        t_ns: t_ns.chunks_exact(2).map(|p| (p[0] + p[1]) / 2).collect(),
        v: rec.accel.chunks_exact(2).map(|p| [0, 1, 2].map(|k| 0.5 * (p[0][k] + p[1][k]))).collect(),
    };
    let m = tumble::io::split::merge_onto_gyro(gyro, accel).unwrap();
    let mut split = rec.clone();
    let keep = |i: usize| m.t_ns.binary_search(&t_ns[i]).is_ok();
    let idx: Vec<usize> = (0..rec.len()).filter(|&i| keep(i)).collect();
    split.t = idx.iter().map(|&i| rec.t[i]).collect();
    split.gyro = m.gyro;
    split.accel = m.accel;
    split.temperature = None;
    let opts = CalibOptions { gravity: 9.81, ..Default::default() };
    let one = calibrate(&rec, &opts).unwrap().calibration;
    let two = calibrate(&split, &opts).unwrap().calibration;
    let mut z = Vec::new();
    for (a, b) in [(&one.accel, &two.accel), (&one.gyro, &two.gyro)] {
        for i in 0..3 {
            z.push((a.k[i] - b.k[i]) / a.k_std[i]);
            z.push((a.b[i] - b.b[i]) / a.b_std[i].max(1e-12));
            for j in 0..3 {
                if a.t_std[(i, j)] > 0.0 {
                    z.push((a.t[(i, j)] - b.t[(i, j)]) / a.t_std[(i, j)]);
                }
            }
        }
    }
    let rms = (z.iter().map(|x| x * x).sum::<f64>() / z.len() as f64).sqrt();
    let worst = z.iter().fold(0.0f64, |a, b| a.max(b.abs()));
    eprintln!("split vs single stream: {} parameters, rms {rms:.2} σ, largest {worst:.2} σ", z.len());
    assert!(worst <= 1.0, "rms {rms:.2} σ, largest {worst:.2} σ");
}

/// `tumble allan` on a bag writes the bag's topic into imu.yaml's `rostopic`.
#[test]
fn allan_on_a_bag_names_its_topic_in_imu_yaml() {
    let d = dir("allan");
    let mut state = 12345u64;
    let mut noise = || {
        // Sum of 12 uniforms: near-Gaussian, unit variance.
        (0..12)
            .map(|_| {
                state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                (state >> 11) as f64 / (1u64 << 53) as f64
            })
            .sum::<f64>()
            - 6.0
    };
    let msgs: Vec<cdr::BagMessage> = (0..24_000i64)
        .map(|i| {
            let t = 2_000_000_000 + i * 5_000_000;
            let w = [1e-3 * noise(), 1e-3 * noise(), 1e-3 * noise()];
            let a = [2e-2 * noise(), 2e-2 * noise(), 9.81 + 2e-2 * noise()];
            ("/bmi088/imu".into(), "sensor_msgs/msg/Imu".into(), t, cdr::imu(t, w, a))
        })
        .collect();
    let bag = d.join("still");
    cdr::write_rosbag2(&bag, "sqlite3", &msgs);
    let rec = open_recording(&bag, &RecordingOptions::default()).unwrap();
    let report = tumble::allan::run_allan(&rec, &Default::default()).unwrap();
    let yaml = report.kalibr_yaml().unwrap();
    assert!(yaml.contains("rostopic: /bmi088/imu\n"), "{yaml}");
}

/// `tumble convert`: a rosbag2 folder with IMU, a camera with camera_info and ground truth
/// becomes an ASL folder that reads back as the same data; a failed conversion writes nothing.
#[test]
fn convert_writes_an_asl_folder_that_reads_back() {
    let d = dir("convert");
    let mut msgs = imu_messages("/imu0");
    let k = [458.6, 0.0, 367.2, 0.0, 457.3, 248.4, 0.0, 0.0, 1.0];
    for f in 0..20i64 {
        let t = 1_700_000_000_123_456_789 + f * 50_000_000;
        let px: Vec<u8> = (0..12).map(|i| (i * 20 + f) as u8).collect();
        msgs.push(("/cam0/image_raw".into(), "sensor_msgs/msg/Image".into(), t, cdr::image_mono8(t, 4, 3, &px)));
        let info = cdr::camera_info(t, 4, 3, "plumb_bob", &[-0.28, 0.07, 1e-4, 2e-5, 0.0], k);
        msgs.push(("/cam0/camera_info".into(), "sensor_msgs/msg/CameraInfo".into(), t, info));
        let q = [(0.1 * f as f64).cos(), 0.0, 0.0, (0.1 * f as f64).sin()];
        let pose = cdr::pose_stamped(t, [f as f64, 2.0, 3.0], q);
        msgs.push(("/leica/pose".into(), "geometry_msgs/msg/PoseStamped".into(), t, pose));
    }
    msgs.sort_by_key(|m| m.2);
    let bag = d.join("bag");
    cdr::write_rosbag2(&bag, "sqlite3", &msgs);
    let out = d.join("asl");
    let opts = tumble::io::convert::ConvertOptions::default();
    let report = tumble::io::convert::convert_to_asl(&bag, &out, &opts, &mut |_, _| {}).unwrap();
    assert_eq!(report.cameras, vec![("cam0".to_string(), "/cam0/image_raw".to_string(), 20, true)]);
    assert_eq!(report.groundtruth, Some(("/leica/pose".to_string(), 20)));
    let asl = tumble::io::asl::read_asl(&out, &Default::default()).unwrap();
    let direct = open_recording(&bag, &RecordingOptions::default()).unwrap();
    assert_eq!(
        (asl.imu.t0_ns, &asl.imu.t, &asl.imu.gyro, &asl.imu.accel),
        (direct.t0_ns, &direct.t, &direct.gyro, &direct.accel)
    );
    let cam = &asl.cameras[0];
    assert_eq!((cam.frames.len(), cam.resolution, cam.model.as_ref().map(|m| m.fx)), (20, Some([4, 3]), Some(458.6)));
    let png = std::fs::read(&cam.frames[3].1).unwrap();
    let mut dec = png::Decoder::new(std::io::Cursor::new(png)).read_info().unwrap();
    let mut buf = vec![0; dec.output_buffer_size().unwrap()];
    dec.next_frame(&mut buf).unwrap();
    assert_eq!(buf, (0..12).map(|i| (i * 20 + 3) as u8).collect::<Vec<_>>());
    let gt = asl.groundtruth.unwrap();
    assert_eq!((gt.len(), gt.p[5], gt.q[5][3]), (20, [5.0, 2.0, 3.0], (0.5f64).sin()));
    // Into a non-empty folder: refused. A bag whose image is cut short: nothing left behind.
    let e = tumble::io::convert::convert_to_asl(&bag, &out, &opts, &mut |_, _| {}).unwrap_err().to_string();
    assert!(e.contains("not empty"), "{e}");
    let cut = msgs.iter().position(|m| m.0 == "/cam0/image_raw").unwrap() + 7;
    let mut bad = msgs.clone();
    let i = bad.iter().skip(cut).position(|m| m.0 == "/cam0/image_raw").unwrap() + cut;
    bad[i].3.truncate(60);
    cdr::write_rosbag2(&d.join("badbag"), "sqlite3", &bad);
    let out2 = d.join("asl2");
    let e =
        tumble::io::convert::convert_to_asl(&d.join("badbag"), &out2, &opts, &mut |_, _| {}).unwrap_err().to_string();
    assert!(e.contains("/cam0/image_raw"), "{e}");
    assert!(!out2.exists() || std::fs::read_dir(&out2).unwrap().next().is_none(), "a failed conversion left files");
}

/// A driver that leaves header.stamp at zero: the recorder's receive times stamp the samples, with a warning.
#[test]
fn unstamped_imu_messages_take_the_receive_time() {
    let d = dir("unstamped");
    let msgs: Vec<cdr::BagMessage> = (0..500i64)
        .map(|i| {
            let t = 5_000_000_000 + i * 2_500_000;
            ("/imu".into(), "sensor_msgs/msg/Imu".into(), t, cdr::imu(0, [0.0, 0.0, 0.01], [0.0, 0.0, 9.81]))
        })
        .collect();
    cdr::write_db3(&d.join("u.db3"), &msgs);
    let r = open_recording(&d.join("u.db3"), &RecordingOptions::default()).unwrap();
    assert_eq!((r.t0_ns, r.len()), (5_000_000_000, 500));
    assert!((r.mean_rate() - 400.0).abs() < 1e-9);
    assert!(r.warnings.iter().any(|w| w.contains("500 IMU messages have header.stamp = 0")), "{:?}", r.warnings);
}

/// The fuzz targets' seed corpora (`fuzz/seeds/`, docs/development.md): small
/// valid files for each reader, so the fuzzer starts inside the formats.
/// Written only when asked: `cargo test --test ros2 -- --ignored write_fuzz_seeds`.
#[test]
#[ignore = "writes fuzz/seeds/ (run by hand before fuzzing)"]
fn write_fuzz_seeds() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/seeds");
    let msgs = root.join("cdr");
    std::fs::create_dir_all(&msgs).unwrap();
    let t = 1_700_000_000_000_000_000;
    let mut few: Vec<cdr::BagMessage> = imu_messages("/imu0").into_iter().take(8).collect();
    few.push(("/temp".into(), "sensor_msgs/msg/Temperature".into(), t, cdr::temperature(t, 25.0)));
    few.push((
        "/gt".into(),
        "geometry_msgs/msg/PoseStamped".into(),
        t,
        cdr::pose_stamped(t, [1.0, 2.0, 3.0], [1.0, 0.0, 0.0, 0.0]),
    ));
    few.push(("/cam0".into(), "sensor_msgs/msg/Image".into(), t, cdr::image_mono8(t, 4, 2, &[0, 1, 2, 3, 4, 5, 6, 7])));
    let tmp = dir("seeds");
    for ext in ["db3", "mcap"] {
        let file = tmp.join(format!("seed.{ext}"));
        if ext == "db3" {
            cdr::write_db3(&file, &few);
        } else {
            cdr::write_mcap(&file, &few);
        }
        std::fs::create_dir_all(root.join(ext)).unwrap();
        std::fs::copy(&file, root.join(ext).join("seed")).unwrap();
    }
    for (i, (_, _, _, data)) in few.iter().enumerate().skip(6) {
        std::fs::write(msgs.join(format!("seed_{i}")), data).unwrap();
    }
}

//! ROS recording → ASL/EuRoC folder (`tumble convert`): the layout `tumble
//! vio`, `track` and `calibrate-rig` read, and every EuRoC-reading estimator.
//!
//! - `mav0/imu0/data.csv` (+ `sensor.yaml` with the rate): the IMU as
//!   [`super::ros::read_ros_imu`] reads it (split streams merged, temperature joined);
//! - `mav0/camN/data.csv` + `data/<stamp>.png`: each image topic
//!   (`sensor_msgs/Image` in `mono8`/`8UC1`, `mono16`/`16UC1`, `rgb8`, `bgr8`,
//!   `rgba8`, `bgra8` → PNG; `sensor_msgs/CompressedImage` written as its own
//!   bytes, `.png` or `.jpg`), stamped by `header.stamp`; `sensor.yaml` from
//!   the topic's `camera_info` sibling when there is one (pinhole with
//!   radial-tangential or equidistant distortion);
//! - `mav0/state_groundtruth_estimate0/data.csv`: a pose topic
//!   (`PoseStamped`, `PoseWithCovarianceStamped`, `TransformStamped`,
//!   `Odometry`) as position and orientation.
//!
//! Everything is written into a staging folder and moved into place only
//! when the whole conversion succeeded.

use super::imu_write::write_asl_imu;
use super::ros::msgs;
use super::ros::{read_ros_imu, ImuTopics, RawMessage, Storage, TopicInfo};
use super::trajectory::{write_asl_groundtruth, Trajectory};
use super::validate::ValidateOptions;
use crate::error::{InputError, OutputError};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// What to convert.
#[derive(Debug, Clone, Default)]
pub struct ConvertOptions {
    /// The IMU topics (see [`ImuTopics`]).
    pub imu: ImuTopics,
    /// Image topics in camera order (`cam0`, `cam1`, …); default: every
    /// `Image`/`CompressedImage` topic, sorted by name.
    pub images: Option<Vec<String>>,
    /// The ground-truth pose topic; default: the only pose topic, if one.
    pub groundtruth: Option<String>,
    /// Checks of the IMU stream.
    pub validate: ValidateOptions,
}

/// What a conversion wrote.
#[derive(Debug, Clone, Default)]
pub struct ConvertReport {
    /// Every file written (images counted, not listed: see `cameras`).
    pub files: Vec<PathBuf>,
    /// IMU samples written, and from which topic(s).
    pub imu: (usize, String),
    /// Per camera: folder name, topic, frames written, whether a sensor.yaml was written.
    pub cameras: Vec<(String, String, usize, bool)>,
    /// Ground truth: topic and poses written.
    pub groundtruth: Option<(String, usize)>,
    /// What was decided on the way (IMU merge notes, skipped topics).
    pub notes: Vec<String>,
}

const IMAGE_TYPES: [&str; 2] = ["sensor_msgs/Image", "sensor_msgs/CompressedImage"];

fn pick_images(path: &Path, all: &[TopicInfo], want: &Option<Vec<String>>) -> Result<Vec<String>, InputError> {
    let images: Vec<&TopicInfo> = all.iter().filter(|t| IMAGE_TYPES.contains(&t.msg_type.as_str())).collect();
    match want {
        None => Ok(images.iter().map(|t| t.name.clone()).collect()),
        Some(w) => w
            .iter()
            .map(|name| {
                if images.iter().any(|t| &t.name == name) {
                    Ok(name.clone())
                } else {
                    Err(InputError::file(path, format!("no image topic '{name}'")).with_hint(format!(
                        "image topics here: {}",
                        images.iter().map(|t| t.name.as_str()).collect::<Vec<_>>().join(", ")
                    )))
                }
            })
            .collect(),
    }
}

/// The ground-truth topic, and a note when several pose topics leave it unchosen.
fn pick_groundtruth(
    path: &Path,
    all: &[TopicInfo],
    want: &Option<String>,
) -> Result<(Option<String>, Option<String>), InputError> {
    let poses: Vec<&TopicInfo> = all.iter().filter(|t| msgs::POSE_TYPES.contains(&t.msg_type.as_str())).collect();
    match want {
        Some(name) if poses.iter().any(|t| &t.name == name) => Ok((Some(name.clone()), None)),
        Some(name) => Err(InputError::file(path, format!("no pose topic '{name}'")).with_hint(format!(
            "pose topics here: {}",
            poses.iter().map(|t| format!("{} ({})", t.name, t.msg_type)).collect::<Vec<_>>().join(", ")
        ))),
        None if poses.len() == 1 => Ok((Some(poses[0].name.clone()), None)),
        None if poses.len() > 1 => Ok((
            None,
            Some(format!(
                "several pose topics ({}): no ground truth written; choose one with --groundtruth-topic",
                poses.iter().map(|t| t.name.as_str()).collect::<Vec<_>>().join(", ")
            )),
        )),
        None => Ok((None, None)),
    }
}

/// The `camera_info` topic beside an image topic (`/cam0/image_raw` → `/cam0/camera_info`).
fn info_topic(image: &str, all: &[TopicInfo]) -> Option<String> {
    let parent = image.rsplit_once('/').map(|(p, _)| p).unwrap_or("");
    all.iter()
        .find(|t| t.msg_type == "sensor_msgs/CameraInfo" && t.name.rsplit_once('/').map(|(p, _)| p) == Some(parent))
        .map(|t| t.name.clone())
}

/// Encode one raw image as PNG bytes.
fn png_of(img: &msgs::Image) -> Result<Vec<u8>, String> {
    let (color, depth, channels, swap) = match img.encoding.as_str() {
        "mono8" | "8UC1" => (png::ColorType::Grayscale, png::BitDepth::Eight, 1, false),
        "mono16" | "16UC1" => (png::ColorType::Grayscale, png::BitDepth::Sixteen, 2, false),
        "rgb8" | "8UC3" => (png::ColorType::Rgb, png::BitDepth::Eight, 3, false),
        "bgr8" => (png::ColorType::Rgb, png::BitDepth::Eight, 3, true),
        "rgba8" | "8UC4" => (png::ColorType::Rgba, png::BitDepth::Eight, 4, false),
        "bgra8" => (png::ColorType::Rgba, png::BitDepth::Eight, 4, true),
        other => {
            return Err(format!("image encoding '{other}' is not converted (mono8/16, rgb8, bgr8, rgba8, bgra8 are)"))
        }
    };
    let row = img.width as usize * channels;
    if (img.step as usize) < row || img.data.len() < img.step as usize * img.height as usize {
        return Err(format!(
            "{}×{} {} image with step {} holds {} bytes: too few",
            img.width,
            img.height,
            img.encoding,
            img.step,
            img.data.len()
        ));
    }
    let mut px = Vec::with_capacity(row * img.height as usize);
    for r in 0..img.height as usize {
        let s = &img.data[r * img.step as usize..r * img.step as usize + row];
        if depth == png::BitDepth::Sixteen && !img.big_endian {
            // PNG stores 16-bit samples big-endian.
            s.chunks_exact(2).for_each(|b| px.extend([b[1], b[0]]));
        } else if swap {
            s.chunks_exact(channels).for_each(|p| {
                px.extend([p[2], p[1], p[0]]);
                if channels == 4 {
                    px.push(p[3]);
                }
            });
        } else {
            px.extend_from_slice(s);
        }
    }
    encode_png(&px, img.width as usize, img.height as usize, color, depth)
}

/// Packed pixels (rows of `width` samples, 16-bit ones big-endian) as PNG
/// bytes, compressed fast (recordings hold thousands of frames).
pub(crate) fn encode_png(
    px: &[u8],
    width: usize,
    height: usize,
    color: png::ColorType,
    depth: png::BitDepth,
) -> Result<Vec<u8>, String> {
    let mut out = Vec::new();
    {
        let mut e = png::Encoder::new(&mut out, width as u32, height as u32);
        e.set_color(color);
        e.set_depth(depth);
        e.set_compression(png::Compression::Fast);
        let mut w = e.write_header().map_err(|e| e.to_string())?;
        w.write_image_data(px).map_err(|e| e.to_string())?;
    }
    Ok(out)
}

/// A camera `sensor.yaml` from a `CameraInfo`, or why none can be written.
fn camera_yaml(info: &msgs::CameraInfo, rate_hz: f64) -> Result<String, String> {
    let k = info.k;
    if !(k[0] > 0.0 && k[4] > 0.0) {
        return Err("its camera matrix K is empty (uncalibrated camera)".into());
    }
    let (model, d) = match (info.distortion_model.as_str(), info.d.as_slice()) {
        ("plumb_bob" | "radial-tangential", [k1, k2, p1, p2]) | ("plumb_bob", [k1, k2, p1, p2, 0.0]) => {
            ("radial-tangential", vec![*k1, *k2, *p1, *p2])
        }
        ("equidistant" | "fisheye", [k1, k2, k3, k4]) => ("equidistant", vec![*k1, *k2, *k3, *k4]),
        (_, d) if d.iter().all(|v| *v == 0.0) => ("none", Vec::new()),
        (m, d) => return Err(format!("distortion '{m}' with {} coefficients has no ASL equivalent", d.len())),
    };
    let list = |v: &[f64]| v.iter().map(|x| format!("{x:e}")).collect::<Vec<_>>().join(", ");
    Ok(format!(
        "# from the bag's camera_info (T_BS unknown: calibrate the rig to get it)\nsensor_type: camera\nrate_hz: {rate_hz:.3}\nresolution: [{}, {}]\ncamera_model: pinhole\nintrinsics: [{}]\ndistortion_model: {model}\ndistortion_coefficients: [{}]\n",
        info.width,
        info.height,
        list(&[k[0], k[4], k[2], k[5]]),
        list(&d)
    ))
}

/// Convert the ROS recording `input` into an ASL folder `out` (see the module
/// doc). `progress(done, total)` is called as messages are written (total from
/// the file's index, 0 when unknown).
///
/// The steps: the topics chosen (IMU, images, their camera_info, a ground
/// truth) → the IMU written → the other messages streamed (frames written as
/// they come) → each camera's index and `sensor.yaml` → the ground truth;
/// all into a staging folder moved into place when everything succeeded.
pub fn convert_to_asl(
    input: &Path,
    out: &Path,
    opts: &ConvertOptions,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<ConvertReport, OutputError> {
    let storage = Storage::of(input)?.ok_or_else(|| {
        InputError::file(input, "is not a ROS recording (a rosbag2 folder with metadata.yaml, .db3, .mcap or .bag)")
    })?;
    if out.exists() && std::fs::read_dir(out).map(|mut d| d.next().is_some()).unwrap_or(true) {
        return Err(OutputError::Failed(format!("{}: exists and is not empty; give a new folder", out.display())));
    }
    let all = storage.topics()?;
    let imu = read_ros_imu(&storage, &opts.imu, &opts.validate)?;
    let images = pick_images(input, &all, &opts.images)?;
    let (gt_topic, gt_note) = pick_groundtruth(input, &all, &opts.groundtruth)?;
    let infos: Vec<Option<String>> = images.iter().map(|t| info_topic(t, &all)).collect();
    let topics = Topics { images, infos, groundtruth: gt_topic };
    let mut report = ConvertReport { imu: (imu.len(), imu.topic.clone().unwrap_or_default()), ..Default::default() };
    report.notes.extend(imu.warnings.iter().cloned());
    report.notes.extend(gt_note);
    let total: usize = all
        .iter()
        .filter(|t| topics.images.contains(&t.name) || Some(&t.name) == topics.groundtruth.as_ref())
        .filter_map(|t| t.count)
        .sum::<u64>() as usize;
    let files = super::staging::write_staged(out, |stage| -> Result<Vec<PathBuf>, OutputError> {
        let mav0 = stage.join("mav0");
        let mut files = write_imu(&mav0, input, &imu)?;
        let streamed = stream(&storage, input, &mav0, &topics, total, progress)?;
        for (c, frames) in streamed.frames.into_iter().enumerate() {
            files.extend(write_camera(&mav0, c, frames, &topics, streamed.info[c].as_ref(), &mut report)?);
        }
        if let Some(topic) = &topics.groundtruth {
            let d = mav0.join("state_groundtruth_estimate0");
            let sorted = sorted_unique(&streamed.groundtruth);
            std::fs::create_dir_all(&d).map_err(|e| format!("{}: {e}", d.display()))?;
            write_asl_groundtruth(&d.join("data.csv"), &sorted)?;
            files.push(d.join("data.csv"));
            report.groundtruth = Some((topic.clone(), sorted.len()));
        }
        Ok(files)
    })?;
    report.files = files.into_iter().filter(|f| !f.components().any(|c| c.as_os_str() == "data")).collect();
    Ok(report)
}

/// The topics a conversion reads besides the IMU's.
struct Topics {
    /// Image topics, camera by camera.
    images: Vec<String>,
    /// Each camera's camera_info topic, when there is one.
    infos: Vec<Option<String>>,
    groundtruth: Option<String>,
}

/// `mav0/imu0/data.csv` and a `sensor.yaml` with its rate.
fn write_imu(mav0: &Path, input: &Path, imu: &super::ImuRecording) -> Result<Vec<PathBuf>, OutputError> {
    let imu_dir = mav0.join("imu0");
    std::fs::create_dir_all(&imu_dir).map_err(|e| format!("{}: {e}", imu_dir.display()))?;
    write_asl_imu(&imu_dir.join("data.csv"), imu)?;
    let yaml = format!(
        "# from {} ({})\nsensor_type: imu\nrate_hz: {:.3}\n",
        input.display(),
        imu.topic.as_deref().unwrap_or(""),
        imu.mean_rate()
    );
    std::fs::write(imu_dir.join("sensor.yaml"), yaml).map_err(|e| format!("{}: {e}", imu_dir.display()))?;
    Ok(vec![imu_dir.join("data.csv"), imu_dir.join("sensor.yaml")])
}

/// What streaming the messages gave: per camera its frames (stamp, file
/// name), written as they came; its first camera_info; the ground truth.
struct Streamed {
    frames: Vec<Vec<(i64, String)>>,
    info: Vec<Option<msgs::CameraInfo>>,
    groundtruth: Trajectory,
}

/// Stream the images, camera_info and ground-truth messages, writing each
/// image into `mav0/camN/data/` as it comes.
fn stream(
    storage: &Storage,
    input: &Path,
    mav0: &Path,
    topics: &Topics,
    total: usize,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Streamed, OutputError> {
    let cam_of: BTreeMap<&str, usize> = topics.images.iter().enumerate().map(|(i, t)| (t.as_str(), i)).collect();
    let info_of: BTreeMap<&str, usize> =
        topics.infos.iter().enumerate().filter_map(|(i, t)| t.as_deref().map(|t| (t, i))).collect();
    let n = topics.images.len();
    let mut out = Streamed { frames: vec![Vec::new(); n], info: vec![None; n], groundtruth: Trajectory::default() };
    for i in 0..n {
        let d = mav0.join(format!("cam{i}")).join("data");
        std::fs::create_dir_all(&d).map_err(|e| format!("{}: {e}", d.display()))?;
    }
    let mut names: Vec<&str> = topics.images.iter().map(String::as_str).collect();
    names.extend(topics.infos.iter().flatten().map(String::as_str));
    names.extend(topics.groundtruth.as_deref());
    let mut done = 0usize;
    let mut write_error: Option<OutputError> = None;
    storage
        .for_each(&names, &mut |m: &RawMessage| {
            let bad = |what: &str| InputError::file(input, format!("a message on {} is not a {what}", m.topic));
            if let Some(&c) = cam_of.get(m.topic) {
                let (t, name, bytes) = image_file(input, m)?;
                let p = mav0.join(format!("cam{c}")).join("data").join(&name);
                if let Err(e) = std::fs::write(&p, bytes) {
                    write_error = Some(OutputError::Failed(format!("{}: {e}", p.display())));
                    return Err(InputError::file(&p, "cannot be written"));
                }
                out.frames[c].push((t, name));
            } else if let Some(&c) = info_of.get(m.topic) {
                if out.info[c].is_none() {
                    out.info[c] =
                        Some(msgs::camera_info(m.encoding, m.data).ok_or_else(|| bad("sensor_msgs/CameraInfo"))?);
                }
            } else if Some(m.topic) == topics.groundtruth.as_deref() {
                let (t, p, q) = msgs::pose(m.msg_type, m.encoding, m.data).ok_or_else(|| bad(m.msg_type))?;
                out.groundtruth.t_ns.push(t);
                out.groundtruth.p.push(p);
                out.groundtruth.q.push(q);
            }
            done += 1;
            progress(done, total);
            Ok(())
        })
        .map_err(|e| write_error.take().unwrap_or(OutputError::Input(e)))?;
    Ok(out)
}

/// An image message as a file: its stamp, file name and bytes (a raw image
/// encoded as PNG, a compressed one as it came).
fn image_file(input: &Path, m: &RawMessage) -> Result<(i64, String, Vec<u8>), InputError> {
    let bad = |what: &str| InputError::file(input, format!("a message on {} is not a {what}", m.topic));
    Ok(match m.msg_type {
        "sensor_msgs/Image" => {
            let img = msgs::image(m.encoding, m.data).ok_or_else(|| bad("sensor_msgs/Image (too short)"))?;
            let png = png_of(&img).map_err(|e| InputError::file(input, format!("{}: {e}", m.topic)))?;
            (img.t_ns, format!("{}.png", img.t_ns), png)
        }
        _ => {
            let (t, format, data) = msgs::compressed_image(m.encoding, m.data)
                .ok_or_else(|| bad("sensor_msgs/CompressedImage (too short)"))?;
            let ext = if format.contains("png") { "png" } else { "jpg" };
            (t, format!("{t}.{ext}"), data.to_vec())
        }
    })
}

/// Camera `c`'s index (`data.csv`, one frame per stamp) and, from its
/// camera_info, its `sensor.yaml`; noted in `report`. Returns the files
/// (its frames included, so that staging moves them).
fn write_camera(
    mav0: &Path,
    c: usize,
    mut f: Vec<(i64, String)>,
    topics: &Topics,
    info: Option<&msgs::CameraInfo>,
    report: &mut ConvertReport,
) -> Result<Vec<PathBuf>, OutputError> {
    let mut files = Vec::new();
    f.sort_by_key(|x| x.0);
    let before = f.len();
    f.dedup_by_key(|x| x.0);
    if f.len() < before {
        report.notes.push(format!(
            "{}: {} frames repeat a stamp: one image kept per stamp",
            topics.images[c],
            before - f.len()
        ));
    }
    let dir = mav0.join(format!("cam{c}"));
    let mut csv = String::from("#timestamp [ns],filename\n");
    for (t, name) in f.iter() {
        csv.push_str(&format!("{t},{name}\n"));
    }
    std::fs::write(dir.join("data.csv"), csv).map_err(|e| format!("{}: {e}", dir.display()))?;
    files.push(dir.join("data.csv"));
    files.extend(f.iter().map(|(_, name)| dir.join("data").join(name)));
    let rate = if f.len() > 1 { (f.len() - 1) as f64 / ((f[f.len() - 1].0 - f[0].0) as f64 * 1e-9) } else { 0.0 };
    let wrote_yaml = match (info, &topics.infos[c]) {
        (Some(i), Some(topic)) => match camera_yaml(i, rate) {
            Ok(y) => {
                std::fs::write(dir.join("sensor.yaml"), y).map_err(|e| format!("{}: {e}", dir.display()))?;
                files.push(dir.join("sensor.yaml"));
                true
            }
            Err(why) => {
                report.notes.push(format!("{topic}: no sensor.yaml: {why}"));
                false
            }
        },
        _ => {
            report
                .notes
                .push(format!("{}: no camera_info beside it: no sensor.yaml (intrinsics unknown)", topics.images[c]));
            false
        }
    };
    report.cameras.push((format!("cam{c}"), topics.images[c].clone(), f.len(), wrote_yaml));
    Ok(files)
}

/// The poses in time order, one per stamp.
fn sorted_unique(gt: &Trajectory) -> Trajectory {
    let mut idx: Vec<usize> = (0..gt.len()).collect();
    idx.sort_by_key(|&i| gt.t_ns[i]);
    idx.dedup_by_key(|i| gt.t_ns[*i]);
    Trajectory {
        t_ns: idx.iter().map(|&i| gt.t_ns[i]).collect(),
        p: idx.iter().map(|&i| gt.p[i]).collect(),
        q: idx.iter().map(|&i| gt.q[i]).collect(),
        ..Default::default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn png_rows_drop_padding_and_bgr_is_swapped() {
        let data = [1u8, 2, 3, 9, 4, 5, 6, 9];
        let img = msgs::Image {
            t_ns: 0,
            height: 2,
            width: 1,
            encoding: "bgr8".into(),
            big_endian: false,
            step: 4,
            data: &data,
        };
        let png = png_of(&img).unwrap();
        let mut dec = png::Decoder::new(std::io::Cursor::new(png)).read_info().unwrap();
        let mut buf = vec![0; dec.output_buffer_size().unwrap()];
        dec.next_frame(&mut buf).unwrap();
        assert_eq!(buf, vec![3, 2, 1, 6, 5, 4]);
        let bayer = msgs::Image { encoding: "bayer_rggb8".into(), ..img };
        assert!(png_of(&bayer).unwrap_err().contains("bayer_rggb8"));
    }

    #[test]
    fn camera_info_to_sensor_yaml() {
        let info = msgs::CameraInfo {
            width: 752,
            height: 480,
            distortion_model: "plumb_bob".into(),
            d: vec![-0.28, 0.07, 1e-4, 2e-5, 0.0],
            k: [458.6, 0.0, 367.2, 0.0, 457.3, 248.4, 0.0, 0.0, 1.0],
        };
        let y = camera_yaml(&info, 20.0).unwrap();
        let (m, t_bs, res, rate) = crate::io::asl::parse_camera_sensor(Path::new("x.yaml"), &y).unwrap();
        assert_eq!((m.fx, m.cy, t_bs, res, rate), (458.6, 248.4, None, Some([752, 480]), Some(20.0)));
        let k3 = msgs::CameraInfo { d: vec![-0.28, 0.07, 1e-4, 2e-5, 0.01], ..info };
        assert!(camera_yaml(&k3, 20.0).unwrap_err().contains("5 coefficients"));
    }
}

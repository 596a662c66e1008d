//! The KLT tracker on OpenCV (feature `opencv`).

use super::anchor::Anchor;
use super::corners::{CornerSearch, GrayImage, ShiTomasi};
use super::FrontendError;
use super::{FrontendOptions, FrontendStats, Observation, StereoStats};
use opencv::core::{self, Mat, Point, Point2f, Scalar, Size, TermCriteria, Vector};
use opencv::prelude::*;
use opencv::{calib3d, imgcodecs, imgproc, video};
use std::path::Path;
use std::time::Instant;
use tumble_factors::camera::CameraModel;

fn cv(e: opencv::Error) -> String {
    format!("OpenCV: {e}")
}

/// A feature tracker over one camera's images, VINS-Mono style: tracked
/// features are kept by KLT + forward–backward + RANSAC, the longest tracks
/// win where two are closer than the minimum distance, and new Shi–Tomasi
/// corners fill the image up to `max_features`.
///
/// ```no_run
/// use tumble::vio::frontend::{FrontendOptions, KltTracker};
/// use tumble::factors::camera::{CameraModel, Distortion};
/// let cam = CameraModel { fx: 458.654, fy: 457.296, cx: 367.215, cy: 248.375, distortion: Distortion::None };
/// let mut tracker = KltTracker::new(cam, FrontendOptions::default());
/// let img = opencv::imgcodecs::imread("frame.png", opencv::imgcodecs::IMREAD_GRAYSCALE).unwrap();
/// let features = tracker.track(&img).unwrap(); // (track id, [u, v]) per feature
/// println!("{} features; {}", features.len(), tracker.stats().line());
/// ```
pub struct KltTracker {
    opts: FrontendOptions,
    camera: CameraModel,
    clahe: Option<core::Ptr<imgproc::CLAHE>>,
    corners: ShiTomasi,
    prev: Option<Vector<Mat>>,
    pts: Vec<Point2f>,
    ids: Vec<u64>,
    ages: Vec<u32>,
    /// Each feature's anchor ([`FrontendOptions::anchored`]; None: none yet).
    anchors: Vec<Option<Anchor>>,
    next_id: u64,
    // Statistics.
    frames: usize,
    features: usize,
    finished_len: u64,
    finished: u64,
    klt_tracked: u64,
    fb_kept: u64,
    ransac_in: u64,
    ransac_kept: u64,
    anchor_tried: u64,
    anchor_held: u64,
    seconds: f64,
}

impl KltTracker {
    /// A tracker for images of `camera` (intrinsics and distortion undistort the points for RANSAC).
    pub fn new(camera: CameraModel, opts: FrontendOptions) -> KltTracker {
        KltTracker {
            clahe: None,
            corners: ShiTomasi::default(),
            opts,
            camera,
            prev: None,
            pts: Vec::new(),
            ids: Vec::new(),
            ages: Vec::new(),
            anchors: Vec::new(),
            next_id: 0,
            frames: 0,
            features: 0,
            finished_len: 0,
            finished: 0,
            klt_tracked: 0,
            fb_kept: 0,
            ransac_in: 0,
            ransac_kept: 0,
            anchor_tried: 0,
            anchor_held: 0,
            seconds: 0.0,
        }
    }

    /// Statistics so far.
    pub fn stats(&self) -> FrontendStats {
        let ratio = |a: u64, b: u64| if b > 0 { a as f64 / b as f64 } else { f64::NAN };
        let alive: u64 = self.ages.iter().map(|&a| a as u64).sum();
        FrontendStats {
            frames: self.frames,
            features_per_frame: ratio(self.features as u64, self.frames as u64),
            mean_track_length: ratio(self.finished_len + alive, self.finished + self.ages.len() as u64),
            tracks: self.next_id as usize,
            fb_ratio: ratio(self.fb_kept, self.klt_tracked),
            inlier_ratio: ratio(self.ransac_kept, self.ransac_in),
            anchored_ratio: ratio(self.anchor_held, self.anchor_tried),
            ms_per_frame: 1e3 * self.seconds / self.frames.max(1) as f64,
            warnings: Vec::new(),
            stereo: None,
        }
    }

    /// Keep the features where `keep` is true; the others' tracks end.
    fn retain(&mut self, keep: &[bool]) {
        let mut k = 0;
        for (i, &ok) in keep.iter().enumerate() {
            if ok {
                self.pts[k] = self.pts[i];
                self.ids[k] = self.ids[i];
                self.ages[k] = self.ages[i];
                self.anchors.swap(k, i);
                k += 1;
            } else {
                self.finished += 1;
                self.finished_len += self.ages[i] as u64;
            }
        }
        self.pts.truncate(k);
        self.ids.truncate(k);
        self.ages.truncate(k);
        self.anchors.truncate(k);
    }

    /// The image pyramid with derivatives, built once per image and used by both KLT passes.
    fn pyramid(&self, img: &Mat) -> Result<Vector<Mat>, FrontendError> {
        let mut pyr = Vector::<Mat>::new();
        let win = Size::new(self.opts.window, self.opts.window);
        video::build_optical_flow_pyramid(
            img,
            &mut pyr,
            win,
            self.opts.pyramid_levels,
            true,
            core::BORDER_REFLECT_101,
            core::BORDER_CONSTANT,
            true,
        )
        .map_err(cv)?;
        Ok(pyr)
    }

    /// Where each feature should be after the camera turned by `rotation`
    /// (`R_{c_now ← c_prev}`): its bearing turned and projected through the
    /// lens; its old place when that leaves the image or the lens' domain.
    fn predict(&self, rotation: &nalgebra::Rotation3<f64>, size: Size) -> Vector<Point2f> {
        let (w, h) = (size.width as f64, size.height as f64);
        let c = &self.camera;
        let moved = |p: &Point2f| -> Option<Point2f> {
            let [x, y] = c.unproject([p.x as f64, p.y as f64])?;
            let b = rotation * nalgebra::Vector3::new(x, y, 1.0);
            let [u, v] = c.project(&[b.x, b.y, b.z])?;
            (u >= 0.0 && v >= 0.0 && u < w && v < h).then(|| Point2f::new(u as f32, v as f32))
        };
        self.pts.iter().map(|p| moved(p).unwrap_or(*p)).collect()
    }

    /// Pyramidal KLT from `prev` to `img` (pyramids) with the forward–backward
    /// check, started where `rotation` moves each feature when given; returns what survived.
    fn klt(
        &mut self,
        prev: &Vector<Mat>,
        img: &Vector<Mat>,
        size: Size,
        rotation: Option<&nalgebra::Rotation3<f64>>,
    ) -> Result<Vec<bool>, FrontendError> {
        let o = &self.opts;
        let win = Size::new(o.window, o.window);
        let prev_pts: Vector<Point2f> = self.pts.iter().copied().collect();
        let mut next = rotation.map_or_else(Vector::<Point2f>::new, |r| self.predict(r, size));
        let (status, back, status_b) =
            klt_both_ways(prev, img, &prev_pts, &mut next, win, [o.pyramid_levels, 1], rotation.is_some())?;
        let (w, h) = (size.width as f32, size.height as f32);
        let mut keep = vec![false; self.pts.len()];
        for (i, k) in keep.iter_mut().enumerate() {
            let (p, q, b) = (next.get(i).map_err(cv)?, prev_pts.get(i).map_err(cv)?, back.get(i).map_err(cv)?);
            let inside = p.x >= 1.0 && p.y >= 1.0 && p.x < w - 1.0 && p.y < h - 1.0;
            if status.get(i).map_err(cv)? == 0 || !inside {
                continue;
            }
            self.klt_tracked += 1;
            let fb = ((b.x - q.x).powi(2) + (b.y - q.y).powi(2)).sqrt() as f64;
            if status_b.get(i).map_err(cv)? != 0 && fb <= self.opts.fb_threshold {
                self.fb_kept += 1;
                *k = true;
                self.pts[i] = p;
            }
        }
        Ok(keep)
    }

    /// Each tracked feature moved onto its anchor's patch in `img` (the
    /// image KLT just tracked into); where that fails, KLT's position stays
    /// and a new anchor starts there ([`super::anchor`]).
    fn hold_to_anchors(&mut self, img: &GrayImage) {
        for (p, anchor) in self.pts.iter_mut().zip(&mut self.anchors) {
            let klt = [p.x as f64, p.y as f64];
            if let Some(a) = anchor.as_mut() {
                self.anchor_tried += 1;
                if let Some([u, v]) = a.align(img, klt) {
                    self.anchor_held += 1;
                    *p = Point2f::new(u as f32, v as f32);
                    continue;
                }
            }
            *anchor = Anchor::new(img, klt);
        }
    }

    /// RANSAC on the fundamental matrix between the undistorted old and new points.
    fn ransac(&mut self, old: &[Point2f]) -> Result<Vec<bool>, FrontendError> {
        let n = self.pts.len();
        if n < 8 {
            return Ok(vec![true; n]);
        }
        let c = &self.camera;
        let undistort = |p: &Point2f| -> Option<Point2f> {
            let xy = c.unproject([p.x as f64, p.y as f64])?;
            Some(Point2f::new((c.fx * xy[0] + c.cx) as f32, (c.fy * xy[1] + c.cy) as f32))
        };
        let mut a = Vector::<Point2f>::with_capacity(n);
        let mut b = Vector::<Point2f>::with_capacity(n);
        let mut keep = vec![false; n];
        let mut idx = Vec::with_capacity(n);
        for (i, (o, c)) in old.iter().zip(&self.pts).enumerate() {
            if let (Some(p), Some(q)) = (undistort(o), undistort(c)) {
                a.push(p);
                b.push(q);
                idx.push(i);
            }
        }
        if idx.len() < 8 {
            return Ok(vec![true; n]);
        }
        let mut mask = Vector::<u8>::new();
        calib3d::find_fundamental_mat(&a, &b, calib3d::FM_RANSAC, self.opts.ransac_threshold, 0.99, 1000, &mut mask)
            .map_err(cv)?;
        self.ransac_in += idx.len() as u64;
        for (k, &i) in idx.iter().enumerate() {
            if mask.get(k).map_err(cv)? != 0 {
                keep[i] = true;
                self.ransac_kept += 1;
            }
        }
        Ok(keep)
    }

    /// Longest tracks first; drop those within `min_distance` of a longer one; returns the mask for new corners.
    fn spread(&mut self, rows: i32, cols: i32) -> Result<Mat, FrontendError> {
        let mut mask = Mat::new_rows_cols_with_default(rows, cols, core::CV_8UC1, Scalar::all(255.0)).map_err(cv)?;
        let mut order: Vec<usize> = (0..self.pts.len()).collect();
        order.sort_by(|&i, &j| self.ages[j].cmp(&self.ages[i]).then(self.ids[i].cmp(&self.ids[j])));
        let mut keep = vec![false; self.pts.len()];
        let r = self.opts.min_distance.round() as i32;
        for i in order {
            let p = Point::new(self.pts[i].x.round() as i32, self.pts[i].y.round() as i32);
            if p.x < 0 || p.y < 0 || p.x >= cols || p.y >= rows {
                continue;
            }
            if *mask.at_2d::<u8>(p.y, p.x).map_err(cv)? == 255 {
                keep[i] = true;
                imgproc::circle(&mut mask, p, r, Scalar::all(0.0), -1, imgproc::LINE_8, 0).map_err(cv)?;
            }
        }
        self.retain(&keep);
        Ok(mask)
    }

    /// Up to `want` new Shi–Tomasi corners of `image` where `mask` is nonzero.
    fn detect(&mut self, image: &GrayImage, mask: &Mat, want: usize) -> Result<Vec<[f32; 2]>, FrontendError> {
        let search = CornerSearch {
            mask: mask.data_bytes().map_err(cv)?,
            max_corners: want,
            quality: self.opts.quality,
            min_distance: self.opts.min_distance,
        };
        Ok(self.corners.detect(image, &search))
    }

    /// Track into the next image (8-bit grayscale); returns the features seen, `(track id, [u, v])`.
    pub fn track(&mut self, image: &Mat) -> Result<Vec<(u64, [f64; 2])>, FrontendError> {
        self.track_turned(image, None)
    }

    /// [`KltTracker::track`], each feature's search started where the
    /// camera's rotation since the last image moves it: `rotation` is
    /// `R_{c_now ← c_prev}` (a bearing of the last image's camera frame in
    /// this one's; [`gyro_rotations`](super::gyro_rotations) gives it from an
    /// IMU). None: started at the old places.
    pub fn track_turned(
        &mut self,
        image: &Mat,
        rotation: Option<&nalgebra::Rotation3<f64>>,
    ) -> Result<Vec<(u64, [f64; 2])>, FrontendError> {
        if image.empty() {
            return Err("empty image".into());
        }
        if image.typ() != core::CV_8UC1 {
            return Err(format!("the tracker wants 8-bit grayscale images, got OpenCV type {}", image.typ()).into());
        }
        let start = Instant::now();
        let img = match self.opts.equalize {
            true => {
                if self.clahe.is_none() {
                    self.clahe = Some(imgproc::create_clahe(3.0, Size::new(8, 8)).map_err(cv)?);
                }
                let mut out = Mat::default();
                self.clahe.as_mut().expect("just set").apply(image, &mut out).map_err(cv)?;
                out
            }
            false => image.try_clone().map_err(cv)?,
        };
        let pyr = self.pyramid(&img)?;
        let image = gray(&img)?;
        if let (Some(prev), false) = (self.prev.take(), self.pts.is_empty()) {
            let old = self.pts.clone();
            let keep = self.klt(&prev, &pyr, img.size().map_err(cv)?, rotation)?;
            let old: Vec<Point2f> = old.iter().zip(&keep).filter(|(_, &k)| k).map(|(p, _)| *p).collect();
            self.retain(&keep);
            if self.opts.anchored {
                self.hold_to_anchors(&image);
            }
            let keep = self.ransac(&old)?;
            self.retain(&keep);
        }
        self.ages.iter_mut().for_each(|a| *a += 1);
        let mask = self.spread(img.rows(), img.cols())?;
        let want = self.opts.max_features.saturating_sub(self.pts.len());
        if want > 0 {
            let corners = self.detect(&image, &mask, want)?;
            for [x, y] in corners {
                let anchor = self.opts.anchored.then(|| Anchor::new(&image, [x as f64, y as f64])).flatten();
                self.anchors.push(anchor);
                self.pts.push(Point2f::new(x, y));
                self.ids.push(self.next_id);
                self.ages.push(1);
                self.next_id += 1;
            }
        }
        self.prev = Some(pyr);
        self.frames += 1;
        self.features += self.pts.len();
        self.seconds += start.elapsed().as_secs_f64();
        Ok(self.ids.iter().zip(&self.pts).map(|(&id, p)| (id, [p.x as f64, p.y as f64])).collect())
    }
}

/// `track`'s image (its own continuous copy, or CLAHE's output: rows
/// without padding) as the pure-Rust parts of the frontend see it.
fn gray(img: &Mat) -> Result<GrayImage<'_>, FrontendError> {
    Ok(GrayImage { pixels: img.data_bytes().map_err(cv)?, width: img.cols() as usize, height: img.rows() as usize })
}

/// [`read_gray`](crate::io::image::read_gray), refusing an image whose size is not `resolution` `[w, h]` (from sensor.yaml) when given.
fn read_sized(path: &Path, resolution: Option<[u32; 2]>) -> Result<Mat, FrontendError> {
    let img = crate::io::image::read_gray(path)?;
    if let Some([w, h]) = resolution {
        if img.cols() as u32 != w || img.rows() as u32 != h {
            return Err(format!(
                "{}: image is {}×{}, sensor.yaml says {w}×{h}",
                path.display(),
                img.cols(),
                img.rows()
            )
            .into());
        }
    }
    Ok(img)
}

/// Track a camera's frames `(t[ns], image path)` in order; `progress(done, total)`
/// is called after each frame. Images must all have `resolution` `[w, h]` when given.
/// `rotations[k]`, when given, is the camera's rotation from frame `k − 1` to
/// frame `k` ([`KltTracker::track_turned`]; [`gyro_rotations`](super::gyro_rotations)).
pub fn track_camera(
    frames: &[(i64, std::path::PathBuf)],
    camera: CameraModel,
    resolution: Option<[u32; 2]>,
    opts: &FrontendOptions,
    rotations: Option<&[Option<nalgebra::Rotation3<f64>>]>,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<(Vec<Observation>, FrontendStats), FrontendError> {
    let mut tracker = KltTracker::new(camera, opts.clone());
    let mut obs = Vec::new();
    for (k, (t, path)) in frames.iter().enumerate() {
        let img = read_sized(path, resolution)?;
        let turn = rotations.and_then(|r| r.get(k)).and_then(Option::as_ref);
        let f = tracker.track_turned(&img, turn).map_err(|e| format!("{}: {e}", path.display()))?;
        obs.extend(f.into_iter().map(|(id, uv)| (*t, id, uv)));
        progress(k + 1, frames.len());
    }
    Ok((obs, tracker.stats()))
}

/// Draw the tracks seen in frame `t_ns` over its image: each feature's path
/// over the last `history` frames, colored from red (new) to blue (tracked
/// for 20 frames or more); written as PNG to `out`.
pub fn draw_tracks(
    image: &Path,
    t_ns: i64,
    obs: &[Observation],
    history: usize,
    out: &Path,
) -> Result<(), FrontendError> {
    let gray = crate::io::image::read_gray(image)?;
    let mut img = Mat::default();
    imgproc::cvt_color(&gray, &mut img, imgproc::COLOR_GRAY2BGR, 0).map_err(cv)?;
    let mut times: Vec<i64> = obs.iter().map(|o| o.0).filter(|&t| t <= t_ns).collect();
    times.dedup();
    let from = times[times.len().saturating_sub(history)..].first().copied().unwrap_or(t_ns);
    let mut paths: std::collections::BTreeMap<u64, Vec<[f64; 2]>> = Default::default();
    let mut length: std::collections::HashMap<u64, usize> = Default::default();
    for &(t, id, uv) in obs.iter().filter(|o| o.0 <= t_ns) {
        *length.entry(id).or_default() += 1;
        if t >= from {
            paths.entry(id).or_default().push(uv);
        }
    }
    let pt = |p: [f64; 2]| Point::new(p[0].round() as i32, p[1].round() as i32);
    let current: std::collections::HashSet<u64> = obs.iter().filter(|o| o.0 == t_ns).map(|o| o.1).collect();
    for (id, path) in paths.iter().filter(|(id, _)| current.contains(id)) {
        let f = (length[id] as f64 / 20.0).min(1.0);
        let color = Scalar::new(255.0 * f, 0.0, 255.0 * (1.0 - f), 0.0);
        for w in path.windows(2) {
            imgproc::line(&mut img, pt(w[0]), pt(w[1]), color, 1, imgproc::LINE_AA, 0).map_err(cv)?;
        }
        let last = *path.last().expect("non-empty");
        imgproc::circle(&mut img, pt(last), 3, color, -1, imgproc::LINE_AA, 0).map_err(cv)?;
    }
    let ok = imgcodecs::imwrite(out, &img, &Vector::new()).map_err(|e| format!("{}: {e}", out.display()))?;
    if !ok {
        return Err(format!("{}: could not write the image", out.display()).into());
    }
    Ok(())
}

/// A synthetic image sequence with known motion, for testing and benchmarking
/// the tracker: frame `k` is the `size` `[w, h]` window at the centre of
/// `base`, after `base` was rotated by `k·deg_per_frame` degrees about that
/// centre and shifted by `k·px_per_frame` pixels. Returns the frames and, per
/// frame, the affine map from the first frame's pixels to that frame's.
/// Errors when the window would leave `base` by the last frame.
pub fn moving_window(
    base: &Mat,
    size: [i32; 2],
    frames: usize,
    px_per_frame: [f64; 2],
    deg_per_frame: f64,
) -> Result<(Vec<Mat>, Vec<nalgebra::Matrix2x3<f64>>), FrontendError> {
    let (bw, bh) = (base.cols() as f64, base.rows() as f64);
    let (w, h) = (size[0] as f64, size[1] as f64);
    let n = frames.saturating_sub(1) as f64;
    let ang = (n * deg_per_frame).to_radians().abs();
    let half_diag = 0.5 * (w * w + h * h).sqrt();
    let reach_x = 0.5 * w * ang.cos() + 0.5 * h * ang.sin() + n * px_per_frame[0].abs();
    let reach_y = 0.5 * h * ang.cos() + 0.5 * w * ang.sin() + n * px_per_frame[1].abs();
    if reach_x > 0.5 * bw || reach_y > 0.5 * bh || half_diag * ang > 0.5 * bw {
        return Err(format!("a {w}×{h} window moving this far leaves the {bw}×{bh} image").into());
    }
    let (cx, cy) = (0.5 * bw, 0.5 * bh);
    let (ox, oy) = (cx - 0.5 * w, cy - 0.5 * h);
    let mut imgs = Vec::with_capacity(frames);
    let mut maps = Vec::with_capacity(frames);
    for k in 0..frames {
        let a = (k as f64 * deg_per_frame).to_radians();
        let (c, s) = (a.cos(), a.sin());
        let (tx, ty) = (k as f64 * px_per_frame[0], k as f64 * px_per_frame[1]);
        // Base pixel → rotated+shifted base pixel → window pixel.
        let m = nalgebra::Matrix2x3::new(c, -s, cx - c * cx + s * cy + tx - ox, s, c, cy - s * cx - c * cy + ty - oy);
        let cvm =
            Mat::from_slice_2d(&[[m[(0, 0)], m[(0, 1)], m[(0, 2)]], [m[(1, 0)], m[(1, 1)], m[(1, 2)]]]).map_err(cv)?;
        let mut out = Mat::default();
        imgproc::warp_affine(
            base,
            &mut out,
            &cvm,
            Size::new(size[0], size[1]),
            imgproc::INTER_LINEAR,
            core::BORDER_REFLECT,
            Scalar::default(),
        )
        .map_err(cv)?;
        imgs.push(out);
        maps.push(m);
    }
    // From the first frame's pixels: M_k ∘ M_0⁻¹.
    let to3 = |m: &nalgebra::Matrix2x3<f64>| {
        let mut t = nalgebra::Matrix3::identity();
        t.fixed_view_mut::<2, 3>(0, 0).copy_from(m);
        t
    };
    let inv0 = to3(&maps[0]).try_inverse().ok_or("singular first map")?;
    let rel = maps.iter().map(|m| (to3(m) * inv0).fixed_view::<2, 3>(0, 0).into_owned()).collect();
    Ok((imgs, rel))
}

/// Forward status, backward positions, backward status of [`klt_both_ways`].
type BothWays = (Vector<u8>, Vector<Point2f>, Vector<u8>);

/// Pyramidal KLT from `a` to `b` (images or their pyramids) into `next`
/// (which holds the starts when `initial`), then back from where the features
/// went, starting at their old places; `levels` for each direction. Returns
/// the forward status, the backward positions and the backward status.
fn klt_both_ways(
    a: &impl core::ToInputArray,
    b: &impl core::ToInputArray,
    pts: &Vector<Point2f>,
    next: &mut Vector<Point2f>,
    win: Size,
    levels: [i32; 2],
    initial: bool,
) -> Result<BothWays, FrontendError> {
    let crit = TermCriteria::new(core::TermCriteria_COUNT + core::TermCriteria_EPS, 30, 0.01).map_err(cv)?;
    let (mut status, mut err) = (Vector::<u8>::new(), Vector::<f32>::new());
    let flags = if initial { video::OPTFLOW_USE_INITIAL_FLOW } else { 0 };
    video::calc_optical_flow_pyr_lk(a, b, pts, next, &mut status, &mut err, win, levels[0], crit, flags, 1e-4)
        .map_err(cv)?;
    let mut back = pts.clone();
    let mut status_b = Vector::<u8>::new();
    video::calc_optical_flow_pyr_lk(
        b,
        a,
        &*next,
        &mut back,
        &mut status_b,
        &mut err,
        win,
        levels[1],
        crit,
        video::OPTFLOW_USE_INITIAL_FLOW,
        1e-4,
    )
    .map_err(cv)?;
    Ok((status, back, status_b))
}

/// Where KLT starts a stereo match: the feature's left ray at these depths
/// \[m\] (its own earlier depth first when known), tried in turn for the
/// features still unmatched. One pyramid level above the image: with a start
/// this close, a deeper pyramid lets KLT wander off on low-texture surfaces
/// (V1_01: 21 % matched with 3 levels from one guess, 33 % with 0–1 levels).
const STEREO_DEPTHS_M: [f64; 4] = [2.0, 1.0, 4.0, 0.6];
const STEREO_LEVELS: i32 = 1;

/// Match features of a left image into the right image of a stereo pair:
/// KLT started where the feature would be at a prior depth (`prior` by track
/// id, else 2, 1, 4 and 0.6 m in turn), the forward–backward
/// check, then the epipolar constraint of the known extrinsics
/// (`right_from_left`, the left camera's pose in the right camera's frame) on
/// undistorted points, and a positive, finite depth. Returns `(track id,
/// right pixel [u, v], depth in the left camera [m])` per match and adds to
/// `stats`.
#[allow(clippy::too_many_arguments)]
pub fn match_stereo(
    left: &Mat,
    right: &Mat,
    features: &[(u64, [f64; 2])],
    cams: [&CameraModel; 2],
    right_from_left: &nalgebra::Isometry3<f64>,
    prior: &std::collections::HashMap<u64, f64>,
    opts: &FrontendOptions,
    stats: &mut StereoStats,
) -> Result<Vec<(u64, [f64; 2], f64)>, FrontendError> {
    use nalgebra::Vector3;
    let [cam0, cam1] = cams;
    stats.pairs += 1;
    stats.offered += features.len();
    let r = right_from_left.rotation.to_rotation_matrix().into_inner();
    let t = right_from_left.translation.vector;
    let win = Size::new(opts.window, opts.window);
    let (w, h) = (right.cols() as f32, right.rows() as f32);
    // The right pixel of left feature `uv` at `depth`.
    let at_depth = |uv: &[f64; 2], depth: f64| -> Option<Point2f> {
        let x = cam0.unproject(*uv)?;
        let p = r * (Vector3::new(x[0], x[1], 1.0) * depth) + t;
        let q = cam1.project(&[p.x, p.y, p.z])?;
        Some(Point2f::new(q[0] as f32, q[1] as f32))
    };
    let mut result: Vec<Option<([f64; 2], f64)>> = vec![None; features.len()];
    let mut klt_kept = vec![false; features.len()];
    for attempt in 0..=STEREO_DEPTHS_M.len() {
        // Features still unmatched and the start of each.
        let mut idx = Vec::new();
        let (mut pts, mut next) = (Vector::<Point2f>::new(), Vector::<Point2f>::new());
        for (i, (id, uv)) in features.iter().enumerate() {
            let depth = match (attempt, prior.get(id)) {
                _ if result[i].is_some() => continue,
                (0, Some(d)) => *d,
                (0, None) => continue,
                (k, _) => STEREO_DEPTHS_M[k - 1],
            };
            if let Some(g) = at_depth(uv, depth) {
                idx.push(i);
                pts.push(Point2f::new(uv[0] as f32, uv[1] as f32));
                next.push(g);
            }
        }
        if idx.is_empty() {
            continue;
        }
        let levels = [STEREO_LEVELS, STEREO_LEVELS];
        let (status, back, status_b) = klt_both_ways(left, right, &pts, &mut next, win, levels, true)?;
        for (k, &i) in idx.iter().enumerate() {
            let uv0 = features[i].1;
            let (p, b) = (next.get(k).map_err(cv)?, back.get(k).map_err(cv)?);
            let inside = p.x >= 1.0 && p.y >= 1.0 && p.x < w - 1.0 && p.y < h - 1.0;
            let fb = ((b.x as f64 - uv0[0]).powi(2) + (b.y as f64 - uv0[1]).powi(2)).sqrt();
            if status.get(k).map_err(cv)? == 0 || status_b.get(k).map_err(cv)? == 0 || !inside || fb > opts.fb_threshold
            {
                continue;
            }
            klt_kept[i] = true;
            let uv1 = [p.x as f64, p.y as f64];
            let (Some(x0), Some(x1)) = (cam0.unproject(uv0), cam1.unproject(uv1)) else { continue };
            // The left ray in the right frame; the epipolar plane holds it and the baseline.
            let f0 = r * Vector3::new(x0[0], x0[1], 1.0);
            let f1 = Vector3::new(x1[0], x1[1], 1.0);
            let n = t.cross(&f0);
            let line = (n.x * n.x + n.y * n.y).sqrt();
            if line < 1e-12 {
                continue;
            }
            let epipolar_px = (n.dot(&f1) / line).abs() * cam1.fx;
            if epipolar_px > opts.ransac_threshold {
                continue;
            }
            // Depth along the left ray: least squares on d0·f0 + t = d1·f1.
            let a = nalgebra::Matrix3x2::from_columns(&[f0, -f1]);
            let Some(d) = (a.transpose() * a).try_inverse().map(|m| m * a.transpose() * (-t)) else { continue };
            if d[0].is_finite() && d[0] > 0.05 && d[1] > 0.05 && d[0] < 1000.0 {
                stats.epipolar_px.push(epipolar_px);
                stats.depths_m.push(d[0]);
                result[i] = Some((uv1, d[0]));
            }
        }
    }
    stats.klt_kept += klt_kept.iter().filter(|&&k| k).count();
    Ok(features.iter().zip(result).filter_map(|((id, _), m)| m.map(|(uv, d)| (*id, uv, d))).collect())
}

/// Track cam0's frames and match each into cam1's image of the same time
/// (`frames`: `(t[ns], left image, right image if any)`; images must have the
/// `resolutions` of their sensor.yaml when given). Returns the cam0
/// observations, the cam1 observations (same track ids), and the statistics.
/// `rotations`: cam0's rotation between consecutive frames, as for [`track_camera`].
#[allow(clippy::type_complexity)]
pub fn track_stereo(
    frames: &[(i64, std::path::PathBuf, Option<std::path::PathBuf>)],
    cams: [CameraModel; 2],
    resolutions: [Option<[u32; 2]>; 2],
    right_from_left: &nalgebra::Isometry3<f64>,
    opts: &FrontendOptions,
    rotations: Option<&[Option<nalgebra::Rotation3<f64>>]>,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<(Vec<Observation>, Vec<Observation>, FrontendStats), FrontendError> {
    let mut tracker = KltTracker::new(cams[0], opts.clone());
    let mut stereo = StereoStats::default();
    let mut depths = std::collections::HashMap::new();
    let (mut obs0, mut obs1) = (Vec::new(), Vec::new());
    for (k, (t, left, right)) in frames.iter().enumerate() {
        let img = read_sized(left, resolutions[0])?;
        let turn = rotations.and_then(|r| r.get(k)).and_then(Option::as_ref);
        let f = tracker.track_turned(&img, turn).map_err(|e| format!("{}: {e}", left.display()))?;
        if let Some(right) = right {
            let rimg = read_sized(right, resolutions[1])?;
            let m = match_stereo(&img, &rimg, &f, [&cams[0], &cams[1]], right_from_left, &depths, opts, &mut stereo)
                .map_err(|e| format!("{}: {e}", right.display()))?;
            depths = m.iter().map(|(id, _, d)| (*id, *d)).collect();
            obs1.extend(m.into_iter().map(|(id, uv, _)| (*t, id, uv)));
        }
        obs0.extend(f.into_iter().map(|(id, uv)| (*t, id, uv)));
        progress(k + 1, frames.len());
    }
    let mut stats = tracker.stats();
    stats.stereo = Some(stereo);
    Ok((obs0, obs1, stats))
}

//! The camera's extrinsic `T_BC` and time offset `td` as variables of the
//! window ([`super::CameraCalibrationOptions`]): their keys, the prior at the
//! given values, and the values the landmarks and factors read.
//!
//! Each is one variable for the whole run. Their prior stays in every window
//! graph; the information of the measurements that leave the window reaches
//! them through the marginalization prior (they are in its separator), so
//! nothing is counted twice. A parameter that is not estimated is held
//! constant at its value; the estimator also holds them until a window's
//! length of keyframes is in the prior, and after an estimate that
//! `CameraPrior::implausible` rejects. A parameter estimated `auto` is
//! estimated along the directions the window determines and held along the
//! others (`super::auto_calib`).

use super::auto_calib::HeldDirections;
use super::{CameraCalibrationOptions, Estimate, VioInput};
use crate::model::geometry::{parts, pose};
use crate::model::ImuData;
use crate::model::DETERMINED_FRACTION;
use nalgebra::{DMatrix, Matrix3, Vector1, Vector3, Vector6};
use tumble_factors::reprojection::ExposureMotion;
use tumble_factors::PriorFactor;
use tumble_solvers::sophus_lie::Isometry3F64;
use tumble_solvers::{Covariances, Graph, Key, NoiseModel, SolveError, Values, V, X};

/// Key of the first camera's pose in the IMU frame `T_BC` (SE(3)).
pub(crate) const EXTRINSIC: Key = Key::new('c', 0);
/// Key of the time offset `td` \[s\] (R¹).
pub(crate) const TIME_OFFSET: Key = Key::new('d', 0);

/// The estimate of the camera's calibration at the end of a run.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct CameraEstimate {
    /// `T_BC`: rotation body←camera `[w, x, y, z]`.
    pub rotation: [f64; 4],
    /// `T_BC`: the camera's centre in the body frame \[m\].
    pub translation: [f64; 3],
    /// Time offset \[s\] (t_imu = t_cam + td).
    pub time_offset_s: f64,
    /// σ of the rotation about the camera's axes \[deg\] (NaN when not estimated or not recovered).
    pub rotation_sigma_deg: [f64; 3],
    /// σ of the translation along the camera's axes \[m\] (NaN as above).
    pub translation_sigma_m: [f64; 3],
    /// σ of the time offset \[s\] (NaN as above).
    pub time_offset_sigma_s: f64,
    /// Rotation from the given `T_BC` to the estimate \[deg\].
    pub rotation_change_deg: f64,
    /// Distance from the given `T_BC`'s translation to the estimate's \[m\].
    pub translation_change_m: f64,
    /// Whether `T_BC` was estimated (`on`, or `auto` once determined).
    pub extrinsics_estimated: bool,
    /// Whether `td` was estimated (as above).
    pub time_offset_estimated: bool,
    /// With `auto`: whether and when the motion determined `T_BC`.
    pub extrinsics_auto: Option<AutoOutcome>,
    /// With `auto`: whether and when the motion determined `td`.
    pub time_offset_auto: Option<AutoOutcome>,
}

/// What `auto` ([`Estimate::Auto`]) decided for one online parameter.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct AutoOutcome {
    /// When the motion first determined a direction of it \[s\] (estimated
    /// from then on); None: never, it was held at the given value throughout.
    pub freed_at_s: Option<f64>,
    /// When every direction was determined \[s\].
    pub determined_at_s: Option<f64>,
    /// The directions still not determined at the end, held at the given
    /// value: each named by its largest components (rotation about the
    /// camera's axes, translation along them, in the prior's σ units) with
    /// the σ the data and the prior give it, as a fraction of the prior's.
    pub held: Vec<(String, f64)>,
}

impl AutoOutcome {
    /// What stayed held, for the terminal; None when nothing did.
    fn held(&self, what: &str) -> Option<String> {
        if self.held.is_empty() {
            return None;
        }
        let list: Vec<String> = self.held.iter().map(|(d, f)| format!("{d} (σ {f:.2} of its prior's)")).collect();
        Some(format!(
            "{what} not determined by this motion along {}, where a σ below {DETERMINED_FRACTION:.2} of the prior's is \
             needed: held at the given value there",
            list.join(", ")
        ))
    }

    /// When it was estimated, for the terminal.
    fn when(&self) -> String {
        match (self.freed_at_s, self.determined_at_s) {
            (_, Some(t)) => format!(" (auto: determined at {t:.2} s)"),
            (Some(t), None) => format!(" (auto: partly determined from {t:.2} s)"),
            _ => String::new(),
        }
    }
}

impl CameraEstimate {
    /// The rotation \[deg\] and the distance between the translations \[m\]
    /// from `body_from_camera` (a reference `T_BC`) to this estimate.
    pub fn difference(&self, body_from_camera: &Isometry3F64) -> (f64, f64) {
        let (rot, t) = deviation(body_from_camera, &self.body_from_camera());
        (rot.norm().to_degrees(), t.norm())
    }

    /// The rotation from `body_from_camera` (a reference `T_BC`) to this
    /// estimate, a rotation vector about the reference camera's axes \[rad\]:
    /// the error [`CameraEstimate::rotation_sigma_deg`] describes.
    pub fn rotation_error(&self, body_from_camera: &Isometry3F64) -> Vector3<f64> {
        deviation(body_from_camera, &self.body_from_camera()).0
    }

    /// This estimate's `T_BC`.
    fn body_from_camera(&self) -> Isometry3F64 {
        let [w, x, y, z] = self.rotation;
        let q = nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z));
        pose(q.to_rotation_matrix().matrix(), &Vector3::from(self.translation))
    }

    /// This estimate's translation minus `body_from_camera`'s (a reference
    /// `T_BC`), along the reference camera's axes \[m\].
    pub fn translation_error(&self, body_from_camera: &Isometry3F64) -> Vector3<f64> {
        let (r, t) = parts(body_from_camera);
        r.transpose() * (Vector3::from(self.translation) - t)
    }

    /// One line for the terminal: what was estimated, its σ and how far it moved from the given values.
    pub fn line(&self) -> String {
        let mut parts = Vec::new();
        let auto = |o: &Option<AutoOutcome>| o.as_ref().map_or(String::new(), AutoOutcome::when);
        parts.extend(self.extrinsics_auto.as_ref().and_then(|o| o.held("T_BC")));
        parts.extend(self.time_offset_auto.as_ref().and_then(|o| o.held("the time offset")));
        if self.extrinsics_estimated {
            let [a, b, c] = self.rotation_sigma_deg;
            let [x, y, z] = self.translation_sigma_m.map(|s| s * 1e3);
            let t = self.translation;
            parts.push(format!(
                "T_BC translation [{:.4}, {:.4}, {:.4}] m (σ {x:.1} {y:.1} {z:.1} mm), rotation σ {a:.3} {b:.3} {c:.3}°; \
                 moved {:.3}° and {:.1} mm from the given{}",
                t[0],
                t[1],
                t[2],
                self.rotation_change_deg,
                self.translation_change_m * 1e3,
                auto(&self.extrinsics_auto)
            ));
        }
        if self.time_offset_estimated {
            parts.push(format!(
                "time offset {:.2} ms (σ {:.2} ms, t_imu = t_cam + offset){}",
                self.time_offset_s * 1e3,
                self.time_offset_sigma_s * 1e3,
                auto(&self.time_offset_auto)
            ));
        }
        format!(
            "camera estimated online: {} (σ are the window's precision and optimistic: docs/vio.md)",
            parts.join("; ")
        )
    }
}

/// The prior of the online calibration: the given values and their σ, and,
/// for a parameter estimated `auto`, when the recording was found to determine it.
#[derive(Debug, Clone)]
pub(crate) struct CameraPrior {
    body_from_camera: Isometry3F64,
    pose_sigma: [f64; 6],
    td_sigma: f64,
    /// How `T_BC` and `td` are estimated (in the order of [`GROUPS`]).
    modes: [Estimate; 2],
    /// `auto`: the directions of each the recording has not determined yet.
    auto: [Option<HeldDirections>; 2],
}

/// The online parameters' keys: `T_BC`, then `td`.
const GROUPS: [Key; 2] = [EXTRINSIC, TIME_OFFSET];

impl CameraPrior {
    /// The prior for `input` under `c`; None when nothing is estimated.
    pub fn new(input: &VioInput, c: &CameraCalibrationOptions) -> Option<CameraPrior> {
        if !c.online() {
            return None;
        }
        let r = c.rotation_sigma_deg.to_radians();
        let t = c.translation_sigma_m;
        Some(CameraPrior {
            body_from_camera: input.body_from_camera,
            pose_sigma: [r, r, r, t, t, t],
            td_sigma: c.time_offset_sigma_s,
            modes: [c.extrinsics, c.time_offset],
            auto: [(c.extrinsics, 6), (c.time_offset, 1)]
                .map(|(m, dim)| (m == Estimate::Auto).then(|| HeldDirections::all(dim))),
        })
    }

    /// Whether group `g` of [`GROUPS`] is estimated (`on` or `auto`).
    fn estimated(&self, g: usize) -> bool {
        self.modes[g] != Estimate::Off
    }

    /// Whether group `g` is free when the estimator frees the calibration
    /// (`on`, or `auto` once determined).
    fn freed(&self, g: usize) -> bool {
        match self.modes[g] {
            Estimate::Off => false,
            Estimate::On => true,
            Estimate::Auto => self.auto[g].as_ref().is_some_and(HeldDirections::freed),
        }
    }

    /// The prior σ of group `g` \[rad, m or s\].
    fn sigma(&self, g: usize) -> &[f64] {
        if g == 0 {
            &self.pose_sigma
        } else {
            std::slice::from_ref(&self.td_sigma)
        }
    }

    /// The noise of group `g`'s prior: its σ, with the directions `auto`
    /// holds held once it is free.
    fn prior_noise(&self, g: usize) -> NoiseModel {
        let sigma = self.sigma(g);
        let Some(h) = self.auto[g].as_ref().filter(|h| h.freed() && h.held.ncols() > 0) else {
            return self.plain_noise(g);
        };
        NoiseModel::from_information(&over_sigmas(&h.prior_information(), sigma)).expect("validated positive σ")
    }

    /// The noise of group `g`'s prior as given: its σ, nothing held.
    fn plain_noise(&self, g: usize) -> NoiseModel {
        NoiseModel::diagonal(self.sigma(g)).expect("validated positive σ")
    }

    /// What `auto` decided for group `g` so far (None unless it is `auto`).
    fn auto_outcome(&self, g: usize) -> Option<AutoOutcome> {
        let h = self.auto[g].as_ref()?;
        let names: &[&str] = if g == 0 { &EXTRINSIC_DIRECTIONS } else { &["time offset"] };
        let held = (0..h.held.ncols()).map(|c| (direction_name(h.held.column(c).as_slice(), names), h.fractions[c]));
        Some(AutoOutcome { freed_at_s: h.freed_at, determined_at_s: h.determined_at, held: held.collect() })
    }

    /// Put the variables into `values` at `current` (`T_BC`, `td`) or, without
    /// one, at the given values, held constant (see [`CameraPrior::free`]).
    pub fn insert(&self, values: &mut Values, current: Option<(Isometry3F64, f64)>) {
        let (x, td) = current.unwrap_or((self.body_from_camera, 0.0));
        values.insert(EXTRINSIC, x);
        values.insert(TIME_OFFSET, Vector1::new(td));
        self.free(values, false);
    }

    /// Free the estimated parameters in `values` (`free`; an `auto` one only
    /// once it was found determined), or hold them at their values (the
    /// estimator decides when).
    pub fn free(&self, values: &mut Values, free: bool) {
        for (g, key) in GROUPS.into_iter().enumerate() {
            values.set_constant(key, !(free && self.freed(g)));
        }
    }

    /// For each `auto` parameter with directions still held: its covariance
    /// in the window's `graph` at `solved` (the keyframe's solution) as if it
    /// were free and under its plain prior (the graph's priors on it are
    /// replaced: subtracting a hold's information from the covariance's
    /// inverse would lose the data's to rounding), whitened by the prior's σ,
    /// from which [`HeldDirections::update`] releases the directions the data
    /// now determine (time `t` \[s\]).
    pub fn probe(&mut self, t: f64, graph: &mut Graph, solved: &Values) -> Result<(), SolveError> {
        let pending: Vec<usize> =
            (0..2).filter(|&g| self.auto[g].as_ref().is_some_and(|h| h.held.ncols() > 0)).collect();
        if pending.is_empty() {
            return Ok(());
        }
        let mut values = solved.clone();
        let keys: Vec<Key> = pending.iter().map(|&g| GROUPS[g]).collect();
        let priors: Vec<usize> =
            (0..graph.len()).filter(|&i| keys.iter().any(|&k| graph.entries()[i].factor.keys() == [k])).collect();
        graph.remove(&priors);
        for &g in &pending {
            values.set_constant(GROUPS[g], false);
            self.add_prior(graph, g, self.plain_noise(g));
        }
        let cov = tumble_solvers::covariances_eliminating(graph, &values, &keys, &['l'])?;
        for g in pending {
            let Some(block) = cov.get(GROUPS[g]).filter(|b| b.nrows() == self.sigma(g).len()) else { continue };
            let whitened = over_sigmas(&block, self.sigma(g));
            if let Some(h) = self.auto[g].as_mut() {
                h.update(t, &whitened).ok_or_else(|| SolveError::Config("a singular calibration covariance".into()))?;
            }
        }
        Ok(())
    }

    /// Add the priors of the estimated parameters to `g`.
    pub fn add_factors(&self, g: &mut Graph) {
        for k in (0..2).filter(|&k| self.estimated(k)) {
            self.add_prior(g, k, self.prior_noise(k));
        }
    }

    /// Add group `k`'s prior at the given value with `noise` to `g`.
    fn add_prior(&self, g: &mut Graph, k: usize, noise: NoiseModel) {
        if k == 0 {
            g.add(PriorFactor::new(EXTRINSIC, self.body_from_camera), noise);
        } else {
            g.add(PriorFactor::new(TIME_OFFSET, Vector1::new(0.0)), noise);
        }
    }

    /// Why the calibration in `values` cannot be right, or None: its distance
    /// from the given values, normalized by the prior's σ, beyond the 99.9 %
    /// quantile of χ² with as many degrees of freedom as are free in
    /// `values` (a wrong minimum of the window's solve, or a prior that does
    /// not hold).
    pub fn implausible(&self, values: &Values) -> Option<String> {
        let (x, td) = current(values)?;
        let (rot, t) = deviation(&self.body_from_camera, &x);
        let mut d2 = 0.0;
        let mut dof = 0;
        if !values.is_constant(EXTRINSIC) {
            d2 += (rot / self.pose_sigma[0]).norm_squared() + (t / self.pose_sigma[3]).norm_squared();
            dof += 6;
        }
        if !values.is_constant(TIME_OFFSET) {
            d2 += (td / self.td_sigma).powi(2);
            dof += 1;
        }
        // χ² quantiles at 0.999 for 1, 6 and 7 degrees of freedom.
        let limit = match dof {
            0 => return None,
            1 => 10.83,
            6 => 22.46,
            _ => 24.32,
        };
        (d2 > limit).then(|| {
            format!(
                "{:.1}° and {:.0} mm from the given T_BC, time offset {:.1} ms ({:.0} σ² of its prior, limit {limit})",
                rot.norm().to_degrees(),
                t.norm() * 1e3,
                td * 1e3,
                d2
            )
        })
    }

    /// The keys whose covariances the window's solve should recover: the
    /// parameters free in `values`.
    pub fn keys(&self, values: &Values) -> Vec<Key> {
        [EXTRINSIC, TIME_OFFSET].into_iter().filter(|&k| values.contains(k) && !values.is_constant(k)).collect()
    }

    /// The σ of group `g`'s coordinates from the window's `covariances` (NaN
    /// where it is not free or they are not given). Along the directions
    /// `auto` holds, the window's σ is the hold's, not the given value's: the
    /// σ the data and the plain prior leave there is added back.
    fn sigmas(&self, g: usize, covariances: Option<&Covariances>) -> Vec<f64> {
        let n = self.sigma(g).len();
        let Some(mut cov) = covariances.filter(|_| self.estimated(g)).and_then(|c| c.get(GROUPS[g])) else {
            return vec![f64::NAN; n];
        };
        if let Some(h) = &self.auto[g] {
            let d = DMatrix::from_diagonal(&nalgebra::DVector::from_column_slice(self.sigma(g)));
            let f2 = DMatrix::from_diagonal(&nalgebra::DVector::from_iterator(
                h.fractions.len(),
                h.fractions.iter().map(|f| f * f),
            ));
            cov += &d * &h.held * f2 * h.held.transpose() * &d;
        }
        (0..n).map(|i| cov[(i, i)].max(0.0).sqrt()).collect()
    }

    /// The estimate in `values`, its σ from `covariances` when given.
    pub fn estimate(&self, values: &Values, covariances: Option<&Covariances>) -> CameraEstimate {
        let x = current(values).map_or(self.body_from_camera, |c| c.0);
        let (r, t) = parts(&x);
        let q = nalgebra::UnitQuaternion::from_matrix(&r);
        let sigmas = |g: usize| self.sigmas(g, covariances);
        let (pose_sigma, td_sigma) = (sigmas(0), sigmas(1));
        let (change_rot, change_t) = deviation(&self.body_from_camera, &x);
        CameraEstimate {
            rotation: [q.w, q.i, q.j, q.k],
            translation: [t.x, t.y, t.z],
            time_offset_s: time_offset(values),
            rotation_sigma_deg: [0, 1, 2].map(|i| pose_sigma[i].to_degrees()),
            translation_sigma_m: [3, 4, 5].map(|i| pose_sigma[i]),
            time_offset_sigma_s: td_sigma[0],
            rotation_change_deg: change_rot.norm().to_degrees(),
            translation_change_m: change_t.norm(),
            extrinsics_estimated: self.freed(0),
            time_offset_estimated: self.freed(1),
            extrinsics_auto: self.auto_outcome(0),
            time_offset_auto: self.auto_outcome(1),
        }
    }
}

/// `m` with each element `(r, c)` divided by `sigma[r] · sigma[c]`: a
/// covariance into the prior's whitened coordinates, or a whitened
/// information out of them.
fn over_sigmas(m: &DMatrix<f64>, sigma: &[f64]) -> DMatrix<f64> {
    DMatrix::from_fn(m.nrows(), m.ncols(), |r, c| m[(r, c)] / (sigma[r] * sigma[c]))
}

/// The directions of `T_BC`'s tangent `[ω, ν]`, camera frame.
const EXTRINSIC_DIRECTIONS: [&str; 6] = [
    "rotation about x",
    "rotation about y",
    "rotation about z",
    "translation along x",
    "translation along y",
    "translation along z",
];

/// A unit direction `v` over the coordinates `names`: the one name whose
/// component carries at least 90 % of it, else the components above 30 %
/// with their signed weights.
fn direction_name(v: &[f64], names: &[&str]) -> String {
    if let Some(i) = (0..v.len()).find(|&i| v[i] * v[i] >= 0.9) {
        return names[i].to_string();
    }
    let parts: Vec<String> =
        (0..v.len()).filter(|&i| v[i] * v[i] >= 0.09).map(|i| format!("{:+.2} {}", v[i], names[i])).collect();
    format!("({})", parts.join(" "))
}

/// From `from` to `to` (two `T_BC`): the rotation vector `log(R_fromᵀ R_to)`
/// \[rad, camera frame\] and the translation difference \[m, body frame\].
fn deviation(from: &Isometry3F64, to: &Isometry3F64) -> (Vector3<f64>, Vector3<f64>) {
    let (r0, t0) = parts(from);
    let (r, t) = parts(to);
    (tumble_solvers::lie::so3_log(&(r0.transpose() * r)), t - t0)
}

/// The online calibration's current `T_BC` and `td` in `values`, when it is there.
pub(crate) fn current(values: &Values) -> Option<(Isometry3F64, f64)> {
    let x = values.get::<Isometry3F64>(EXTRINSIC).ok()?;
    Some((*x, time_offset(values)))
}

/// The camera's `T_BC` for the window: the online estimate in `values` when
/// there is one, else the input's.
pub(crate) fn body_from_camera(input: &VioInput, values: &Values) -> Isometry3F64 {
    current(values).map_or(input.body_from_camera, |c| c.0)
}

/// The time offset in `values` \[s\] (0 without online calibration).
fn time_offset(values: &Values) -> f64 {
    values.get::<Vector1<f64>>(TIME_OFFSET).map_or(0.0, |v| v[0])
}

/// The body's rotation (world ← body) and position \[m\] at the exposure of
/// the frame of state `sid` in `values`, whose motion around its stamp is
/// `motion`: its pose moved by the time offset in `values` as
/// [`tumble_factors::reprojection::CalibratingReprojection`] moves it,
/// `R Exp(ω₀ td + ω₁ td²/2 + ω₂ td³/3)` and `p + v td + (R f + g) td²/2`
/// (`gravity` \[m/s²\], world z up). Without a time offset, the stamp's
/// pose. None when the state is not in `values`.
pub(crate) fn body_at_exposure(
    values: &Values,
    sid: u64,
    motion: &ExposureMotion,
    gravity: f64,
) -> Option<(Matrix3<f64>, Vector3<f64>)> {
    let (r, p) = parts(values.get::<Isometry3F64>(X(sid)).ok()?);
    let td = time_offset(values);
    if td == 0.0 {
        return Some((r, p));
    }
    let v = *values.get::<Vector3<f64>>(V(sid)).ok()?;
    let accel = r * Vector3::from(motion.specific_force) - Vector3::new(0.0, 0.0, gravity);
    Some((r * tumble_solvers::lie::so3_exp(&motion.rotation_vector(td)), p + v * td + accel * (0.5 * td * td)))
}

/// The body's motion around the stamp `t` \[s\] from the IMU, for the time
/// offset: the gyro minus its bias (`bias` = `[b_a, b_g]`) fitted by a
/// quadratic in time by least squares over the samples within `half_width`
/// \[s\] of `t` (at least the two on each side), and the specific force at `t`
/// minus its bias. Too few samples give the rate at `t` alone.
pub(crate) fn exposure_motion(imu: &ImuData, t: f64, bias: &Vector6<f64>, half_width: f64) -> ExposureMotion {
    let (f, w) = imu.at(t);
    let (ba, bg) = (bias.fixed_rows::<3>(0).into_owned(), bias.fixed_rows::<3>(3).into_owned());
    let f = f - ba;
    let mut out = ExposureMotion { rate: [[0.0; 3]; 3], specific_force: [f.x, f.y, f.z] };
    let w0 = w - bg;
    out.rate[0] = [w0.x, w0.y, w0.z];
    let centre = imu.t.partition_point(|&s| s < t);
    let lo = imu.t.partition_point(|&s| s < t - half_width).min(centre.saturating_sub(2));
    let hi = imu.t.partition_point(|&s| s <= t + half_width).max((centre + 2).min(imu.t.len()));
    if hi < lo + 5 {
        return out;
    }
    // Normal equations of ω(s) = c₀ + c₁ s + c₂ s², s = t_k − t, per axis.
    let mut a = Matrix3::zeros();
    let mut b = Matrix3::zeros();
    for k in lo..hi {
        let s = imu.t[k] - t;
        let row = Vector3::new(1.0, s, s * s);
        a += row * row.transpose();
        b += row * (imu.gyro[k] - bg).transpose();
    }
    if let Some(c) = a.cholesky().map(|ch| ch.solve(&b)) {
        for (k, r) in out.rate.iter_mut().enumerate() {
            *r = [c[(k, 0)], c[(k, 1)], c[(k, 2)]];
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vio::VioOptions;

    #[test]
    fn the_fit_recovers_a_quadratic_rate_and_the_specific_force() {
        let rate = |s: f64| Vector3::new(1.0 + 2.0 * s + 30.0 * s * s, -0.5 + 40.0 * s, 0.2 - 10.0 * s * s);
        let t: Vec<f64> = (0..400).map(|k| k as f64 * 0.005).collect();
        let imu = ImuData {
            gyro: t.iter().map(|&s| rate(s - 1.0) + Vector3::new(0.01, 0.0, 0.0)).collect(),
            acc: t.iter().map(|_| Vector3::new(0.1, 0.2, 9.9)).collect(),
            t,
        };
        let bias = Vector6::new(0.1, 0.0, 0.0, 0.01, 0.0, 0.0);
        let m = exposure_motion(&imu, 1.0, &bias, 0.02);
        let want = [[1.0, -0.5, 0.2], [2.0, 40.0, 0.0], [30.0, 0.0, -10.0]];
        for (got, want) in m.rate.iter().zip(want) {
            for (g, w) in got.iter().zip(want) {
                assert!((g - w).abs() < 1e-6 * (1.0 + w.abs()), "{:?}", m.rate);
            }
        }
        assert!((Vector3::from(m.specific_force) - Vector3::new(0.0, 0.2, 9.9)).norm() < 1e-12);
    }

    #[test]
    fn an_estimate_far_outside_the_prior_is_implausible() {
        let input = VioInput::for_tests(ImuData::default(), Vec::new());
        let mut opts = VioOptions::default();
        opts.camera.extrinsics = Estimate::On;
        opts.camera.time_offset = Estimate::On;
        let prior = CameraPrior::new(&input, &opts.camera).unwrap();
        let mut values = Values::new();
        prior.insert(&mut values, None);
        assert!(prior.implausible(&values).is_none());
        // 10° (2 σ) and 5 ms: within the prior.
        let turned = |deg: f64| {
            pose(nalgebra::Rotation3::from_euler_angles(deg.to_radians(), 0.0, 0.0).matrix(), &Vector3::zeros())
        };
        prior.insert(&mut values, Some((input.body_from_camera * turned(10.0), 0.005)));
        prior.free(&mut values, true);
        assert!(prior.implausible(&values).is_none());
        // 50° (10 σ): a wrong minimum — of a free calibration; held, it is the estimator's own choice.
        prior.insert(&mut values, Some((input.body_from_camera * turned(50.0), 0.0)));
        assert!(prior.implausible(&values).is_none());
        prior.free(&mut values, true);
        let why = prior.implausible(&values).expect("implausible");
        assert!(why.contains("50.0°"), "{why}");
    }
}

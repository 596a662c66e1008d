//! The calibration's two fits on the solver: the accelerometer with one
//! gravity-norm factor per static interval (from a closed-form ellipsoid
//! start), the gyroscope with one integrated-rotation factor per pair of
//! consecutive intervals; their covariances turned into the paper's `T`, `K`,
//! `b` with standard deviations.

use super::detect::{mean3, Interval};
use super::floor::{solve_with_floor, FloorFit, MisalignmentPrior};
use super::observability::{undetermined, OffDiagonal, ACCEL_OFF_DIAGONAL, GYRO_OFF_DIAGONAL};
use super::options::CalibOptions;
use super::result::{FitStats, RotationResidual};
use crate::io::{ImuRecording, Stored};
use crate::model::calibration::{split_unit_diagonal, Triad};
use nalgebra::{DMatrix, DVector, Matrix3, Vector3};
use rayon::prelude::*;
use tumble_factors::imu_calib::{
    accel_matrix, gyro_matrix, AccelParams, GravityNormFactor, GyroMatrix, IntegratedRotationFactor, UPPER,
};
use tumble_solvers::{covariances, Factor, Key, LmOptions, Values, Vars};

const KEY_ACCEL: Key = Key::new('a', 0);
const KEY_GYRO: Key = Key::new('g', 0);
const KEY_GYRO_BIAS: Key = Key::new('g', 1);

/// The accelerometer estimate of one detection.
#[derive(Clone)]
pub(super) struct AccelFit {
    pub params: AccelParams,
    /// Covariance (not inflated).
    pub cov: DMatrix<f64>,
    pub stats: FitStats,
    /// Misalignments the poses do not determine (their estimate is mostly the prior's).
    pub not_determined: Vec<OffDiagonal>,
}

/// Mean raw accelerometer sample of each interval.
pub(super) fn interval_means(rec: &ImuRecording, intervals: &[Interval]) -> Vec<Vector3<f64>> {
    intervals.iter().map(|iv| Vector3::from(mean3(&rec.accel[iv.start..iv.end]))).collect()
}

/// ln det of a covariance (∞ when not positive definite).
fn ln_det(cov: &DMatrix<f64>) -> f64 {
    match cov.clone().cholesky() {
        Some(c) => 2.0 * c.l().diagonal().iter().map(|d| d.ln()).sum::<f64>(),
        None => f64::INFINITY,
    }
}

impl AccelFit {
    /// ln det of the inflated covariance (D-optimality; see the threshold sweep in [`super::calibrate`]).
    pub(super) fn uncertainty(&self) -> f64 {
        ln_det(&self.cov) + self.cov.nrows() as f64 * self.stats.covariance_inflation.ln()
    }
}

impl GyroFit {
    /// ln det of the inflated covariance of the gyro matrix.
    pub(super) fn uncertainty(&self) -> f64 {
        ln_det(&self.cov.view((0, 0), (9, 9)).into_owned())
    }
}

/// Axis-aligned ellipsoid through the interval means (linear least squares):
/// the initial bias (centre) and inverse scale (g / semi-axis).
pub(super) fn ellipsoid_guess(means: &[Vector3<f64>], g: f64) -> Option<AccelParams> {
    // Centre the data for conditioning.
    let c0 = means.iter().sum::<Vector3<f64>>() / means.len() as f64;
    let spread = means.iter().map(|m| (m - c0).amax()).fold(0.0, f64::max).max(1e-300);
    let mut a = DMatrix::zeros(means.len(), 6);
    let rhs = DVector::from_element(means.len(), 1.0);
    for (i, m) in means.iter().enumerate() {
        let x = (m - c0) / spread;
        for k in 0..3 {
            a[(i, k)] = x[k] * x[k];
            a[(i, 3 + k)] = x[k];
        }
    }
    let sol = a.svd(true, true).solve(&rhs, 1e-12).ok()?;
    let mut p = AccelParams::zeros();
    let centre: Vector3<f64> = Vector3::from_fn(|k, _| -sol[3 + k] / (2.0 * sol[k]));
    let rhs = 1.0 + (0..3).map(|k| sol[k] * centre[k] * centre[k]).sum::<f64>();
    for k in 0..3 {
        let r2 = rhs / sol[k];
        if !(r2 > 0.0 && r2.is_finite()) {
            return None;
        }
        p[[0, 3, 5][k]] = g / (r2.sqrt() * spread);
        p[6 + k] = c0[k] + centre[k] * spread;
    }
    p.iter().all(|x| x.is_finite()).then_some(p)
}

/// Fallback guess: centre and half-range of each axis's interval means.
pub(super) fn range_guess(means: &[Vector3<f64>], g: f64) -> AccelParams {
    let mut p = AccelParams::zeros();
    for k in 0..3 {
        let lo = means.iter().map(|m| m[k]).fold(f64::MAX, f64::min);
        let hi = means.iter().map(|m| m[k]).fold(f64::MIN, f64::max);
        p[6 + k] = 0.5 * (lo + hi);
        p[[0, 3, 5][k]] = 2.0 * g / (hi - lo).max(1e-300);
    }
    p
}

/// Fit the accelerometer to the static intervals (misalignments with their prior).
pub(super) fn fit_accel(rec: &ImuRecording, intervals: &[Interval], g: f64, var_a: &[f64; 3]) -> Option<AccelFit> {
    let means = interval_means(rec, intervals);
    let x0 = ellipsoid_guess(&means, g).unwrap_or_else(|| range_guess(&means, g));
    let prior = MisalignmentPrior::new(KEY_ACCEL, &x0, &ACCEL_OFF_DIAGONAL);
    let m0 = accel_matrix(&x0);
    let b0 = Vector3::new(x0[6], x0[7], x0[8]);
    let mut factors = Vec::new();
    let mut base = Vec::new();
    for (iv, m) in intervals.iter().zip(&means) {
        // Noise of g² − |a|²: 2g times the noise of |a| along gravity (white noise of the mean).
        let u = (m0 * (m - b0)).normalize();
        let var: f64 = (0..3).map(|k| (u[k] * m0[(k, k)]).powi(2) * var_a[k]).sum::<f64>() / iv.len() as f64;
        base.push(DMatrix::from_element(1, 1, (2.0 * g * var.sqrt()).max(1e-9 * g * g).powi(2)));
        factors.push(GravityNormFactor::new(KEY_ACCEL, *m, g));
    }
    let mut values = Values::new();
    values.insert(KEY_ACCEL, x0);
    let fit = solve_with_floor(&factors, &base, &values, 9, &prior, LmOptions::default().max_iterations, true).ok()?;
    let (sol, graph) = (&fit.values, &fit.graph);
    let params = *sol.get::<AccelParams>(KEY_ACCEL).ok()?;
    let cov = covariances(graph, sol, &[KEY_ACCEL]).ok()?.get(KEY_ACCEL)?;
    let not_determined = undetermined(&params, &(&cov * fit.chi2_final.max(1.0)), &ACCEL_OFF_DIAGONAL);
    let chi2 = fit.chi2_white;
    let ma = accel_matrix(&params);
    let ba = Vector3::new(params[6], params[7], params[8]);
    let rms = (means.iter().map(|m| ((ma * (m - ba)).norm() - g).powi(2)).sum::<f64>() / means.len() as f64).sqrt();
    let imu_tk_cost = 0.5
        * intervals
            .iter()
            .flat_map(|iv| &rec.accel[iv.start..iv.start + iv.len().min(100)])
            .map(|a| (g * g - (ma * (Vector3::from(*a) - ba)).norm_squared()).powi(2))
            .sum::<f64>();
    if !chi2.is_finite() {
        return None;
    }
    Some(AccelFit {
        params,
        cov,
        stats: FitStats {
            residuals: intervals.len(),
            parameters: 9,
            chi2_per_dof: chi2,
            unmodelled_sigma: fit.floor / (2.0 * g),
            covariance_inflation: fit.chi2_final.max(1.0),
            rms,
            imu_tk_cost,
            iterations: fit.iterations,
            converged: !fit.capped,
        },
        not_determined,
    })
}

#[derive(Clone)]
pub(super) struct GyroFit {
    /// `[M_g row major (9), b_g (3)]`.
    pub x: [f64; 12],
    /// Its covariance (12×12, inflated).
    pub cov: DMatrix<f64>,
    pub stats: FitStats,
    pub rotations: Vec<RotationResidual>,
    /// Misalignments the turns do not determine (their estimate is mostly the prior's).
    pub not_determined: Vec<OffDiagonal>,
    /// Another start explained the data nearly as well at another scale:
    /// `(kept scale, other scale, χ² ratio)`.
    pub ambiguity: Option<(f64, f64, f64)>,
    /// The isotropic scales it started from, the kept one's first.
    pub starts: Vec<f64>,
}

impl GyroFit {
    /// `M_g` (as the solver holds it).
    pub fn matrix(&self) -> GyroMatrix {
        GyroMatrix::from_column_slice(&self.x[..9])
    }
}

/// Iterations the other starts of the gyro fit get (the first gets the solver's
/// default): a start that has not converged by then is wandering.
const OTHER_START_ITERATIONS: usize = 20;

/// Another start whose χ² is within this factor of the best one's makes the
/// gyro scale ambiguous.
const AMBIGUOUS_CHI2_RATIO: f64 = 2.0;

/// What the gyro fit takes from the initial rest and the detector.
pub(super) struct GyroInputs<'a> {
    /// Per-axis variance of the initial rest (accelerometer, gyro) \[raw units²\].
    pub var_a: &'a [f64; 3],
    pub var_g: &'a [f64; 3],
    /// The gyro bias (mean of the initial rest) and the samples it was averaged over.
    pub bias: &'a Vector3<f64>,
    pub n_init: usize,
    /// Half the detector's window \[samples\] (see [`turn_span`]).
    pub edge: usize,
}

/// The turns between consecutive static intervals, as integrated-rotation
/// factors, with the gravity directions they carry one into the other.
struct Turns {
    factors: Vec<IntegratedRotationFactor>,
    /// Each factor's intervals `(before, after)`.
    pairs: Vec<(usize, usize)>,
    /// Calibrated gravity direction of every interval (accelerometer fit).
    dirs: Vec<Vector3<f64>>,
}

/// The gravity directions of the intervals' mean raw readings `means` under
/// accelerometer parameters `pa`.
fn directions(means: &[Vector3<f64>], pa: &AccelParams) -> Vec<Vector3<f64>> {
    let (ma, ba) = (accel_matrix(pa), Vector3::new(pa[6], pa[7], pa[8]));
    means.iter().map(|m| ma * (m - ba)).collect()
}

impl Turns {
    fn new(rec: &ImuRecording, intervals: &[Interval], dirs: Vec<Vector3<f64>>, edge: usize) -> Result<Turns, String> {
        let mut factors = Vec::new();
        let mut pairs = Vec::new();
        for k in 1..intervals.len() {
            let (a, b) = turn_span(&intervals[k - 1], &intervals[k], edge);
            let raw = rec.gyro[a..=b].to_vec();
            let dt = rec.t[a..=b].windows(2).map(|w| w[1] - w[0]).collect();
            let f = IntegratedRotationFactor::new([KEY_GYRO, KEY_GYRO_BIAS], raw, dt, dirs[k - 1], dirs[k])
                .map_err(|e| format!("motion between static intervals {} and {k}: {e}", k - 1))?;
            factors.push(f);
            pairs.push((k - 1, k));
        }
        Ok(Turns { factors, pairs, dirs })
    }

    /// Starts: isotropic scales s·I at the local minima of the isotropic cost
    /// on a log grid. Every turn's gravity angle θ ≤ s ∫|ω̃ − b| dt, so the
    /// ratios θ/∫ locate s; the grid spans well beyond them because the cost
    /// is not convex in s: a quarter turn taken as three quarters explains
    /// gravity's direction nearly as well (aliases at 3s, 5s). Ranking a
    /// detection (not `final_fit`) needs one start, found on a coarser grid.
    fn starts(
        &self,
        rec: &ImuRecording,
        intervals: &[Interval],
        b0: &Vector3<f64>,
        edge: usize,
        final_fit: bool,
    ) -> Result<Vec<f64>, String> {
        let dirs = &self.dirs;
        let ratios: Vec<f64> = self
            .pairs
            .iter()
            .filter_map(|&(i, j)| {
                let theta = dirs[i].normalize().dot(&dirs[j].normalize()).clamp(-1.0, 1.0).acos();
                let (a, b) = turn_span(&intervals[i], &intervals[j], edge);
                let len = integrated_raw_angle(rec, a, b, b0);
                (len > 0.0 && theta > 0.2).then_some(theta / len)
            })
            .filter(|r| r.is_finite())
            .collect();
        if ratios.is_empty() {
            return Err("no turn between static intervals rotates gravity by more than 11°: nothing to calibrate the \
                        gyroscope with"
                .into());
        }
        let s_max = ratios.iter().copied().fold(0.0, f64::max);
        let mut sorted = ratios.clone();
        sorted.sort_by(f64::total_cmp);
        let s_med = sorted[sorted.len() / 2];
        // Summed in the turns' order after the parallel map: rayon's own sum
        // groups the terms as its threads happen to split the work, so the
        // last bit of the cost (and through the starts the whole calibration
        // and what is computed from it) would change from run to run.
        let iso_cost = |s: f64| -> f64 {
            let m = Matrix3::identity() * s;
            let terms: Vec<f64> = self
                .factors
                .par_iter()
                .map(|f| {
                    let vars: [&dyn tumble_solvers::DynVariable; 2] = [&gyro_vec(&m), b0];
                    f.residual(Vars::new(&vars)).map(|r| r.norm_squared()).unwrap_or(f64::MAX)
                })
                .collect();
            terms.iter().sum()
        };
        // A gyro that reports rad/s is within a factor of 2 of it; beyond that the units are
        // wrong (deg/s is 57×), which no calibration should paper over.
        let (lo, hi) = if rec.gyro_units == Stored::RawCounts { (0.25 * s_med, 4.0 * s_max) } else { (0.5, 2.0) };
        Ok(if final_fit {
            isotropic_starts(&iso_cost, lo, hi, GYRO_STARTS, 32)
        } else {
            isotropic_starts(&iso_cost, lo, hi, 1, 16)
        })
    }

    /// Noise of each turn: the gyro's white noise integrated over it (per
    /// axis, through the steps' Jacobians, at the start scale `s0`) plus the
    /// two gravity directions' noise.
    fn noise(
        &self,
        intervals: &[Interval],
        ma: &Matrix3<f64>,
        inputs: &GyroInputs,
        s0: f64,
        gravity: f64,
    ) -> Vec<DMatrix<f64>> {
        let m0 = Matrix3::identity() * s0;
        let var_acc: f64 = (0..3).map(|k| ma[(k, k)].powi(2) * inputs.var_a[k]).sum::<f64>() / 3.0;
        let g2 = gravity * gravity;
        let raw_var = Vector3::from(*inputs.var_g);
        self.factors
            .par_iter()
            .zip(&self.pairs)
            .map(|(f, &(i, j))| {
                let dir = var_acc / g2 * (1.0 / intervals[i].len() as f64 + 1.0 / intervals[j].len() as f64);
                let c = f.noise_covariance(&m0, inputs.bias, &raw_var) + nalgebra::Matrix2::identity() * dir.max(1e-24);
                DMatrix::from_column_slice(2, 2, c.as_slice())
            })
            .collect()
    }

    /// Every turn's rotation and the angle between the gravity it carries and
    /// the one measured after it; with the RMS angle and imu_tk's cost.
    fn residuals(&self, m: &Matrix3<f64>, b: &Vector3<f64>) -> (Vec<RotationResidual>, f64, f64) {
        let mut rotations = Vec::new();
        let (mut sq, mut tk) = (0.0, 0.0);
        for (f, &(i, j)) in self.factors.iter().zip(&self.pairs) {
            let r = f.rotation(m, b);
            let (g0, g1) = (self.dirs[i].normalize(), self.dirs[j].normalize());
            let pred = r.transpose() * g0;
            let e = pred.cross(&g1).norm().atan2(pred.dot(&g1));
            sq += e * e;
            tk += 0.5 * (pred - g1).norm_squared();
            let turn = nalgebra::Rotation3::from_matrix_unchecked(r).angle().to_degrees();
            rotations.push(RotationResidual { from: i, to: j, rotation_deg: turn, error_rad: e });
        }
        (rotations, (sq / self.factors.len() as f64).sqrt(), tk)
    }
}

/// One solve per start (the first from `from` when given); the one that
/// explains the data best (lowest χ² with the predicted noise) is kept and
/// finished. The other starts get few
/// iterations: a start that has not converged by then is wandering (an alias
/// start can take 300). Returns the kept fit with its prior, and the
/// ambiguity when another start explains the data nearly as well at a clearly
/// different scale (single-axis turns alias at 1, 5, 9, … × a quarter turn).
type GyroSolve = (MisalignmentPrior, FloorFit, Option<(f64, f64, f64)>);
fn solve_starts(
    turns: &Turns,
    base: &[DMatrix<f64>],
    starts: &[f64],
    from: Option<GyroMatrix>,
    b0: &Vector3<f64>,
    opts: &CalibOptions,
    final_fit: bool,
) -> Result<GyroSolve, String> {
    let n_params = 9 + 3 * opts.estimate_gyro_bias as usize;
    let full = LmOptions::default().max_iterations;
    let mut fits: Vec<(usize, MisalignmentPrior, FloorFit)> = starts
        .par_iter()
        .enumerate()
        .filter_map(|(i, &s)| {
            let start = gyro_vec(&(Matrix3::identity() * s));
            let prior = MisalignmentPrior::new(KEY_GYRO, &start, &GYRO_OFF_DIAGONAL);
            let mut values = Values::new();
            values.insert(KEY_GYRO, if i == 0 { from.unwrap_or(start) } else { start });
            values.insert(KEY_GYRO_BIAS, *b0);
            values.set_constant(KEY_GYRO_BIAS, !opts.estimate_gyro_bias);
            // The other starts are compared on their first solve; the kept one is refined below.
            let (cap, refine) = if i == 0 { (full, final_fit) } else { (OTHER_START_ITERATIONS, false) };
            solve_with_floor(&turns.factors, base, &values, n_params, &prior, cap, refine).ok().map(|f| (i, prior, f))
        })
        .collect();
    fits.sort_by(|a, b| a.2.chi2_white.total_cmp(&b.2.chi2_white));
    if let Some((_, prior, f)) = fits.first_mut().filter(|(i, _, f)| f.capped || (*i != 0 && final_fit)) {
        let more = solve_with_floor(&turns.factors, base, &f.values, n_params, prior, full, true)?;
        f.iterations += more.iterations;
        (f.values, f.graph, f.chi2_final, f.floor, f.capped) =
            (more.values, more.graph, more.chi2_final, more.floor, more.capped);
    }
    let scale_of =
        |f: &FloorFit| f.values.get::<GyroMatrix>(KEY_GYRO).map(|p| gyro_matrix(p).determinant().abs().cbrt());
    let mut ambiguity = None;
    if let (Some((_, _, best)), Some((_, _, other))) = (fits.first(), fits.get(1)) {
        if let (Ok(a), Ok(b)) = (scale_of(best), scale_of(other)) {
            if !other.capped
                && other.chi2_white < AMBIGUOUS_CHI2_RATIO * best.chi2_white
                && (a / b).ln().abs() > 1.5f64.ln()
            {
                ambiguity = Some((a, b, other.chi2_white / best.chi2_white));
            }
        }
    }
    let (_, prior, fit) = fits.into_iter().next().ok_or("gyroscope fit failed from every start")?;
    Ok((prior, fit, ambiguity))
}

/// The free gyro parameters at the fit: `[M_g (9), b_g (3)]`, or `M_g` alone
/// when the bias is the initial rest's mean (held).
fn free_gyro_keys(opts: &CalibOptions) -> Vec<Key> {
    if opts.estimate_gyro_bias {
        vec![KEY_GYRO, KEY_GYRO_BIAS]
    } else {
        vec![KEY_GYRO]
    }
}

/// The inverse of the fit's information matrix over the free gyro parameters
/// ([`free_gyro_keys`]): their covariance before any inflation.
fn information_inverse(fit: &FloorFit, opts: &CalibOptions) -> Result<DMatrix<f64>, String> {
    let keys = free_gyro_keys(opts);
    let cv = covariances(&fit.graph, &fit.values, &keys).map_err(|e| format!("gyroscope covariance: {e}"))?;
    cv.joint(&keys).ok_or_else(|| "gyroscope covariance: no joint block".to_string())
}

/// The fit's covariance of `[M_g (9), b_g (3)]` from the information's
/// inverse `h_inv`, inflated by its χ²/dof; the bias's white-noise standard
/// error when it is the initial rest's mean.
fn gyro_covariance(h_inv: &DMatrix<f64>, fit: &FloorFit, inputs: &GyroInputs) -> DMatrix<f64> {
    let n = h_inv.nrows();
    let mut cov = DMatrix::zeros(12, 12);
    cov.view_mut((0, 0), (n, n)).copy_from(&(h_inv * fit.chi2_final.max(1.0)));
    if n == 9 {
        for k in 0..3 {
            cov[(9 + k, 9 + k)] = inputs.var_g[k] / inputs.n_init as f64;
        }
    }
    cov
}

/// The gravity directions come from the accelerometer fit: its uncertainty
/// carried into the gyro parameters, `J Σ_a Jᵀ` with `J = ∂x_g/∂x_a`, the
/// solution's sensitivity by the implicit function theorem at the fit's
/// Gauss–Newton normal equations: `J = −H⁻¹ Σ_t J_tᵀ W_t D_t`, with each turn
/// `t`'s whitened Jacobian `J_t` in the gyro parameters and `D_t` its
/// residual's derivative in the accelerometer parameters (the turn's rotation
/// held: only the directions move; central differences over ±1σ of each).
/// Its σ are within 0.7 % of those that re-solving at ±1σ of each parameter
/// gives (18 solves; imu_tk's Xsens and T265 recordings, simulated tumbles):
/// what it leaves out is the residuals' curvature, second order in residuals
/// of a few milliradians.
fn accel_uncertainty_in_gyro(
    turns: &Turns,
    base: &[DMatrix<f64>],
    means: &[Vector3<f64>],
    accel: &AccelFit,
    fit: &FloorFit,
    h_inv: &DMatrix<f64>,
) -> Result<DMatrix<f64>, String> {
    let acc_cov = &accel.cov * accel.stats.covariance_inflation;
    let p = *fit.values.get::<GyroMatrix>(KEY_GYRO).map_err(|e| e.to_string())?;
    let b = *fit.values.get::<Vector3<f64>>(KEY_GYRO_BIAS).map_err(|e| e.to_string())?;
    let m = gyro_matrix(&p);
    let n = h_inv.nrows();
    let steps: Vec<f64> = (0..9).map(|k| acc_cov[(k, k)].max(0.0).sqrt()).collect();
    // Each accelerometer parameter moved by ±1σ: the directions of every pose.
    let moved: Vec<[Vec<Vector3<f64>>; 2]> = (0..9)
        .map(|k| {
            let (mut lo, mut hi) = (accel.params, accel.params);
            lo[k] -= steps[k];
            hi[k] += steps[k];
            [directions(means, &lo), directions(means, &hi)]
        })
        .collect();
    let per_turn = |((f, &(i, j)), c): ((&IntegratedRotationFactor, &(usize, usize)), &DMatrix<f64>)| {
        let vars: [&dyn tumble_solvers::DynVariable; 2] = [&p, &b];
        let lin = f.linearize(Vars::new(&vars)).map_err(|e| e.to_string())?;
        let jt =
            DMatrix::from_fn(
                2,
                n,
                |r, col| if col < 9 { lin.jacobians[0][(r, col)] } else { lin.jacobians[1][(r, col - 9)] },
            );
        let w = (c + DMatrix::identity(2, 2) * fit.floor.powi(2)).try_inverse().ok_or("singular turn noise")?;
        let r = f.rotation(&m, &b);
        // Each column once: both residuals of a parameter's ±1σ move, differenced.
        let mut d = DMatrix::zeros(2, 9);
        for (k, [lo, hi]) in moved.iter().enumerate().filter(|(k, _)| steps[*k] > 0.0) {
            let e_lo = IntegratedRotationFactor::residual_between(&r, &lo[i], &lo[j]);
            let e_hi = IntegratedRotationFactor::residual_between(&r, &hi[i], &hi[j]);
            d.set_column(k, &((e_hi - e_lo) / (2.0 * steps[k])));
        }
        Ok::<DMatrix<f64>, String>(jt.transpose() * w * d)
    };
    // Summed in the turns' order (as the cost in `Turns::starts`): a parallel
    // reduce would group the terms differently from run to run.
    let terms: Vec<DMatrix<f64>> =
        turns.factors.par_iter().zip(&turns.pairs).zip(base).map(per_turn).collect::<Result<_, _>>()?;
    let g = terms.iter().fold(DMatrix::zeros(n, 9), |a, t| a + t);
    let mut j = DMatrix::zeros(12, 9);
    j.view_mut((0, 0), (n, 9)).copy_from(&-(h_inv * g));
    Ok(&j * acc_cov * j.transpose())
}

/// The isotropic scale a detection's gyro fit starts from when it only
/// ranks the detection (see [`Turns::starts`]).
pub(super) fn ranking_start(
    rec: &ImuRecording,
    intervals: &[Interval],
    accel: &AccelFit,
    inputs: &GyroInputs,
) -> Result<f64, String> {
    let means = interval_means(rec, intervals);
    let turns = Turns::new(rec, intervals, directions(&means, &accel.params), inputs.edge)?;
    Ok(turns.starts(rec, intervals, inputs.bias, inputs.edge, false)?[0])
}

/// Where a gyro fit starts.
#[derive(Clone, Copy)]
pub(super) enum GyroStart {
    /// At the isotropic scales its own turns' cost shows (several; one when
    /// only ranking a detection).
    Search,
    /// At the isotropic scale `scale`·I, which also sets the turns' noise and
    /// the misalignment prior; solved from `from` when given — a nearby
    /// detection's or the whole recording's solution: the same problem,
    /// reached in fewer iterations.
    Scale { scale: f64, from: Option<GyroMatrix> },
}

/// Fit the gyroscope to the turns between the static intervals `intervals`
/// (mean raw readings `means`, gravity directions from `accel`) from
/// `start`, then its covariance, with the accelerometer's uncertainty
/// carried in on the `final_fit`.
#[allow(clippy::too_many_arguments)]
pub(super) fn fit_gyro(
    rec: &ImuRecording,
    intervals: &[Interval],
    means: &[Vector3<f64>],
    accel: &AccelFit,
    inputs: &GyroInputs,
    opts: &CalibOptions,
    final_fit: bool,
    start: GyroStart,
) -> Result<GyroFit, String> {
    let turns = Turns::new(rec, intervals, directions(means, &accel.params), inputs.edge)?;
    let (starts, from) = match start {
        GyroStart::Scale { scale, from } => (vec![scale], from),
        GyroStart::Search => (turns.starts(rec, intervals, inputs.bias, inputs.edge, final_fit)?, None),
    };
    let base = turns.noise(intervals, &accel_matrix(&accel.params), inputs, starts[0], opts.gravity);
    let (_, fit, ambiguity) = solve_starts(&turns, &base, &starts, from, inputs.bias, opts, final_fit)?;
    let p = *fit.values.get::<GyroMatrix>(KEY_GYRO).map_err(|e| e.to_string())?;
    let b = *fit.values.get::<Vector3<f64>>(KEY_GYRO_BIAS).map_err(|e| e.to_string())?;
    let h_inv = information_inverse(&fit, opts)?;
    let mut cov = gyro_covariance(&h_inv, &fit, inputs);
    if final_fit {
        cov += accel_uncertainty_in_gyro(&turns, &base, means, accel, &fit, &h_inv)?;
    }
    let not_determined = undetermined(&p, &cov, &GYRO_OFF_DIAGONAL);
    let (rotations, rms, imu_tk_cost) = turns.residuals(&gyro_matrix(&p), &b);
    let mut x = [0.0; 12];
    x[..9].copy_from_slice(p.as_slice());
    x[9..].copy_from_slice(b.as_slice());
    Ok(GyroFit {
        x,
        cov,
        starts,
        stats: FitStats {
            residuals: 2 * turns.factors.len(),
            parameters: 9 + 3 * opts.estimate_gyro_bias as usize,
            chi2_per_dof: fit.chi2_white,
            unmodelled_sigma: fit.floor,
            covariance_inflation: fit.chi2_final.max(1.0),
            rms,
            imu_tk_cost,
            iterations: fit.iterations,
            converged: !fit.capped,
        },
        rotations,
        not_determined,
        ambiguity,
    })
}

/// Starts of the gyro fit (see [`isotropic_starts`]).
const GYRO_STARTS: usize = 3;

/// Up to `count` isotropic scales in `[lo, hi]` at the deepest local minima of
/// `cost` on a log grid of `points`, each refined by 12 golden-section steps
/// between its grid neighbours (to 0.3 % of that bracket; the solver does the
/// rest); the lowest cost first.
pub(super) fn isotropic_starts(
    cost: &(dyn Fn(f64) -> f64 + Sync),
    lo: f64,
    hi: f64,
    count: usize,
    points: usize,
) -> Vec<f64> {
    let n_grid = points.max(3);
    let (l0, l1) = (lo.ln(), hi.max(lo * 1.01).ln());
    let grid: Vec<f64> = (0..n_grid).map(|i| l0 + (l1 - l0) * i as f64 / (n_grid - 1) as f64).collect();
    let values: Vec<f64> = grid.par_iter().map(|x| cost(x.exp())).collect();
    let local: Vec<usize> = (0..n_grid)
        .filter(|&i| (i == 0 || values[i] <= values[i - 1]) && (i == n_grid - 1 || values[i] <= values[i + 1]))
        .collect();
    let mut minima: Vec<(f64, f64)> = local
        .into_par_iter()
        .map(|i| {
            let (mut a, mut b) = (grid[i.saturating_sub(1)], grid[(i + 1).min(n_grid - 1)]);
            let phi = 0.5 * (5f64.sqrt() - 1.0);
            let (mut x1, mut x2) = (b - phi * (b - a), a + phi * (b - a));
            let (mut f1, mut f2) = (cost(x1.exp()), cost(x2.exp()));
            for _ in 0..12 {
                if f1 < f2 {
                    (b, x2, f2) = (x2, x1, f1);
                    x1 = b - phi * (b - a);
                    f1 = cost(x1.exp());
                } else {
                    (a, x1, f1) = (x1, x2, f2);
                    x2 = a + phi * (b - a);
                    f2 = cost(x2.exp());
                }
            }
            let x = 0.5 * (a + b);
            (x.exp(), cost(x.exp()))
        })
        .collect();
    minima.sort_by(|a, b| a.1.total_cmp(&b.1));
    minima.into_iter().take(count.max(1)).map(|(s, _)| s).collect()
}

/// The samples a turn between two poses is integrated over: from `edge`
/// samples before the end of the first to `edge` after the start of the next
/// (at most to their middles). The detector's window is `2·edge + 1` samples
/// wide, so the slow start and end of a turn can hide that far inside a
/// detected pose; left out, they bias the gyro scales low.
fn turn_span(before: &Interval, after: &Interval, edge: usize) -> (usize, usize) {
    let a = (before.end - 1).saturating_sub(edge).max(before.start + before.len() / 2);
    let b = (after.start + edge).min(after.start + after.len() / 2);
    (a, b)
}

/// `Σ |ū_i − b| Δt_i` over samples `a..=b` (raw units · s).
pub(super) fn integrated_raw_angle(rec: &ImuRecording, a: usize, b: usize, bias: &Vector3<f64>) -> f64 {
    (a..b)
        .map(|i| {
            let u = (Vector3::from(rec.gyro[i]) + Vector3::from(rec.gyro[i + 1])) * 0.5 - bias;
            u.norm() * (rec.t[i + 1] - rec.t[i])
        })
        .sum()
}

pub(super) fn gyro_vec(m: &Matrix3<f64>) -> GyroMatrix {
    GyroMatrix::from_row_slice(&[
        m[(0, 0)],
        m[(0, 1)],
        m[(0, 2)],
        m[(1, 0)],
        m[(1, 1)],
        m[(1, 2)],
        m[(2, 0)],
        m[(2, 1)],
        m[(2, 2)],
    ])
}

/// Standard deviations of `f(x)` from `cov(x)` by a central-difference Jacobian.
pub(super) fn propagate_std(f: &dyn Fn(&[f64]) -> Vec<f64>, x: &[f64], cov: &DMatrix<f64>) -> Vec<f64> {
    let y0 = f(x);
    let mut j = DMatrix::zeros(y0.len(), x.len());
    for c in 0..x.len() {
        let h = 1e-6 * x[c].abs().max(1e-6);
        let mut xp = x.to_vec();
        let mut xm = x.to_vec();
        xp[c] += h;
        xm[c] -= h;
        let (yp, ym) = (f(&xp), f(&xm));
        for r in 0..y0.len() {
            j[(r, c)] = (yp[r] - ym[r]) / (2.0 * h);
        }
    }
    let c = &j * cov * j.transpose();
    (0..y0.len()).map(|i| c[(i, i)].max(0.0).sqrt()).collect()
}

/// `(T, K)` of the paper from the inverse model matrix `M = (T K)⁻¹`, as
/// `[T row major (9), K (3)]` (NaN when singular).
pub(super) fn paper_tk(m: &Matrix3<f64>) -> Vec<f64> {
    let Some((t, k)) = m.try_inverse().and_then(|n| split_unit_diagonal(&n)) else {
        return vec![f64::NAN; 12];
    };
    let mut v: Vec<f64> = (0..9).map(|i| t[(i / 3, i % 3)]).collect();
    v.extend(k.iter());
    v
}

pub(super) fn triad_from(y: &[f64], s: &[f64], b: Vector3<f64>, b_std: Vector3<f64>) -> Triad {
    Triad {
        t: Matrix3::from_row_slice(&y[..9]),
        k: Vector3::new(y[9], y[10], y[11]),
        b,
        t_std: Matrix3::from_row_slice(&s[..9]),
        k_std: Vector3::new(s[9], s[10], s[11]),
        b_std,
    }
}

pub(crate) fn accel_triad(p: &AccelParams, cov: &DMatrix<f64>, inflation: f64) -> Triad {
    let f = |x: &[f64]| {
        let mut m = Matrix3::zeros();
        for (k, &(r, c)) in UPPER.iter().enumerate() {
            m[(r, c)] = x[k];
        }
        paper_tk(&m)
    };
    let cov = cov * inflation;
    let y = f(p.as_slice());
    let s = propagate_std(&f, &p.as_slice()[..6], &cov.view((0, 0), (6, 6)).into_owned());
    let b_std = Vector3::from_fn(|k, _| (cov[(6 + k, 6 + k)]).max(0.0).sqrt());
    triad_from(&y, &s, Vector3::new(p[6], p[7], p[8]), b_std)
}

pub(crate) fn gyro_triad(x: &[f64; 12], cov: &DMatrix<f64>) -> Triad {
    let f = |x: &[f64]| paper_tk(&Matrix3::from_row_slice(&x[..9]));
    let y = f(x);
    let s = propagate_std(&f, &x[..9], &cov.view((0, 0), (9, 9)).into_owned());
    let b_std = Vector3::from_fn(|k, _| cov[(9 + k, 9 + k)].max(0.0).sqrt());
    triad_from(&y, &s, Vector3::new(x[9], x[10], x[11]), b_std)
}

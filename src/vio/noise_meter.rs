//! The IMU's white noise as the window's own residuals show it in motion
//! (variance component estimation, Helmert/Förstner).
//!
//! A real IMU in flight is noisier than its datasheet or its Allan figures
//! at rest: rotors and motors shake it (EuRoC's ADIS16448 reads 6× its
//! accelerometer density on a vibrating ground and more in flight). With the
//! datasheet figures the estimator trusts every IMU link too much; its biases
//! then absorb what the noise does not explain and their σ are several times
//! too small. The meter measures the noise where it matters — in the IMU
//! links' residuals at the estimate — instead of inflating it by hand.
//!
//! For each link that leaves the window (solved with everything the window
//! knew), with its residual `r`, Jacobian `J`, preintegration covariance `C`
//! and the joint covariance `Σ` of its states from the solve:
//! - whiten with `L⁻¹` (`C = L Lᵀ`, lower): the first three rows are the
//!   rotation (gyro) alone, the last six the velocity and position given the
//!   rotation (the accelerometer);
//! - each group's χ² is `‖e_g‖²` and its redundancy `r_g = n_g − tr(H_gg)`
//!   with `H = L⁻¹ J Σ Jᵀ L⁻ᵀ` (the share of the group's rows the estimate
//!   did not use up). At the right noise `E[χ²_g] = r_g`; a link integrated
//!   with the densities scaled by `s` measures `s²·χ²_g/r_g` as the squared
//!   scale of the given figures.
//!
//! The scale is pooled over the links of the last [`MEMORY_S`] (weighted by
//! redundancy; older ones too while the recent ones hold fewer than
//! [`MIN_REDUNDANCY`] degrees of freedom) once they hold that many, and
//! used for the links integrated from then on when it exceeds 1 by more than
//! [`SIGNIFICANCE_SIGMAS`] standard errors — never below 1: the given
//! figures are the sensor's floor.

use nalgebra::{DMatrix, DVector};
use std::collections::VecDeque;
use tumble_factors::imu_preint::PreintegrationParams;

/// Memory of the pooled scale \[s\]: links older than this (by the time they
/// left the window) no longer count, so the figure follows a change of
/// vibration (a take-off, a landing) within a few seconds of flight.
pub const MEMORY_S: f64 = 10.0;

/// Degrees of freedom (summed redundancy) the pooled scale needs before it
/// is used: the relative standard error of the squared scale is then `√(2/10)` = 45 %, of the scale 22 %.
pub const MIN_REDUNDANCY: f64 = 10.0;

/// Standard errors by which the pooled squared scale must exceed 1 before
/// the noise is raised: below, the excess is within what the estimate of
/// the scale itself scatters by (and within the 1.2–1.5× the window's own
/// approximations — its marginalization prior — show on simulated data whose
/// noise is exactly known).
pub const SIGNIFICANCE_SIGMAS: f64 = 3.0;

/// One link's measurement.
#[derive(Debug, Clone, Copy)]
struct LinkMeasure {
    /// When it left the window \[s\].
    t: f64,
    /// `s²·χ²` and redundancy of the gyro (rotation) rows.
    gyro: (f64, f64),
    /// The same for the accelerometer (velocity and position) rows.
    accel: (f64, f64),
}

/// The white-noise scale the window's residuals show, and what is in use.
#[derive(Debug, Clone)]
pub(crate) struct NoiseMeter {
    /// The figures given (after a static start's raise, when asked for).
    given: PreintegrationParams,
    links: VecDeque<LinkMeasure>,
    /// The scales `[gyro, accel]` of the given densities in use now.
    in_use: [f64; 2],
    /// The largest scales measured so far.
    largest: [f64; 2],
    /// The last pooled measurement, when there was enough redundancy.
    measured: Option<[f64; 2]>,
}

impl NoiseMeter {
    /// A meter over the given figures `given`.
    pub fn new(given: PreintegrationParams) -> Self {
        NoiseMeter { given, links: VecDeque::new(), in_use: [1.0, 1.0], largest: [0.0, 0.0], measured: None }
    }

    /// A meter over the given figures `given` for a new start after
    /// `previous` (a withdrawn start's meter): it begins with the scales the
    /// previous one had in use and keeps what it measured, without its links
    /// (integrated from the estimate that was withdrawn).
    ///
    /// The given figures stay the run's: a meter built on the previous one's
    /// figures in use would scale them again at every new start (a simulated
    /// walk started again 30 times ended with its given gyro noise 20× the
    /// model's).
    pub fn continuing(given: PreintegrationParams, previous: &NoiseMeter) -> Self {
        NoiseMeter {
            in_use: previous.in_use,
            largest: previous.largest,
            measured: previous.measured,
            ..Self::new(given)
        }
    }

    /// The given figures.
    pub fn given(&self) -> &PreintegrationParams {
        &self.given
    }

    /// The figures in use: the given ones, white densities scaled.
    pub fn params(&self) -> PreintegrationParams {
        scaled(&self.given, self.in_use)
    }

    /// Measure a link leaving the window at time `t`, at the window's
    /// estimate: its raw residual `r` (9, `[θ, p, v]`), Jacobian `j` (9 × n)
    /// over its states, their joint covariance `sigma` (n × n), its
    /// preintegration covariance `c` (9 × 9, as the factor weighed it) and the
    /// scales its densities were integrated with. [`NoiseMeter::update`] then
    /// pools the measurements.
    pub fn measure(
        &mut self,
        t: f64,
        r: &DVector<f64>,
        j: &DMatrix<f64>,
        sigma: &DMatrix<f64>,
        c: &DMatrix<f64>,
        [sg, sa]: [f64; 2],
    ) {
        let Some(m) = link_measure(r, j, sigma, c) else { return };
        self.links.push_back(LinkMeasure { t, gyro: (m.0 .0 * sg * sg, m.0 .1), accel: (m.1 .0 * sa * sa, m.1 .1) });
    }

    /// Pool the links measured over the memory up to time `t` and choose the
    /// scale in use; returns whether it changed.
    pub fn update(&mut self, t: f64) -> bool {
        // Forget links past the memory while the rest still hold enough redundancy.
        while self.links.front().is_some_and(|l| l.t < t - MEMORY_S) {
            let left = |f: fn(&LinkMeasure) -> f64| self.links.iter().skip(1).map(f).sum::<f64>() >= MIN_REDUNDANCY;
            if !(left(|l| l.gyro.1) && left(|l| l.accel.1)) {
                break;
            }
            self.links.pop_front();
        }
        // The pooled scale and whether it exceeds the given figures beyond
        // its own uncertainty (χ²/r has the standard error √(2/r) at scale 1).
        let pool = |f: fn(&LinkMeasure) -> (f64, f64)| -> Option<(f64, bool)> {
            let (chi2, red) = self.links.iter().map(f).fold((0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1));
            (red >= MIN_REDUNDANCY).then(|| {
                let s2 = chi2 / red;
                (s2.sqrt(), s2 > 1.0 + SIGNIFICANCE_SIGMAS * (2.0 / red).sqrt())
            })
        };
        let (Some(g), Some(a)) = (pool(|l| l.gyro), pool(|l| l.accel)) else { return false };
        self.measured = Some([g.0, a.0]);
        self.largest = [self.largest[0].max(g.0), self.largest[1].max(a.0)];
        let before = self.in_use;
        let used = |(s, significant): (f64, bool)| if significant { s } else { 1.0 };
        self.in_use = [used(g), used(a)];
        before != self.in_use
    }
}

/// The IMU white-noise densities of a run: given, measured, in use
/// (`[gyro rad/s/√Hz, accel m/s²/√Hz]`, the largest axis' when per axis).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct NoiseReport {
    /// The figures given (`--noise`, the dataset's or the defaults).
    pub given: [f64; 2],
    /// What the static start measured from the samples' spread, if it started at rest.
    pub at_rest: Option<[f64; 2]>,
    /// What the last links' residuals showed in motion (over [`MEMORY_S`]).
    pub in_motion: Option<[f64; 2]>,
    /// The largest in-motion figures of the run.
    pub in_motion_largest: Option<[f64; 2]>,
    /// The densities in use at the end (the given ones where the measured are smaller).
    pub in_use: [f64; 2],
}

impl NoiseReport {
    /// One line for a terminal: `noise … given …, at rest …, in motion …, in use …`.
    pub fn line(&self) -> String {
        let f = |d: [f64; 2]| format!("{:.2e} rad/s/√Hz, {:.2e} m/s²/√Hz", d[0], d[1]);
        let mut s = format!("IMU white noise: given {}", f(self.given));
        if let Some(r) = self.at_rest {
            s += &format!("; at rest {}", f(r));
        }
        match (self.in_motion, self.in_motion_largest) {
            (Some(m), Some(l)) => s += &format!("; in motion (window residuals) {} (largest {})", f(m), f(l)),
            _ => s += "; in motion: not measured (too few links left the window)",
        }
        s + &format!("; in use at the end {}", f(self.in_use))
    }
}

impl NoiseMeter {
    /// The report of this meter, with the static start's measurement `at_rest`.
    pub fn report(&self, at_rest: Option<[f64; 2]>) -> NoiseReport {
        let d = |p: &PreintegrationParams| [p.gyro_noise().amax(), p.accel_noise().amax()];
        let given = d(&self.given);
        let abs = |s: [f64; 2]| [given[0] * s[0], given[1] * s[1]];
        NoiseReport {
            given,
            at_rest,
            in_motion: self.measured.map(abs),
            in_motion_largest: self.measured.map(|_| abs(self.largest)),
            in_use: abs(self.in_use),
        }
    }
}

/// `p` with its white densities scaled by `[gyro, accel]` (random walks kept).
pub fn scaled(p: &PreintegrationParams, [sg, sa]: [f64; 2]) -> PreintegrationParams {
    let mut q = *p;
    q.gyro_noise_density *= sg;
    q.accel_noise_density *= sa;
    if let Some(axes) = q.axes.as_mut() {
        axes.gyro_noise_density.iter_mut().for_each(|d| *d *= sg);
        axes.accel_noise_density.iter_mut().for_each(|d| *d *= sa);
    }
    q
}

/// `((χ², redundancy) of the rotation rows, (χ², redundancy) of the rest)`
/// of one link; None when a matrix is not positive definite or sizes disagree.
#[allow(clippy::type_complexity)]
fn link_measure(
    r: &DVector<f64>,
    j: &DMatrix<f64>,
    sigma: &DMatrix<f64>,
    c: &DMatrix<f64>,
) -> Option<((f64, f64), (f64, f64))> {
    let n = r.len();
    if n != 9 || j.nrows() != n || c.shape() != (n, n) || sigma.shape() != (j.ncols(), j.ncols()) {
        return None;
    }
    let l = nalgebra::Cholesky::new(c.clone())?.l();
    let e = l.solve_lower_triangular(r)?;
    let je = l.solve_lower_triangular(j)?;
    let h = &je * sigma * je.transpose();
    let group = |a: usize, b: usize| -> (f64, f64) {
        let chi2: f64 = (a..b).map(|i| e[i] * e[i]).sum();
        let used: f64 = (a..b).map(|i| h[(i, i)]).sum();
        (chi2, ((b - a) as f64 - used).max(0.0))
    };
    let out = (group(0, 3), group(3, 9));
    [out.0 .0, out.0 .1, out.1 .0, out.1 .1].iter().all(|x| x.is_finite()).then_some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A direct measurement of a 9-vector (J = I) with prior covariance
    /// `sigma`: the estimate uses `tr(Σ C⁻¹)`-worth of the rows.
    #[test]
    fn redundancy_of_a_direct_measurement_is_what_the_prior_leaves() {
        let c = DMatrix::identity(9, 9) * 4.0;
        // Posterior of x with measurement noise C = 4 I and a prior 4 I: Σ = 2 I.
        let sigma = DMatrix::identity(9, 9) * 2.0;
        let r = DVector::from_element(9, 2.0);
        let ((chi_g, red_g), (chi_a, red_a)) = link_measure(&r, &DMatrix::identity(9, 9), &sigma, &c).unwrap();
        assert!((red_g - 1.5).abs() < 1e-12 && (red_a - 3.0).abs() < 1e-12);
        assert!((chi_g - 3.0).abs() < 1e-12 && (chi_a - 6.0).abs() < 1e-12);
    }

    /// Simulated links: residuals drawn with the true covariance `k² C`
    /// projected as an estimate would leave them; the pooled scale finds `k`.
    #[test]
    fn the_pooled_scale_finds_the_true_noise() {
        use rand::SeedableRng;
        let mut rng = rand::rngs::StdRng::seed_from_u64(3);
        let mut meter = NoiseMeter::new(PreintegrationParams::default());
        let c: DMatrix<f64> =
            DMatrix::from_diagonal(&DVector::from_vec(vec![1e-6, 1e-6, 1e-6, 1e-4, 1e-4, 1e-4, 4e-4, 4e-4, 4e-4]));
        let (kg, ka) = (3.0, 5.0);
        // No estimate uses the rows (Σ = 0): the redundancy is the row count.
        let sigma = DMatrix::zeros(9, 9);
        let j = DMatrix::identity(9, 9);
        for i in 0..200 {
            let r = DVector::from_fn(9, |row, _| {
                let k = if row < 3 { kg } else { ka };
                let z: f64 = rand_distr::Distribution::sample(&rand_distr::StandardNormal, &mut rng);
                k * c[(row, row)].sqrt() * z
            });
            meter.measure(i as f64 * 0.1, &r, &j, &sigma, &c, [1.0, 1.0]);
            meter.update(i as f64 * 0.1);
        }
        let [g, a] = meter.measured.unwrap();
        assert!((g / kg - 1.0).abs() < 0.15 && (a / ka - 1.0).abs() < 0.1, "{g} {a}");
        assert_eq!(meter.in_use, [g, a]);
        // Links already integrated with the scale in use measure the same scale.
        let p = meter.params();
        assert!((p.gyro_noise_density / PreintegrationParams::default().gyro_noise_density - g).abs() < 1e-12);
    }

    #[test]
    fn the_scale_in_use_never_goes_below_the_given_figures() {
        let mut meter = NoiseMeter::new(PreintegrationParams::default());
        let c = DMatrix::identity(9, 9);
        for i in 0..20 {
            let r = DVector::from_element(9, 0.1);
            meter.measure(i as f64, &r, &DMatrix::identity(9, 9), &DMatrix::zeros(9, 9), &c, [1.0; 2]);
            meter.update(i as f64);
        }
        let [g, a] = meter.measured.unwrap();
        assert!(g < 0.2 && a < 0.2);
        assert_eq!(meter.in_use, [1.0, 1.0]);
    }
}

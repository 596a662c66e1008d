//! `auto` online calibration ([`super::Estimate::Auto`]): which directions of
//! a parameter the recording determines, and a prior that holds the others.
//!
//! A parameter `x` with prior σ `D` (diagonal) is looked at in the prior's
//! whitened coordinates `D⁻¹ x`, where the prior's information is the
//! identity. The window's data add information `A − I` there; a direction is
//! *determined* when the data carry at least 3× the prior's information along
//! it — its posterior σ below
//! [`DETERMINED_FRACTION`](crate::model::DETERMINED_FRACTION)
//! (½) of the prior's, the rule of the IMU calibration's misalignments —, an
//! eigenvalue of `A` of at least `1/½² = 4`. The other directions are *held*:
//! their prior information is raised [`HOLD_INFORMATION`]-fold, so they stay
//! at the given value (σ a thousandth of the prior's) while the determined
//! ones are estimated. A direction once determined is never held again (the
//! information the window has gathered only grows through its
//! marginalization prior, and holding it later would pull it back).

use crate::model::DETERMINED_FRACTION;
use nalgebra::DMatrix;

/// How much more information than the prior's holds an undetermined
/// direction at the given value (σ: a thousandth of the prior's).
pub(crate) const HOLD_INFORMATION: f64 = 1e6;

/// The directions of one parameter not (yet) determined, in the prior's
/// whitened coordinates, and when the rest were.
#[derive(Debug, Clone)]
pub(crate) struct HeldDirections {
    /// Orthonormal columns spanning the held directions (all of them before
    /// the first probe).
    pub held: DMatrix<f64>,
    /// The posterior σ along each held direction as a fraction of the
    /// prior's, at the last probe (NaN before one).
    pub fractions: Vec<f64>,
    /// When the first direction was determined \[s\] (the parameter is free from then on).
    pub freed_at: Option<f64>,
    /// When the last direction was determined \[s\].
    pub determined_at: Option<f64>,
}

impl HeldDirections {
    /// Every one of `dim` directions held.
    pub fn all(dim: usize) -> HeldDirections {
        HeldDirections {
            held: DMatrix::identity(dim, dim),
            fractions: vec![f64::NAN; dim],
            freed_at: None,
            determined_at: None,
        }
    }

    /// Whether some direction is determined (the parameter is then free,
    /// with the held ones under [`HeldDirections::prior_information`]).
    pub fn freed(&self) -> bool {
        self.held.ncols() < self.held.nrows()
    }

    /// The prior's information in whitened coordinates: the identity, raised
    /// [`HOLD_INFORMATION`]-fold along the held directions once the parameter
    /// is free (while nothing is determined the parameter is held constant
    /// and the prior is the plain one).
    pub fn prior_information(&self) -> DMatrix<f64> {
        let n = self.held.nrows();
        let mut info = DMatrix::identity(n, n);
        if self.freed() {
            info += &self.held * self.held.transpose() * (HOLD_INFORMATION - 1.0);
        }
        info
    }

    /// Update from the parameter's marginal covariance `cov` in the window
    /// with its plain prior, whitened by the prior's σ, at time `t` \[s\]: the
    /// held directions along which it gives a σ below half the prior's are
    /// released. None when `cov` cannot be inverted.
    pub fn update(&mut self, t: f64, cov: &DMatrix<f64>) -> Option<()> {
        if self.held.ncols() == 0 {
            return Some(());
        }
        // The information of the data and the plain prior, within the held span.
        let info = cov.clone().try_inverse()?;
        let within = self.held.transpose() * info * &self.held;
        let within = (&within + within.transpose()) * 0.5;
        let eig = within.symmetric_eigen();
        let least = 1.0 / (DETERMINED_FRACTION * DETERMINED_FRACTION);
        let keep: Vec<usize> = (0..eig.eigenvalues.len()).filter(|&i| eig.eigenvalues[i] < least).collect();
        let was_free = self.freed();
        let held =
            DMatrix::from_fn(self.held.nrows(), keep.len(), |r, c| (&self.held * eig.eigenvectors.column(keep[c]))[r]);
        self.fractions = keep.iter().map(|&i| 1.0 / eig.eigenvalues[i].max(1e-300).sqrt()).collect();
        self.held = held;
        if self.freed() && !was_free {
            self.freed_at = Some(t);
        }
        if self.held.ncols() == 0 {
            self.determined_at = Some(t);
        }
        Some(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The covariance the data of information `data` (whitened) give with the plain prior.
    fn posterior(_: &HeldDirections, data: &DMatrix<f64>) -> DMatrix<f64> {
        (data + DMatrix::identity(data.nrows(), data.ncols())).try_inverse().unwrap()
    }

    #[test]
    fn only_the_directions_with_three_times_the_prior_information_are_released() {
        let mut h = HeldDirections::all(3);
        assert!(!h.freed());
        // Data: 10× the prior along x, 2× along a diagonal of y and z, nothing along the other.
        let d = nalgebra::Vector3::new(0.0, 1.0, 1.0).normalize();
        let data = DMatrix::from_diagonal(&nalgebra::DVector::from_vec(vec![10.0, 0.0, 0.0]))
            + DMatrix::from_column_slice(3, 1, d.as_slice()) * DMatrix::from_row_slice(1, 3, d.as_slice()) * 2.0;
        h.update(1.0, &posterior(&h, &data)).unwrap();
        assert!(h.freed() && h.freed_at == Some(1.0) && h.determined_at.is_none());
        assert_eq!(h.held.ncols(), 2);
        // x is free: no held direction has an x component.
        assert!(h.held.row(0).norm() < 1e-9, "{}", h.held);
        let mut f = h.fractions.clone();
        f.sort_by(f64::total_cmp);
        assert!((f[0] - 1.0 / 3f64.sqrt()).abs() < 1e-6 && (f[1] - 1.0).abs() < 1e-6, "{f:?}");
        // The prior now holds the two (they span y and z); the same data release nothing more.
        let info = h.prior_information();
        assert!((info[(1, 1)] - HOLD_INFORMATION).abs() < 1e-3 && (info[(0, 0)] - 1.0).abs() < 1e-9, "{info}");
        h.update(2.0, &posterior(&h, &data)).unwrap();
        assert_eq!(h.held.ncols(), 2);
        // More data along the diagonal releases it, and only it.
        let more = &data + DMatrix::from_column_slice(3, 1, d.as_slice()) * DMatrix::from_row_slice(1, 3, d.as_slice());
        h.update(3.0, &posterior(&h, &more)).unwrap();
        assert_eq!(h.held.ncols(), 1);
        let other = nalgebra::Vector3::new(0.0, 1.0, -1.0).normalize();
        assert!((h.held.column(0).dot(&other).abs() - 1.0).abs() < 1e-9, "{}", h.held);
        assert_eq!(h.freed_at, Some(1.0));
        // Everything determined.
        let all = &more + DMatrix::identity(3, 3) * 5.0;
        h.update(4.0, &posterior(&h, &all)).unwrap();
        assert!(h.held.ncols() == 0 && h.determined_at == Some(4.0));
    }

    #[test]
    fn a_direction_released_is_not_held_again() {
        let mut h = HeldDirections::all(1);
        h.update(1.0, &posterior(&h, &DMatrix::from_element(1, 1, 5.0))).unwrap();
        assert!(h.freed() && h.determined_at == Some(1.0));
        h.update(2.0, &posterior(&h, &DMatrix::from_element(1, 1, 0.1))).unwrap();
        assert!(h.freed() && h.held.ncols() == 0);
    }
}

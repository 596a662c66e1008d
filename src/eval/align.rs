//! Aligning an estimated trajectory onto the ground truth: the closed-form
//! least-squares similarity (Umeyama 1991) in the SE(3), Sim(3) and
//! position+yaw (4-DOF, the unobservable directions of visual-inertial
//! odometry) flavours.

use super::EvalError;
use nalgebra::{Matrix3, Rotation3, Vector3};
use serde::{Deserialize, Serialize};

/// Which transformation the estimate may be moved by before errors are measured.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum Alignment {
    /// Rotation and translation (6 DOF).
    Se3,
    /// Rotation, translation and scale (7 DOF; monocular vision without IMU).
    Sim3,
    /// Translation and a rotation about gravity (4 DOF; visual-inertial odometry).
    #[default]
    PosYaw,
    /// No alignment: the estimate is compared as it is.
    None,
}

impl Alignment {
    /// The name used on the command line and in `metrics.json`.
    pub fn name(self) -> &'static str {
        match self {
            Alignment::Se3 => "se3",
            Alignment::Sim3 => "sim3",
            Alignment::PosYaw => "posyaw",
            Alignment::None => "none",
        }
    }
    /// Parse `se3`, `sim3`, `posyaw` or `none`.
    pub fn parse(s: &str) -> Result<Alignment, super::EvalError> {
        s.parse()
    }
}

impl std::str::FromStr for Alignment {
    type Err = super::EvalError;
    /// `se3`, `sim3`, `posyaw` (or `pos-yaw`, `4dof`) or `none`, any case.
    fn from_str(s: &str) -> Result<Alignment, super::EvalError> {
        match s.to_ascii_lowercase().as_str() {
            "se3" => Ok(Alignment::Se3),
            "sim3" => Ok(Alignment::Sim3),
            "posyaw" | "pos-yaw" | "4dof" => Ok(Alignment::PosYaw),
            "none" => Ok(Alignment::None),
            _ => Err(super::EvalError::Invalid(format!("unknown alignment '{s}': use se3, sim3, posyaw or none"))),
        }
    }
}

/// A similarity transform `x ↦ s·R·x + t` taking estimate coordinates into the ground-truth frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Similarity {
    /// Rotation ground truth ← estimate.
    pub rotation: Rotation3<f64>,
    /// Translation \[m\].
    pub translation: Vector3<f64>,
    /// Scale (1 unless Sim(3)).
    pub scale: f64,
}

impl Default for Similarity {
    fn default() -> Self {
        Similarity { rotation: Rotation3::identity(), translation: Vector3::zeros(), scale: 1.0 }
    }
}

impl Similarity {
    /// Apply to a point.
    pub fn apply(&self, p: &Vector3<f64>) -> Vector3<f64> {
        self.rotation * p * self.scale + self.translation
    }
}

fn centroid(p: &[Vector3<f64>]) -> Vector3<f64> {
    p.iter().sum::<Vector3<f64>>() / p.len() as f64
}

/// The least-squares alignment of `est` onto `gt` (same length, paired by index).
///
/// Errors on fewer than 3 pairs and on geometry that does not determine the
/// transform: (nearly) collinear positions for SE(3)/Sim(3), no horizontal
/// extent for position+yaw, a point-like estimate for Sim(3).
///
/// ```
/// use nalgebra::{Rotation3, Vector3};
/// use tumble::eval::{align, Alignment};
/// let gt: Vec<Vector3<f64>> = (0..20).map(|i| Vector3::new((i as f64).cos(), (i as f64).sin(), 0.1 * i as f64)).collect();
/// let r = Rotation3::from_euler_angles(0.0, 0.0, 0.7);
/// let est: Vec<Vector3<f64>> = gt.iter().map(|p| r * p + Vector3::new(1.0, 2.0, 3.0)).collect();
/// let s = align(&est, &gt, Alignment::PosYaw).unwrap();
/// assert!((s.apply(&est[5]) - gt[5]).norm() < 1e-12);
/// ```
pub fn align(est: &[Vector3<f64>], gt: &[Vector3<f64>], kind: Alignment) -> Result<Similarity, EvalError> {
    if est.len() != gt.len() {
        return Err(format!("alignment needs paired positions ({} vs {})", est.len(), gt.len()).into());
    }
    if kind == Alignment::None {
        return Ok(Similarity::default());
    }
    if est.len() < 3 {
        return Err(format!("alignment needs at least 3 matched poses, got {}", est.len()).into());
    }
    let (ce, cg) = (centroid(est), centroid(gt));
    let n = est.len() as f64;
    let extent = est.iter().map(|p| (p - ce).norm()).fold(0.0, f64::max);
    let mut cov = Matrix3::zeros();
    let (mut var_e, mut horizontal) = (0.0, 0.0f64);
    for (e, g) in est.iter().zip(gt) {
        let (e, g) = (e - ce, g - cg);
        cov += g * e.transpose();
        var_e += e.norm_squared();
        horizontal = horizontal.max(e.xy().norm());
    }
    cov /= n;
    var_e /= n;
    if kind == Alignment::PosYaw {
        // The sine and cosine sums of the yaw ([`best_yaw`]).
        let (s, c) = (cov[(1, 0)] - cov[(0, 1)], cov[(0, 0)] + cov[(1, 1)]);
        if horizontal <= 1e-9 * extent.max(1e-3) || (s == 0.0 && c == 0.0) {
            return Err("degenerate geometry: the estimate does not move horizontally, its yaw cannot be aligned \
                        (use --align none)"
                .into());
        }
        let rotation = Rotation3::from_axis_angle(&Vector3::z_axis(), best_yaw(&cov));
        return Ok(Similarity { rotation, translation: cg - rotation * ce, scale: 1.0 });
    }
    let Some((rotation, singular, d)) = best_rotation(&cov) else {
        return Err("alignment: SVD did not converge".into());
    };
    let mut sv: Vec<f64> = singular.iter().copied().collect();
    sv.sort_by(|a, b| b.total_cmp(a));
    if sv[0].is_nan() || sv[0] <= 0.0 || sv[1] <= 1e-10 * sv[0] {
        return Err(format!(
            "degenerate geometry: the positions are (nearly) collinear, so a {} alignment is not determined \
             (use --align posyaw or none)",
            kind.name()
        )
        .into());
    }
    let scale = if kind == Alignment::Sim3 {
        if var_e <= 1e-18 {
            return Err("degenerate geometry: the estimate does not move, its scale is not determined".into());
        }
        singular.component_mul(&d).sum() / var_e
    } else {
        1.0
    };
    Ok(Similarity { rotation, translation: cg - rotation * ce * scale, scale })
}

/// The rotation `R` that maximizes `tr(Rᵀ M)` (Wahba's problem; Kabsch,
/// Umeyama): `U D Vᵀ` from the SVD `M = U Σ Vᵀ`, where `D` flips the axis of
/// the smallest singular value when `det(U Vᵀ) < 0`. Also `Σ` and `D`'s
/// diagonal (Umeyama's scale is `Σ·D` over the variance); None when the SVD
/// does not converge.
pub fn best_rotation(m: &Matrix3<f64>) -> Option<(Rotation3<f64>, Vector3<f64>, Vector3<f64>)> {
    let svd = m.svd(true, true);
    let (u, v_t) = (svd.u?, svd.v_t?);
    let mut d = Vector3::repeat(1.0);
    if (u.determinant() * v_t.determinant()) < 0.0 {
        d[svd.singular_values.imin()] = -1.0;
    }
    let rotation = Rotation3::from_matrix_unchecked(u * Matrix3::from_diagonal(&d) * v_t);
    Some((rotation, svd.singular_values, d))
}

/// The angle \[rad\] of the rotation about the vertical that maximizes
/// `tr(Rᵀ M)`: `atan2(M₁₀ − M₀₁, M₀₀ + M₁₁)`.
pub fn best_yaw(m: &Matrix3<f64>) -> f64 {
    (m[(1, 0)] - m[(0, 1)]).atan2(m[(0, 0)] + m[(1, 1)])
}

//! The keyframe policy: a frame becomes a keyframe when its features moved
//! enough since the last keyframe (median parallax with the rotation taken
//! out: only translation triangulates) and not too soon after it, when too
//! long has passed, or when it shares too few features with the last keyframe.

use super::WindowOptions;
use nalgebra::{Matrix3, Vector3};
use std::collections::HashMap;

/// Undistorted (normalized) feature positions of one frame, by track id.
pub(crate) type FrameObs = HashMap<u64, [f64; 2]>;

/// A frame's features with the camera rotation (world ← body) at the frame,
/// to measure their motion since an earlier frame.
pub(crate) struct FeatureMotion<'a> {
    /// The frame's features.
    pub obs: &'a FrameObs,
    /// Body rotation at the frame (world ← body; IMU-predicted).
    pub rotation: Matrix3<f64>,
    /// Camera rotation in the body (body ← camera).
    pub r_bc: Matrix3<f64>,
    /// Focal length \[px\] (normalized distances to pixels).
    pub fx: f64,
}

impl FeatureMotion<'_> {
    /// Median distance \[px\] the features common with `then` (an earlier
    /// frame, body rotation `r_then`) moved, with the rotation between the
    /// two frames taken out, and how many were common (∞ and 0 with none).
    /// The median, not the mean: a few landmarks close to the camera would
    /// otherwise make every frame a keyframe while it turns slowly.
    pub fn parallax(&self, then: &FrameObs, r_then: &Matrix3<f64>) -> (f64, usize) {
        let rel = (r_then * self.r_bc).transpose() * (self.rotation * self.r_bc);
        let mut d = Vec::with_capacity(self.obs.len());
        for (id, xy) in self.obs {
            if let Some(q) = then.get(id) {
                let f = rel.transpose() * Vector3::new(q[0], q[1], 1.0);
                if f.z > 1e-6 {
                    d.push(((xy[0] - f.x / f.z).powi(2) + (xy[1] - f.y / f.z).powi(2)).sqrt() * self.fx);
                }
            }
        }
        let n = d.len();
        crate::model::numeric::median(&mut d).map_or((f64::INFINITY, 0), |m| (m, n))
    }
}

/// Features common with the last keyframe below which a frame is a keyframe.
pub(crate) const MIN_COMMON_FEATURES: usize = 10;

/// Whether a frame becomes a keyframe: its median parallax to the last
/// keyframe `parallax_px` reaches [`WindowOptions::keyframe_parallax_px`]
/// at least [`WindowOptions::keyframe_min_interval_s`] after it,
/// `since_keyframe_s` reaches [`WindowOptions::keyframe_max_interval_s`], or
/// it shares fewer than half of the last keyframe's `keyframe_features` (or
/// fewer than [`MIN_COMMON_FEATURES`]): `common` of them.
pub(crate) fn is_keyframe(
    opts: &WindowOptions,
    parallax_px: f64,
    since_keyframe_s: f64,
    common: usize,
    keyframe_features: usize,
) -> bool {
    (parallax_px >= opts.keyframe_parallax_px && since_keyframe_s >= opts.keyframe_min_interval_s)
        || since_keyframe_s >= opts.keyframe_max_interval_s
        || common * 2 < keyframe_features
        || common < MIN_COMMON_FEATURES
}

#[cfg(test)]
mod tests {
    use super::*;
    use tumble_solvers::lie::so3_exp;

    fn grid() -> FrameObs {
        (0..25u64).map(|k| (k, [(k % 5) as f64 * 0.1 - 0.2, (k / 5) as f64 * 0.1 - 0.2])).collect()
    }

    #[test]
    fn a_pure_rotation_has_no_parallax() {
        let then = grid();
        let r = so3_exp(&Vector3::new(0.0, 0.05, 0.0));
        // The features as the rotated camera sees them (points at infinity).
        let now: FrameObs = then
            .iter()
            .map(|(&id, q)| {
                let f = r.transpose() * Vector3::new(q[0], q[1], 1.0);
                (id, [f.x / f.z, f.y / f.z])
            })
            .collect();
        let m = FeatureMotion { obs: &now, rotation: r, r_bc: Matrix3::identity(), fx: 500.0 };
        let (par, n) = m.parallax(&then, &Matrix3::identity());
        assert_eq!(n, 25);
        assert!(par < 1e-9, "{par}");
        // Without the rotation taken out it would be ~25 px.
        let still = FeatureMotion { obs: &now, rotation: Matrix3::identity(), r_bc: Matrix3::identity(), fx: 500.0 };
        assert!(still.parallax(&then, &Matrix3::identity()).0 > 20.0);
    }

    #[test]
    fn the_median_ignores_a_few_near_features() {
        let then = grid();
        let mut now = then.clone();
        for k in 0..5 {
            now.get_mut(&k).unwrap()[0] += 0.2; // 100 px: five near landmarks
        }
        for k in 5..25 {
            now.get_mut(&k).unwrap()[0] += 0.004; // 2 px
        }
        let m = FeatureMotion { obs: &now, rotation: Matrix3::identity(), r_bc: Matrix3::identity(), fx: 500.0 };
        let (par, _) = m.parallax(&then, &Matrix3::identity());
        assert!((par - 2.0).abs() < 1e-9, "{par}");
        assert_eq!(m.parallax(&FrameObs::new(), &Matrix3::identity()), (f64::INFINITY, 0));
    }

    #[test]
    fn keyframe_decision() {
        let o = WindowOptions::default();
        let px = o.keyframe_parallax_px;
        assert!(!is_keyframe(&o, px - 0.1, 0.5, 40, 50));
        assert!(is_keyframe(&o, px, 0.5, 40, 50), "parallax");
        assert!(is_keyframe(&o, 1.0, 1.0, 40, 50), "interval");
        let soon = 0.5 * o.keyframe_min_interval_s;
        assert!(!is_keyframe(&o, 10.0 * px, soon, 40, 50), "parallax, but too soon after the last keyframe");
        assert!(is_keyframe(&o, 1.0, soon, 24, 50), "features lost, however soon");
        assert!(is_keyframe(&o, 1.0, 0.5, 24, 50), "fewer than half the features");
        assert!(is_keyframe(&o, 1.0, 0.5, 9, 12), "fewer than ten");
    }
}

//! The paper's 6-minute hand-held walk as a person walks it: laps of an
//! elliptical corridor at about 1 m/s that end where they began, and the
//! corridor itself — landmarks on its walls, floor and ceiling, with the block
//! inside the ring hiding what lies behind it.
//!
//! Frames as in [`super::motion`]: world z up, the floor at z = 0, the
//! corridor's centre line an ellipse around the world origin.

use super::motion::{envelope, min_jerk_integral, Harmonics, Kinematics, Motion};
use super::SimError;
use nalgebra::{Matrix3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;
use tumble_solvers::lie::{so3_exp, so3_right_jacobian};

/// An elliptical corridor: a ring between two walls around a solid block.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Corridor {
    /// Semi-axes of the walked centre line along world x and y \[m\].
    pub semi_axes: [f64; 2],
    /// Half the corridor's width: each wall is this far from the centre line
    /// along both axes \[m\].
    pub half_width: f64,
    /// Ceiling height above the floor \[m\].
    pub height: f64,
}

impl Default for Corridor {
    /// A 28 m × 14 m ring, 3 m wide and 3 m high: one lap is 67.8 m.
    fn default() -> Self {
        Corridor { semi_axes: [14.0, 7.0], half_width: 1.5, height: 3.0 }
    }
}

/// Perimeter of an ellipse with semi-axes `a`, `b` (Ramanujan's second
/// approximation, relative error < 1e-9 for the axes ratios used here) \[m\].
pub(crate) fn ellipse_perimeter(a: f64, b: f64) -> f64 {
    let h = ((a - b) / (a + b)).powi(2);
    PI * (a + b) * (1.0 + 3.0 * h / (10.0 + (4.0 - 3.0 * h).sqrt()))
}

impl Corridor {
    /// Semi-axes of the inner wall (the block's surface) \[m\].
    pub fn inner(&self) -> [f64; 2] {
        self.semi_axes.map(|s| s - self.half_width)
    }
    /// Semi-axes of the outer wall \[m\].
    pub fn outer(&self) -> [f64; 2] {
        self.semi_axes.map(|s| s + self.half_width)
    }
    /// Length of one lap of the centre line \[m\].
    pub fn lap_length(&self) -> f64 {
        ellipse_perimeter(self.semi_axes[0], self.semi_axes[1])
    }
    /// Area of the walls, floor and ceiling \[m²\].
    pub fn surface(&self) -> f64 {
        let ([ai, bi], [ao, bo]) = (self.inner(), self.outer());
        (ellipse_perimeter(ai, bi) + ellipse_perimeter(ao, bo)) * self.height + 2.0 * PI * (ao * bo - ai * bi)
    }
    /// Check the geometry; the error names the field.
    pub fn check(&self) -> Result<(), SimError> {
        let [a, b] = self.semi_axes;
        if !(a.is_finite() && b.is_finite() && self.half_width > 0.0 && self.height > 0.0 && self.height.is_finite()) {
            return Err("corridor: semi-axes, half width and height must be finite and positive".into());
        }
        if a.min(b) <= self.half_width {
            return Err(format!(
                "corridor: the semi-axes {a} m and {b} m must exceed the half width {} m",
                self.half_width
            )
            .into());
        }
        Ok(())
    }

    /// About `density` landmarks per square metre spread uniformly over the
    /// walls, floor and ceiling \[m\] (world frame).
    pub fn landmarks(&self, density: f64, rng: &mut ChaCha8Rng) -> Vec<[f64; 3]> {
        let ([ai, bi], [ao, bo]) = (self.inner(), self.outer());
        let h = self.height;
        let count = |area: f64| (density * area).round() as usize;
        let mut out = Vec::new();
        for [a, b] in [[ai, bi], [ao, bo]] {
            // Uniform in arc length: angle uniform, kept in proportion to the speed |p'(θ)|.
            let n = count(ellipse_perimeter(a, b) * h);
            let mut placed = 0;
            while placed < n {
                let th = rng.random_range(0.0..2.0 * PI);
                let speed = (a * a * th.sin().powi(2) + b * b * th.cos().powi(2)).sqrt();
                if rng.random_range(0.0..a.max(b)) < speed {
                    out.push([a * th.cos(), b * th.sin(), rng.random_range(0.0..h)]);
                    placed += 1;
                }
            }
        }
        let inside = |x: f64, y: f64, a: f64, b: f64| (x / a).powi(2) + (y / b).powi(2) < 1.0;
        for z in [0.0, h] {
            let n = count(PI * (ao * bo - ai * bi));
            let mut placed = 0;
            while placed < n {
                let (x, y) = (rng.random_range(-ao..ao), rng.random_range(-bo..bo));
                if inside(x, y, ao, bo) && !inside(x, y, ai, bi) {
                    out.push([x, y, z]);
                    placed += 1;
                }
            }
        }
        out
    }

    /// Whether a point is in sight from `eye` \[m\]: the segment between them
    /// misses the block inside the inner wall (shrunk by 5 cm, so that
    /// landmarks on the wall itself are seen from the corridor).
    pub fn sees(&self, eye: &Vector3<f64>, point: &[f64; 3]) -> bool {
        let [a, b] = self.inner().map(|s| s - 0.05);
        let (cx, cy) = (eye.x / a, eye.y / b);
        let (dx, dy) = ((point[0] - eye.x) / a, (point[1] - eye.y) / b);
        // |c + u d|² − 1 over u ∈ [0, 1] in the ellipse's unit-circle coordinates.
        let (alpha, beta, gamma) = (dx * dx + dy * dy, cx * dx + cy * dy, cx * cx + cy * cy - 1.0);
        let u = if alpha > 0.0 { (-beta / alpha).clamp(0.0, 1.0) } else { 0.0 };
        alpha * u * u + 2.0 * beta * u + gamma >= 0.0
    }
}

/// Nominal walking speed of a [`CorridorWalk`] \[m/s\]: the number of laps is
/// the one closest to this speed over the walking time.
pub const WALKING_SPEED: f64 = 1.0;

/// Camera height of the hand-held rig above the floor \[m\].
pub const EYE_HEIGHT: f64 = 1.3;

/// A person walking laps of a [`Corridor`] with the rig in hand, looking
/// ahead along the corridor: rest, speed up, whole laps at about
/// `WALKING_SPEED` (faster on the straights, slower in the bends), slow
/// down, rest, at the start pose again. The hand sways (±5 cm, periods of
/// 1–8 s), bobs with the steps (±2 cm at ~1.8 Hz) and turns (±0.1 rad in
/// roll and pitch, ±0.15 rad in yaw about the walking direction).
#[derive(Debug, Clone)]
pub struct CorridorWalk {
    corridor: Corridor,
    duration: f64,
    rest_s: f64,
    ramp_s: f64,
    laps: u32,
    sway: Harmonics,
    bob: Harmonics,
    rot: Harmonics,
}

impl CorridorWalk {
    /// A walk of `duration` \[s\] (at least 20 s) through `corridor`, its hand motion drawn from `seed`.
    pub fn new(corridor: Corridor, duration: f64, seed: u64) -> Result<CorridorWalk, SimError> {
        corridor.check()?;
        let (rest_s, ramp_s) = (3.0, 2.0);
        if !(duration.is_finite() && duration >= 20.0) {
            return Err(format!("a corridor walk needs at least 20 s, found {duration} s").into());
        }
        let moving = duration - 2.0 * rest_s;
        let laps = ((WALKING_SPEED * (moving - ramp_s) / corridor.lap_length()).round() as u32).max(1);
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x636f7272);
        let harmonics = |periods: &[f64]| periods.iter().map(|p| (moving / p).round().max(1.0)).collect::<Vec<_>>();
        let sway = Harmonics::random(&mut rng, moving, &harmonics(&[8.0, 3.0, 1.3]), Vector3::new(0.15, 0.15, 0.06));
        let bob = Harmonics::random(&mut rng, moving, &harmonics(&[1.0 / 1.8]), Vector3::new(0.0, 0.0, 0.02));
        let rot = Harmonics::random(&mut rng, moving, &harmonics(&[10.0, 4.0, 1.5]), Vector3::new(0.3, 0.3, 0.45));
        Ok(CorridorWalk { corridor, duration, rest_s, ramp_s, laps, sway, bob, rot })
    }
    /// The corridor walked.
    pub fn corridor(&self) -> &Corridor {
        &self.corridor
    }
    /// Number of laps.
    pub fn laps(&self) -> u32 {
        self.laps
    }
}

impl Motion for CorridorWalk {
    fn at(&self, t: f64) -> Kinematics {
        let moving = self.duration - 2.0 * self.rest_s;
        let ramp = self.ramp_s;
        let tm = (t - self.rest_s).clamp(0.0, moving);
        let active = t > self.rest_s && t < self.duration - self.rest_s;
        let (e, de, dde) = if active { envelope(tm, moving, ramp) } else { (0.0, 0.0, 0.0) };
        // ∫ envelope: the distance covered in units of the cruising speed.
        let walked = if tm < ramp {
            ramp * min_jerk_integral(tm / ramp)
        } else if tm > moving - ramp {
            moving - ramp - ramp * min_jerk_integral((moving - tm) / ramp)
        } else {
            tm - 0.5 * ramp
        };
        let k = 2.0 * PI * self.laps as f64 / (moving - ramp);
        let (th, dth, ddth) = (k * walked, k * e, k * de);
        let [a, b] = self.corridor.semi_axes;
        let (s, c) = th.sin_cos();
        let p1 = Vector3::new(-a * s, b * c, 0.0);
        let p2 = Vector3::new(-a * c, -b * s, 0.0);
        let heading = (b * c).atan2(-a * s);
        let heading_rate = a * b / (a * a * s * s + b * b * c * c) * dth;

        let (q1, dq1, ddq1) = self.sway.eval(tm);
        let (q2, dq2, ddq2) = self.bob.eval(tm);
        let (q, dq, ddq) = (q1 + q2, dq1 + dq2, ddq1 + ddq2);
        let (phi, dphi, _) = self.rot.eval(tm);
        let (phi, dphi) = (phi * e, dphi * e + phi * de);
        let wobble = so3_exp(&phi);
        let (sh, ch) = heading.sin_cos();
        let yaw = Matrix3::new(ch, -sh, 0.0, sh, ch, 0.0, 0.0, 0.0, 1.0);
        Kinematics {
            rotation: yaw * wobble,
            position: Vector3::new(a * c, b * s, EYE_HEIGHT) + q * e,
            velocity: p1 * dth + dq * e + q * de,
            acceleration: p2 * (dth * dth) + p1 * ddth + ddq * e + dq * (2.0 * de) + q * dde,
            omega: wobble.transpose() * Vector3::new(0.0, 0.0, heading_rate) + so3_right_jacobian(&phi) * dphi,
        }
    }
    fn duration(&self) -> f64 {
        self.duration
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Central differences of position, velocity and rotation match the
    /// analytic velocity, acceleration and body rate along the whole walk.
    #[test]
    fn derivatives_match_central_differences() {
        let walk = CorridorWalk::new(Corridor::default(), 120.0, 3).unwrap();
        let h = 1e-5;
        for i in 1..400 {
            let t = i as f64 * 0.3;
            let (m, k, p) = (walk.at(t - h), walk.at(t), walk.at(t + h));
            let v = (p.position - m.position) / (2.0 * h);
            let acc = (p.velocity - m.velocity) / (2.0 * h);
            let w = tumble_solvers::lie::so3_log(&(m.rotation.transpose() * p.rotation)) / (2.0 * h);
            assert!((v - k.velocity).norm() < 1e-6, "t {t}: velocity {v} vs {}", k.velocity);
            assert!((acc - k.acceleration).norm() < 1e-5, "t {t}: acceleration {acc} vs {}", k.acceleration);
            assert!((w - k.omega).norm() < 1e-6, "t {t}: rate {w} vs {}", k.omega);
        }
    }

    #[test]
    fn the_walk_returns_to_its_start_after_whole_laps_at_walking_speed() {
        let walk = CorridorWalk::new(Corridor::default(), 360.0, 1).unwrap();
        assert_eq!(walk.laps(), 5);
        let (start, end) = (walk.at(0.0), walk.at(360.0));
        assert!((start.position - end.position).norm() < 1e-9);
        assert!((start.rotation - end.rotation).norm() < 1e-9);
        let mut path = 0.0;
        let mut last = start.position;
        for i in 1..=36000 {
            let p = walk.at(i as f64 * 0.01).position;
            path += (p - last).norm();
            last = p;
        }
        // 5 laps of 67.8 m plus the hand's sway.
        assert!((339.0..380.0).contains(&path), "{path} m");
        assert!(CorridorWalk::new(Corridor::default(), 10.0, 1).is_err());
    }

    #[test]
    fn the_block_hides_the_far_side_and_walls_are_seen_from_the_corridor() {
        let c = Corridor::default();
        let eye = Vector3::new(14.0, 0.0, 1.3);
        // Across the block to the far side: hidden.
        assert!(!c.sees(&eye, &[-14.0, 0.0, 1.0]));
        // The inner wall right beside the walker, and the outer wall.
        assert!(c.sees(&eye, &[12.5, 0.0, 1.0]));
        assert!(c.sees(&eye, &[15.5, 0.0, 2.0]));
        // Down the corridor, past the bend.
        assert!(c.sees(&eye, &[13.0, 4.5, 0.0]));
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let l = c.landmarks(2.0, &mut rng);
        let expected = 2.0 * c.surface();
        assert!((l.len() as f64 - expected).abs() < 3.0, "{} vs {expected}", l.len());
        let [ai, bi] = c.inner();
        let [ao, bo] = c.outer();
        for p in &l {
            let r_in = (p[0] / ai).powi(2) + (p[1] / bi).powi(2);
            let r_out = (p[0] / ao).powi(2) + (p[1] / bo).powi(2);
            assert!(r_in >= 1.0 - 1e-9 && r_out <= 1.0 + 1e-9 && (0.0..=c.height).contains(&p[2]), "{p:?}");
        }
        assert!(Corridor { half_width: 8.0, ..c }.check().is_err());
    }
}

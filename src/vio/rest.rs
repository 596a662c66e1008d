//! Zero-velocity (rest) detection from the feature motion: a frame is at
//! rest when its features hardly moved since the previous frame, or moved
//! within the pixel noise over the last [`super::RestOptions::span_s`].

use super::keyframe::{FeatureMotion, FrameObs};
use super::{RestOptions, REST_NOISE_SIGMAS};
use nalgebra::Matrix3;
use std::collections::VecDeque;

/// Features common with the compared frame below which rest is not decided.
const MIN_COMMON_FEATURES: usize = 10;

/// The frames of the last span and since when the camera has been at rest.
#[derive(Debug)]
pub(crate) struct RestDetector {
    /// The frames of the last `span_s`: time and observations, oldest first.
    recent: VecDeque<(f64, FrameObs)>,
    /// Since when every frame was at rest \[s\] (None: the last one moved).
    since: Option<f64>,
    /// The previous frame's features and body rotation.
    previous: (FrameObs, Matrix3<f64>),
    /// The rest options and the pixel noise σ \[px\].
    opts: RestOptions,
    pixel_sigma: f64,
}

impl RestDetector {
    /// A detector under `opts` with features of pixel noise `pixel_sigma` \[px\].
    pub fn new(opts: &RestOptions, pixel_sigma: f64) -> Self {
        RestDetector {
            recent: VecDeque::new(),
            since: None,
            previous: (FrameObs::new(), Matrix3::identity()),
            opts: opts.clone(),
            pixel_sigma,
        }
    }

    /// Start from a first frame (features and body rotation).
    pub fn restart(&mut self, obs: FrameObs, rotation: Matrix3<f64>) {
        self.previous = (obs, rotation);
    }

    /// Decide whether the frame at time `t` (its features and predicted
    /// rotation in `motion`) is at rest; returns since when the camera has
    /// been at rest, None when it moves. At rest: hardly any motion since the
    /// previous frame, or motion within the pixel noise over the last span —
    /// there without taking out the rotation: the IMU-predicted one errs by
    /// more than the noise over half a second (BMI055: 0.2°, 1.7 px), and at
    /// rest there is none.
    pub fn update(&mut self, t: f64, motion: &FeatureMotion) -> Option<f64> {
        let opts = &self.opts;
        let (par_prev, common_prev) = motion.parallax(&self.previous.0, &self.previous.1);
        let span = opts.span_s;
        let rest_over_span = self.recent.front().and_then(|(t_ref, obs_ref)| {
            let (par, common) = motion.parallax(obs_ref, &motion.rotation);
            let limit = opts.zero_velocity_px.max(REST_NOISE_SIGMAS * self.pixel_sigma);
            (t - t_ref >= 0.8 * span && common >= MIN_COMMON_FEATURES && par < limit).then_some(*t_ref)
        });
        let rest_since_prev = (common_prev >= MIN_COMMON_FEATURES && par_prev < opts.zero_velocity_px)
            .then(|| self.recent.back().map_or(t, |f| f.0));
        self.since = rest_over_span.or(rest_since_prev).map(|since| self.since.map_or(since, |r| r.min(since)));
        self.since
    }

    /// Remember the frame at `t` (after [`RestDetector::update`]) and forget
    /// frames older than the span.
    pub fn push(&mut self, t: f64, obs: &FrameObs, rotation: Matrix3<f64>) {
        self.previous = (obs.clone(), rotation);
        self.recent.push_back((t, obs.clone()));
        while self.recent.front().is_some_and(|f| f.0 < t - self.opts.span_s) {
            self.recent.pop_front();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vio::VioOptions;

    fn frame(shift: f64) -> FrameObs {
        (0..30u64).map(|k| (k, [k as f64 * 0.01 + shift, 0.1])).collect()
    }

    fn motion(obs: &FrameObs) -> FeatureMotion<'_> {
        FeatureMotion { obs, rotation: Matrix3::identity(), r_bc: Matrix3::identity(), fx: 500.0 }
    }

    #[test]
    fn still_features_are_at_rest_since_the_first_still_frame() {
        let opts = VioOptions::default();
        let mut r = RestDetector::new(&opts.rest, opts.noise.pixel_sigma);
        let f = frame(0.0);
        r.restart(f.clone(), Matrix3::identity());
        for k in 1..10 {
            let t = 0.1 * k as f64;
            let since = r.update(t, &motion(&f));
            assert!(since.is_some(), "frame {k}");
            r.push(t, &f, Matrix3::identity());
        }
        assert_eq!(r.since, Some(0.1));
    }

    #[test]
    fn noise_within_the_span_is_rest_and_motion_is_not() {
        let opts = VioOptions::default();
        let mut r = RestDetector::new(&opts.rest, opts.noise.pixel_sigma);
        r.restart(frame(0.0), Matrix3::identity());
        // ±1 px of noise from frame to frame (more than zero_velocity_px), none over the span.
        // Frames every 0.125 s: the first span of 0.8 × 0.5 s is complete at the fifth.
        for k in 1..=10 {
            let t = 0.125 * k as f64;
            let f = frame(if k % 2 == 1 { 0.002 } else { 0.0 });
            let since = r.update(t, &motion(&f));
            assert_eq!(since.is_some(), k >= 5, "frame {k} at {t}");
            r.push(t, &f, Matrix3::identity());
        }
        // Then 6 px away from everything in the span: moving.
        let f = frame(0.012);
        assert_eq!(r.update(1.375, &motion(&f)), None);
    }
}

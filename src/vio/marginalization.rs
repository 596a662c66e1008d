//! Sliding the window: the oldest state and the landmarks anchored in it
//! leave through the Schur complement into a prior on what stays (VINS-Mono's
//! marginalization), and their measurement residuals are counted once, at the
//! estimate they had when they left ([`ResidualTally`], for the audit).

use super::landmarks::{observation_factors, Landmarks};
use super::window::Window;
use super::{VioInput, VioOptions};
use tumble_solvers::{marginalize, Graph, SolveError, B, L, V, X};

/// Whitened measurement residuals of a run, each factor counted once: at the
/// estimate it had when its oldest state was marginalized (reprojections of
/// the landmarks anchored in that state, the IMU and bias random-walk factors
/// to the next state). Priors are not measurements and are left out. The
/// model-discrepancy audit of a VIO run compares them with what the noise explains.
///
/// With the landmarks' bearings estimated
/// ([`super::WindowOptions::landmark_bearings`]) a reprojection residual is
/// whitened by `σ_px`: every observation, the anchor's included, is one
/// residual, and each landmark has three parameters. With the inverse depth
/// alone, by `σ_px √2`: the landmark's ray is fixed by its anchor
/// observation, whose pixel noise therefore enters every other residual of
/// the landmark about as much as the observation's own (the solver's factor
/// weighs by `σ_px` alone, as VINS-Mono's does), and each landmark has one.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct ResidualTally {
    /// Σ ‖r/σ‖² of the reprojections (no robust loss; σ as above).
    pub reprojection_chi2: f64,
    /// Number of reprojection residual rows (2 per observation).
    pub reprojection_rows: usize,
    /// Landmarks whose observations were counted.
    pub landmarks: usize,
    /// Σ of squared whitened IMU-factor and bias random-walk residuals.
    pub imu_chi2: f64,
    /// Their rows (15 per link: 9 IMU, 6 bias random walk).
    pub imu_rows: usize,
    /// Marginalized states (15 parameters each: pose, velocity, biases).
    pub states: usize,
    /// Parameters per landmark: 1 (inverse depth) or 3 (bearing too).
    pub landmark_dof: usize,
}

impl ResidualTally {
    /// χ² of every counted residual.
    pub fn chi2(&self) -> f64 {
        self.reprojection_chi2 + self.imu_chi2
    }

    /// Degrees of freedom: residual rows minus the parameters estimated from them.
    pub fn dof(&self) -> usize {
        (self.reprojection_rows + self.imu_rows).saturating_sub(self.landmark_dof * self.landmarks + 15 * self.states)
    }

    /// The gap χ²/dof − 1, floored at 0 (0 when the noise explains the residuals;
    /// NaN without degrees of freedom).
    pub fn gap(&self) -> f64 {
        match self.dof() {
            0 => f64::NAN,
            d => (self.chi2() / d as f64 - 1.0).max(0.0),
        }
    }
}

/// The whole window's graph: priors, IMU links, rest pseudo-measurements,
/// then the landmarks' reprojections.
pub(crate) fn window_graph(window: &Window, landmarks: &Landmarks, input: &VioInput, opts: &VioOptions) -> Graph {
    let mut g = Graph::new();
    window.add_factors(&mut g);
    landmarks.add_factors(&mut g, input, opts);
    g
}

/// Marginalize the window's oldest state and the landmarks anchored in it,
/// counting their residuals into `tally` first. On failure the window is
/// left as it was (the caller restarts it).
pub(crate) fn marginalize_oldest(
    window: &mut Window,
    landmarks: &mut Landmarks,
    input: &VioInput,
    opts: &VioOptions,
    tally: &mut ResidualTally,
) -> Result<(), SolveError> {
    let old = window.states[0].sid;
    let anchored = landmarks.anchored_in(old);
    let mut keys = vec![X(old), V(old), B(old)];
    keys.extend(anchored.iter().map(|&(_, lid)| L(lid)));
    count_leaving(window, landmarks, input, opts, old, tally);
    let graph = window_graph(window, landmarks, input, opts);
    let m = marginalize(&graph, &window.values, &keys)?;
    window.remove_oldest(m.prior, &keys);
    landmarks.forget(&anchored.iter().map(|&(id, _)| id).collect::<Vec<_>>());
    landmarks.remove_state(old, &mut window.values);
    Ok(())
}

/// Add the residuals of the factors leaving with state `old` (the oldest) to `tally`.
fn count_leaving(
    window: &Window,
    landmarks: &Landmarks,
    input: &VioInput,
    opts: &VioOptions,
    old: u64,
    tally: &mut ResidualTally,
) {
    let mut t = *tally;
    let bearings = opts.window.landmark_bearings;
    t.landmark_dof = if bearings { 3 } else { 1 };
    let variance = opts.noise.pixel_sigma.powi(2) * if bearings { 1.0 } else { 2.0 };
    for tr in landmarks.tracks().values() {
        let Some((lid, a)) = tr.anchored() else { continue };
        if a.sid != old {
            continue;
        }
        let mut counted = false;
        for o in &tr.obs {
            for (f, _) in observation_factors(input, opts, a, lid, o) {
                if let Some(r) = window.values.residual_of(f.as_ref()) {
                    t.reprojection_chi2 += r.norm_squared() / variance;
                    t.reprojection_rows += 2;
                    counted = true;
                }
            }
        }
        t.landmarks += usize::from(counted);
    }
    if !window.links.is_empty() {
        let mut g = Graph::new();
        window.add_link(&mut g, 0);
        if let Ok(c) = g.chi2(&window.values) {
            t.imu_chi2 += c;
            t.imu_rows += g.entries().iter().map(|e| e.factor.residual_dim()).sum::<usize>();
            t.states += 1;
        }
    }
    *tally = t;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tally_degrees_of_freedom_and_gap() {
        let t = ResidualTally {
            reprojection_chi2: 90.0,
            reprojection_rows: 100,
            landmarks: 10,
            imu_chi2: 30.0,
            imu_rows: 30,
            states: 2,
            landmark_dof: 1,
        };
        assert_eq!(t.dof(), 130 - 10 - 30);
        assert!((t.gap() - (120.0 / 90.0 - 1.0)).abs() < 1e-12);
        assert_eq!(ResidualTally { landmark_dof: 3, ..t }.dof(), 130 - 30 - 30);
        assert!(ResidualTally::default().gap().is_nan());
    }
}

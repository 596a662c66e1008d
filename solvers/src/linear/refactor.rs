//! Solves without a new factorization. Near a minimum the normal equations
//! change little from one iteration to the next, and the last sparse
//! Cholesky factor P still solves them nearly: as the chord step `−P⁻¹g`, or
//! as the preconditioner of conjugate gradients, which then reach a direct
//! solve's accuracy in a few iterations. Each costs a pair of triangular
//! solves and a product with H — a small part of a factorization. Where the
//! old factor is not close enough, the caller factorizes.

use super::{dot, SparseFactor, Structure, System};

/// Conjugate-gradient iterations at most. One costs a pair of triangular
/// solves with the factor and a product with H: 0.2–0.4 of a numeric
/// factorization on the benchmark pose graphs (sphere2500, parking-garage),
/// so an attempt that fails costs about one factorization at worst — and it
/// gives up as soon as its rate shows it cannot succeed.
const MAX_ITERATIONS: usize = 4;

/// Converged when the residual's energy in the preconditioner's metric,
/// `rᵀP⁻¹r`, has fallen to this fraction of the right-hand side's. With P
/// close to the system (which the convergence shows), that is the step's
/// squared relative error in the system's energy norm, and its model
/// decrease is within 10⁻⁸ of the exact step's.
const ENERGY_TOLERANCE: f64 = 1e-8;

impl Structure {
    /// Solve `(H + diag(damping)) δ = −g` as [`Structure::solve`] does, by
    /// conjugate gradients preconditioned with the last numeric
    /// factorization (of an earlier system on the same pattern), to
    /// [`ENERGY_TOLERANCE`] or until the model decrease still to come,
    /// `½ rᵀP⁻¹r` at the residual r, is at most `enough` (the caller's
    /// accuracy; 0 for the relative test alone): the decrease of the δ
    /// returned is then within `enough` of the exact step's. None where there
    /// is no factor to use (`last_factor_reusable`), or where CG does not get
    /// there within [`MAX_ITERATIONS`]. Returns δ and the CG iterations taken.
    pub fn solve_with_last_factor(
        &mut self,
        sys: &System,
        damping: Option<&[f64]>,
        enough: f64,
    ) -> Option<(Vec<f64>, usize)> {
        if !self.last_factor_reusable(false) {
            return None;
        }
        let mut factor = self.factor.take()?;
        let solved = self.preconditioned_cg(&mut factor, sys, damping, enough);
        self.factor = Some(factor);
        solved
    }

    /// Whether the last factorization may serve another system on this
    /// pattern: a sparse system without eliminated blocks, whose factor
    /// holds a successful factorization and, where `supernodal` is asked
    /// (the chord steps), is supernodal (`SparseFactor::worth_reusing`).
    fn last_factor_reusable(&self, supernodal: bool) -> bool {
        !self.dense
            && self.elim_dims.is_empty()
            && self.n > 0
            && self.factor.as_ref().is_some_and(|f| f.factored && (f.worth_reusing || !supernodal))
    }

    /// Conjugate gradients on `(H + diag(damping)) δ = −g` from δ = 0,
    /// preconditioned with `factor` ([`Structure::solve_with_last_factor`]).
    fn preconditioned_cg(
        &self,
        factor: &mut SparseFactor,
        sys: &System,
        damping: Option<&[f64]>,
        enough: f64,
    ) -> Option<(Vec<f64>, usize)> {
        let n = self.n;
        let damped_h_times = |v: &[f64]| -> Vec<f64> {
            let mut y = self.h_times(sys, v);
            if let Some(d) = damping {
                for (k, yk) in y.iter_mut().enumerate() {
                    *yk += d[k] * v[k];
                }
            }
            y
        };
        let mut x = vec![0.0; n];
        let mut r: Vec<f64> = sys.g.iter().map(|v| -v).collect();
        let mut z = r.clone();
        factor.apply_inverse(&mut z);
        let rz0 = dot(&r, &z);
        if rz0 == 0.0 {
            return Some((x, 0));
        }
        if rz0.is_nan() || rz0 < 0.0 {
            return None;
        }
        // The fraction of rᵀP⁻¹r to reach: ENERGY_TOLERANCE, or what leaves
        // at most `enough` of the decrease (½ rᵀP⁻¹r) to come.
        let target = ENERGY_TOLERANCE.max(2.0 * enough / rz0);
        let mut p = z.clone();
        let mut rz = rz0;
        for k in 1..=MAX_ITERATIONS {
            let ap = damped_h_times(&p);
            let pap = dot(&p, &ap);
            if !(pap > 0.0 && pap.is_finite()) {
                return None;
            }
            let alpha = rz / pap;
            for i in 0..n {
                x[i] += alpha * p[i];
                r[i] -= alpha * ap[i];
            }
            z.copy_from_slice(&r);
            factor.apply_inverse(&mut z);
            let rz_next = dot(&r, &z);
            let ratio = rz_next / rz0;
            if !(ratio >= 0.0 && ratio.is_finite()) {
                return None;
            }
            if ratio <= target {
                return Some((x, k));
            }
            // Give up where the rate so far, kept up, would not get there.
            if ratio.powf(MAX_ITERATIONS as f64 / k as f64) > target {
                return None;
            }
            let beta = rz_next / rz;
            for i in 0..n {
                p[i] = z[i] + beta * p[i];
            }
            rz = rz_next;
        }
        None
    }

    /// The chord step `δ = −P⁻¹g`, P the last numeric factorization (of an
    /// earlier system on the same pattern), with `Hδ` (undamped) and the
    /// Rayleigh quotient `μ = δᵀ(H + diag(damping))δ / δᵀPδ`: how the
    /// current system compares with P along the step (1 where they agree;
    /// the step's model decrease is then `1 − (μ − 1)²` of the best one's
    /// along it). None where there is no factorization to use, as for
    /// [`Structure::solve_with_last_factor`], or where the first triangular
    /// solve already shows `μ > mu_max`.
    ///
    /// That bound needs `model_value`, the Gauss–Newton model's value at
    /// δ = 0 (`½‖r‖²` of the whitened residuals the system was assembled
    /// from): no step's model decrease exceeds it, so along δ the best
    /// decrease `(gᵀδ)² / 2δᵀHδ` is at most `model_value`, and with
    /// `−gᵀδ = δᵀPδ = ‖L⁻¹g‖²` (P = LLᵀ) that gives
    /// `μ ≥ ‖L⁻¹g‖² / (2 model_value)` before the second solve and the
    /// product with H are spent.
    pub fn chord_step(
        &mut self,
        sys: &System,
        damping: Option<&[f64]>,
        (model_value, mu_max): (f64, f64),
    ) -> Option<(Vec<f64>, Vec<f64>, f64)> {
        if !self.last_factor_reusable(true) {
            return None;
        }
        let factor = self.factor.as_mut()?;
        let mut delta: Vec<f64> = sys.g.iter().map(|v| -v).collect();
        factor.forward(&mut delta);
        // δᵀPδ = ‖L⁻¹g‖².
        let pp = dot(&delta, &delta);
        if pp > 2.0 * model_value * mu_max {
            return None;
        }
        factor.backward(&mut delta);
        let hd = self.h_times(sys, &delta);
        let damped: f64 = damping.map_or(0.0, |d| d.iter().zip(&delta).map(|(dk, x)| dk * x * x).sum());
        let mu = (dot(&delta, &hd) + damped) / pp;
        (pp > 0.0 && mu.is_finite() && delta.iter().all(|v| v.is_finite())).then_some((delta, hd, mu))
    }
}

#[cfg(test)]
mod tests {
    use super::{ENERGY_TOLERANCE, MAX_ITERATIONS};
    use crate::linear::{dot, LinearSolver, Role, Roles, Structure, System};

    /// A grid of 6-dim blocks, `blocks / 12` rows of 12 (a pose graph's
    /// shape: neighbours in a row and across rows), factored supernodally.
    fn grid(blocks: usize) -> Structure {
        let mut roles: Vec<Roles> =
            (1..blocks).map(|b| smallvec::smallvec![Role::Kept(b - 1), Role::Kept(b)]).collect();
        roles.extend((12..blocks).map(|b| smallvec::smallvec![Role::Kept(b - 12), Role::Kept(b)]));
        Structure::new(vec![6; blocks], Vec::new(), &roles, LinearSolver::SparseCholesky).unwrap()
    }

    fn system(s: &Structure, seed: f64, spread: f64) -> System {
        let mut x = seed;
        let mut next = || {
            x = (x * 3.9 * (1.0 - x)).clamp(1e-6, 1.0 - 1e-6);
            x - 0.5
        };
        let mut h = vec![0.0; s.nnz()];
        let mut diag = vec![1.0; s.n];
        for c in 0..s.n {
            let range = s.col_ptr[c]..s.col_ptr[c + 1];
            for (hp, &r) in h[range.clone()].iter_mut().zip(&s.row_idx[range]) {
                if r != c {
                    *hp = 1.0 + spread * next();
                    diag[r] += hp.abs();
                    diag[c] += hp.abs();
                }
            }
        }
        for (k, &p) in s.diag_positions.iter().enumerate() {
            h[p] = diag[k];
        }
        let g = (0..s.n).map(|_| next()).collect();
        System { h, g, hll: Vec::new(), gl: Vec::new(), hcl: Vec::new() }
    }

    fn relative_difference(a: &[f64], b: &[f64]) -> f64 {
        let d: f64 = a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum();
        (d / b.iter().map(|y| y * y).sum::<f64>()).sqrt()
    }

    #[test]
    fn conjugate_gradients_from_a_nearby_factor_match_a_new_factorization() {
        let mut s = grid(240);
        let (near, far) = (system(&s, 0.31, 0.0), system(&s, 0.31, 0.02));
        assert!(s.solve_with_last_factor(&near, None, 0.0).is_none(), "no factorization yet");
        s.solve(&near, None).unwrap();
        assert!(s.factor.as_ref().unwrap().worth_reusing, "a supernodal factor");
        // The nearby system differs by up to 1 % in each off-diagonal entry.
        let (cg, iterations) = s.solve_with_last_factor(&far, None, 0.0).expect("converges from a nearby factor");
        assert!((1..=MAX_ITERATIONS).contains(&iterations));
        let damping = vec![0.5; s.n];
        let (cg_damped, _) = s.solve_with_last_factor(&far, Some(&damping), 0.0).expect("damped too");
        let mut fresh = grid(240);
        let direct = fresh.solve(&far, None).unwrap().0;
        let direct_damped = fresh.solve(&far, Some(&damping)).unwrap().0;
        // The model decrease −gᵀδ − ½δᵀHδ to 10⁻⁸ (ENERGY_TOLERANCE) of the exact one's.
        let decrease = |delta: &[f64], damping: &[f64]| {
            let hd = s.h_times(&far, delta);
            let quad: f64 = delta.iter().zip(&hd).zip(damping).map(|((x, y), d)| x * (y + d * x)).sum();
            -delta.iter().zip(&far.g).map(|(x, g)| x * g).sum::<f64>() - 0.5 * quad
        };
        let none = vec![0.0; s.n];
        for (cg, direct, d) in [(&cg, &direct, &none), (&cg_damped, &direct_damped, &damping)] {
            let (a, b) = (decrease(cg, d), decrease(direct, d));
            assert!(b > 0.0 && (b - a) / b <= ENERGY_TOLERANCE && a <= b * (1.0 + 1e-12), "{a} vs {b}");
            assert!(relative_difference(cg, direct) < 1e-4, "{}", relative_difference(cg, direct));
        }
        // An unrelated system is refused, not solved loosely.
        assert!(s.solve_with_last_factor(&system(&s, 0.77, 1.5), None, 0.0).is_none());
    }

    #[test]
    fn conjugate_gradients_stop_once_the_decrease_to_come_is_within_what_is_asked() {
        let mut s = grid(240);
        s.solve(&system(&s, 0.31, 0.0), None).unwrap();
        let far = system(&s, 0.31, 0.05);
        let mut fresh = grid(240);
        let direct = fresh.solve(&far, None).unwrap().0;
        let decrease = |delta: &[f64]| {
            let hd = fresh.h_times(&far, delta);
            -dot(delta, &far.g) - 0.5 * dot(delta, &hd)
        };
        let exact = decrease(&direct);
        let (_, all) = s.solve_with_last_factor(&far, None, 0.0).expect("converges");
        let enough = 1e-3 * exact;
        let (step, fewer) = s.solve_with_last_factor(&far, None, enough).expect("converges");
        assert!(fewer < all, "{fewer} iterations for 10⁻³, {all} for the relative tolerance");
        // What is left is measured in P's metric, which is within a few % of H's here.
        let left = exact - decrease(&step);
        assert!((0.0..=1.1 * enough).contains(&left), "{left} left of {exact}, {enough} asked");
    }

    #[test]
    fn a_simplicial_factor_serves_the_check_but_not_chord_steps() {
        // A chain of 3-dim blocks: few operations per entry, a simplicial factor.
        let roles: Vec<Roles> = (1..200).map(|b| smallvec::smallvec![Role::Kept(b - 1), Role::Kept(b)]).collect();
        let mut s = Structure::new(vec![3; 200], Vec::new(), &roles, LinearSolver::SparseCholesky).unwrap();
        let (near, far) = (system(&s, 0.29, 0.0), system(&s, 0.29, 0.02));
        s.solve(&near, None).unwrap();
        assert!(!s.factor.as_ref().unwrap().worth_reusing, "a simplicial factor");
        let direct = Structure::new(vec![3; 200], Vec::new(), &roles, LinearSolver::SparseCholesky)
            .unwrap()
            .solve(&far, None)
            .unwrap()
            .0;
        let (cg, _) = s.solve_with_last_factor(&far, None, 0.0).expect("the check's solve");
        assert!(relative_difference(&cg, &direct) < 1e-4, "{}", relative_difference(&cg, &direct));
        assert!(s.chord_step(&far, None, (f64::INFINITY, f64::INFINITY)).is_none(), "no chord steps");
    }

    #[test]
    fn the_chord_step_of_the_factored_system_is_its_solution() {
        let mut s = grid(144);
        let sys = system(&s, 0.43, 0.5);
        assert!(s.chord_step(&sys, None, (f64::INFINITY, f64::INFINITY)).is_none(), "no factorization yet");
        let direct = s.solve(&sys, None).unwrap().0;
        let (delta, hd, mu) = s.chord_step(&sys, None, (f64::INFINITY, f64::INFINITY)).unwrap();
        assert!((mu - 1.0).abs() < 1e-10, "μ = {mu}");
        assert!(relative_difference(&delta, &direct) < 1e-12);
        assert!(relative_difference(&hd, &s.h_times(&sys, &delta)) == 0.0);
        // A system twice the factored one along every direction: μ = 2.
        let double = System { h: sys.h.iter().map(|v| 2.0 * v).collect(), ..system(&s, 0.43, 0.5) };
        let (_, _, mu) = s.chord_step(&double, None, (f64::INFINITY, f64::INFINITY)).unwrap();
        assert!((mu - 2.0).abs() < 1e-10, "μ = {mu}");
    }

    #[test]
    fn the_chord_step_is_refused_after_one_triangular_solve_only_where_mu_is_above_the_bound() {
        let mut s = grid(144);
        let sys = system(&s, 0.43, 0.5);
        s.solve(&sys, None).unwrap();
        // H = 2P: μ = 2 along every step. The model's largest decrease is
        // ½gᵀH⁻¹g, the least value a model can have at δ = 0, and with it the
        // bound μ ≥ ‖L⁻¹g‖² / (2 · model value) is tight.
        let double = System { h: sys.h.iter().map(|v| 2.0 * v).collect(), ..system(&s, 0.43, 0.5) };
        let best = 0.5 * -dot(&grid(144).solve(&double, None).unwrap().0, &double.g);
        let (_, _, mu) = s.chord_step(&double, None, (best, 2.0 + 1e-9)).expect("μ = 2 is allowed");
        assert!((mu - 2.0).abs() < 1e-10, "μ = {mu}");
        assert!(s.chord_step(&double, None, (best, 1.9)).is_none(), "μ = 2 is above 1.9");
        // A larger model value (robust reweighting, factors on constants)
        // only weakens the bound: the full step is computed and returned.
        assert!(s.chord_step(&double, None, (10.0 * best, 1.9)).is_some());
    }
}

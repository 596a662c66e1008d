"""tumble from Python against its Python peers, in one run, as ratios.

1. A robust circle fit of 10,000 residuals written in Python (analytic
   Jacobians, Cauchy loss), from the same start: tumble.Problem against GTSAM's
   Python CustomFactor (pip gtsam==4.3.0), the same final cost.
2. Allan deviations of 6 axes × N samples: tumble.allan (the whole analysis,
   identification included) against allantools.oadev on the same τ.

    pip install ./python gtsam==4.3.0 allantools
    python bench/python/bench_python.py [--residuals 10000] [--samples 1000000] [--repeat 3]

Targets: tumble ≤ 0.5× GTSAM's time; ≥ 30× allantools.
"""

import argparse
import time

import numpy as np

import tumble


def median_time(f, repeat):
    times, out = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = f()
        times.append(time.perf_counter() - t0)
    return float(np.median(times)), out


def circle(n, seed=1):
    rng = np.random.default_rng(seed)
    th = rng.uniform(0, 2 * np.pi, n)
    pts = np.c_[1 + 3 * np.cos(th), -2 + 3 * np.sin(th)] + rng.normal(0, 0.01, (n, 2))
    pts[: n // 50] += rng.normal(0, 1.0, (n // 50, 2))
    return pts


def residual(c, r, q):
    d = q - c
    n = np.sqrt(d @ d)
    return n - r[0], -d / n


def fit_tumble(pts, k):
    p = tumble.Problem()
    p.add_variable("c", np.zeros(2))
    p.add_variable("r", np.array([1.0]))
    for q in pts:
        def f(c, r, q=q):
            e, jc = residual(c, r, q)
            return np.array([e]), [jc.reshape(1, 2), np.array([[-1.0]])]
        p.add_residual(f, ["c", "r"], loss=tumble.Cauchy(k))
    s = p.solve(function_tolerance=1e-12)
    return s.final_cost, s.iterations


def fit_gtsam(pts, k):
    import gtsam

    kc, kr = 0, 1
    noise = gtsam.noiseModel.Robust.Create(gtsam.noiseModel.mEstimator.Cauchy.Create(k), gtsam.noiseModel.Unit.Create(1))
    graph = gtsam.NonlinearFactorGraph()
    for q in pts:
        def f(this, values, jacobians, q=q):
            c, r = values.atVector(kc), values.atVector(kr)
            e, jc = residual(c, r, q)
            if jacobians is not None:
                jacobians[0] = jc.reshape(1, 2)
                jacobians[1] = np.array([[-1.0]])
            return np.array([e])
        graph.add(gtsam.CustomFactor(noise, [kc, kr], f))
    init = gtsam.Values()
    init.insert(kc, np.zeros(2))
    init.insert(kr, np.array([1.0]))
    params = gtsam.LevenbergMarquardtParams()
    params.setRelativeErrorTol(1e-12)
    params.setAbsoluteErrorTol(1e-15)
    result = gtsam.LevenbergMarquardtOptimizer(graph, init, params).optimize()
    return graph.error(result), None


def allan_data(n, seed=2):
    rng = np.random.default_rng(seed)
    white = rng.normal(0, 1e-3, (n, 6))
    walk = np.cumsum(rng.normal(0, 1e-5, (n, 6)), axis=0)
    return white + walk + np.array([0, 0, 0, 0, 0, 9.81])


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--residuals", type=int, default=10000)
    ap.add_argument("--samples", type=int, default=1_000_000)
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args()

    pts = circle(a.residuals)
    k = 0.05
    t_ours, (cost_ours, it) = median_time(lambda: fit_tumble(pts, k), a.repeat)
    print(f"circle fit, {a.residuals} Python residuals (Cauchy {k}):")
    print(f"  tumble.Problem: {t_ours:.3f} s, final cost {cost_ours:.9g} ({it} iterations)")
    try:
        t_gtsam, (cost_gtsam, _) = median_time(lambda: fit_gtsam(pts, k), a.repeat)
        print(f"  GTSAM CustomFactor: {t_gtsam:.3f} s, final cost {cost_gtsam:.9g}")
        print(f"  ratio tumble / GTSAM: {t_ours / t_gtsam:.2f} (target ≤ 0.5); costs agree to {abs(cost_ours - cost_gtsam) / cost_gtsam:.1e}")
    except ImportError:
        print("  GTSAM not installed (pip install gtsam==4.3.0): no ratio")

    x = allan_data(a.samples)
    rate = 100.0
    t_allan, res = median_time(lambda: tumble.allan(x, rate), a.repeat)
    print(f"Allan, 6 axes × {a.samples} samples, {len(res.tau)} τ:")
    print(f"  tumble.allan (whole analysis): {t_allan:.3f} s")
    try:
        import allantools

        taus = np.asarray(res.tau)
        t_at, _ = median_time(lambda: [allantools.oadev(x[:, k], rate=rate, data_type="freq", taus=taus) for k in range(6)], a.repeat)
        print(f"  allantools.oadev (6 axes, the same τ): {t_at:.3f} s")
        print(f"  ratio allantools / tumble: {t_at / t_allan:.1f}× (target ≥ 30×)")
    except ImportError:
        print("  allantools not installed: no ratio")


if __name__ == "__main__":
    main()

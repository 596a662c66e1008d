#!/usr/bin/env python3
"""GTSAM on the same pose graphs as bench_solver, printing the same JSON lines.

    pip install gtsam==4.3.0
    python3 bench/scripts/bench_gtsam.py [--repeat N] FILE.g2o ...

GTSAM's readG2o keeps the information matrices (permuted to its [rot, trans]
order, as tumble does); a PriorFactor with sigma 1e-3 pins the first pose (tumble
holds it constant). LevenbergMarquardtOptimizer with default parameters; the
time is the median of the optimize() call alone; chi2 = 2 * graph.error().
"""
import json
import resource
import statistics
import sys
import time

try:
    import gtsam
except ImportError:
    for path in [a for a in sys.argv[1:] if a.endswith(".g2o") or "/" in a]:
        name = path.rsplit("/", 1)[-1].rsplit(".", 1)[0]
        print(json.dumps({"problem": name, "solver": "gtsam", "skipped": "python gtsam not installed (pip install gtsam==4.3.0)"}))
    sys.exit(0)


def run(path, repeat):
    is3d = any(l.startswith("VERTEX_SE3") for l in open(path))
    graph, initial = gtsam.readG2o(path, is3d)
    keys = sorted(initial.keys())
    first = keys[0]
    if is3d:
        prior = gtsam.PriorFactorPose3(first, initial.atPose3(first), gtsam.noiseModel.Isotropic.Sigma(6, 1e-3))
    else:
        prior = gtsam.PriorFactorPose2(first, initial.atPose2(first), gtsam.noiseModel.Isotropic.Sigma(3, 1e-3))
    graph.add(prior)
    times = []
    result = None
    iterations = 0
    for _ in range(max(1, repeat)):
        opt = gtsam.LevenbergMarquardtOptimizer(graph, initial, gtsam.LevenbergMarquardtParams())
        t = time.perf_counter()
        result = opt.optimize()
        times.append(time.perf_counter() - t)
        iterations = opt.iterations()
    name = path.rsplit("/", 1)[-1].rsplit(".", 1)[0]
    return {
        "problem": name,
        "solver": "gtsam",
        "variables": len(keys) - 1,
        "factors": graph.size() - 1,
        "iterations": iterations,
        "initial_chi2": 2.0 * graph.error(initial),
        "final_chi2": 2.0 * graph.error(result),
        "total_s": statistics.median(times),
        "factorize_s": None,
        "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
        "skipped": None,
    }


def main():
    args = sys.argv[1:]
    repeat = 3
    if "--repeat" in args:
        i = args.index("--repeat")
        repeat = int(args[i + 1])
        del args[i : i + 2]
    for path in args:
        if not path.endswith(".g2o"):
            name = path.rsplit("/", 1)[-1].rsplit(".", 1)[0]
            print(json.dumps({"problem": name, "solver": "gtsam", "skipped": "BAL not wired up for GTSAM here"}), flush=True)
            continue
        try:
            print(json.dumps(run(path, repeat)), flush=True)
        except Exception as e:  # report and go on with the next file
            name = path.rsplit("/", 1)[-1].rsplit(".", 1)[0]
            print(json.dumps({"problem": name, "solver": "gtsam", "skipped": str(e)}), flush=True)


if __name__ == "__main__":
    main()

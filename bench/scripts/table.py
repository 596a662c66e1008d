#!/usr/bin/env python3
"""Markdown table from bench_solver --json and bench_gtsam.py output.

    python3 bench/scripts/table.py rust.jsonl gtsam.jsonl

Columns: per problem, each solver's median optimize time [s] and final chi2;
then tumble's time over the fastest peer's, and tumble's final chi2 relative
to the lowest peer chi2 (negative = tumble lower).
"""
import json
import sys

rows = {}
order = []
for path in sys.argv[1:]:
    for line in open(path):
        line = line.strip()
        if not line.startswith("{"):
            continue
        r = json.loads(line)
        p = r["problem"]
        if p not in rows:
            rows[p] = {}
            order.append(p)
        rows[p][r["solver"]] = r

solvers = ["tumble", "gtsam", "factrs", "tiny-solver", "apex-solver"]
print("| problem | " + " | ".join(solvers) + " | tumble / fastest peer | tumble χ² vs best peer | tumble total / factorize |")
print("|---|" + "---|" * (len(solvers) + 3))
for p in order:
    cells = []
    peers = []
    for s in solvers:
        r = rows[p].get(s)
        if r is None or r.get("skipped"):
            why = (r or {}).get("skipped") or "not run"
            if ".g2o:" in why:  # drop the file path of a reader error
                why = why.split(": ", 1)[-1]
            cells.append("— (" + why[:40] + ")" if r else "—")
            continue
        cells.append(f"{r['total_s']:.3f} s, χ² {r['final_chi2']:.4f}")
        if s != "tumble":
            peers.append(r)
    t = rows[p].get("tumble")
    if t and not t.get("skipped") and peers:
        fastest = min(peers, key=lambda r: r["total_s"])
        best = min(r["final_chi2"] for r in peers)
        ratio = f"{t['total_s'] / fastest['total_s']:.2f} ({fastest['solver']})"
        rel = f"{(t['final_chi2'] - best) / best:+.1e}"
        fac = f"{t['total_s'] / t['factorize_s']:.1f}" if t.get("factorize_s") else "—"
    else:
        ratio, rel = "—", "—"
        fac = f"{t['total_s'] / t['factorize_s']:.1f}" if t and t.get("factorize_s") else "—"
    print(f"| {p} | " + " | ".join(cells) + f" | {ratio} | {rel} | {fac} |")

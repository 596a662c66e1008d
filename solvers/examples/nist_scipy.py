"""The NIST StRD nonlinear regression suite on scipy's least_squares, the peer
of `cargo run --release -p tumble-solvers --example nist`, which runs this
script when Python has scipy and sympy: MINPACK's LM (method='lm') and trf,
both with exact Jacobians (sympy) and default tolerances.

    python3 solvers/examples/nist_scipy.py ../shared/data/nist
"""
import math
import pathlib
import re
import sys
import time

import numpy as np
import sympy as sp
from scipy.optimize import least_squares

# The models, as NIST states them (Roszman1 with atan2 as the certified values need).
MODELS = {
    "Misra1a": "b1*(1-exp(-b2*x))",
    "BoxBOD": "b1*(1-exp(-b2*x))",
    "Misra1b": "b1*(1-(1+b2*x/2)**(-2))",
    "Misra1c": "b1*(1-(1+2*b2*x)**(-0.5))",
    "Misra1d": "b1*b2*x/(1+b2*x)",
    "Chwirut1": "exp(-b1*x)/(b2+b3*x)",
    "Chwirut2": "exp(-b1*x)/(b2+b3*x)",
    "DanWood": "b1*x**b2",
    "Lanczos1": "b1*exp(-b2*x)+b3*exp(-b4*x)+b5*exp(-b6*x)",
    "Lanczos2": "b1*exp(-b2*x)+b3*exp(-b4*x)+b5*exp(-b6*x)",
    "Lanczos3": "b1*exp(-b2*x)+b3*exp(-b4*x)+b5*exp(-b6*x)",
    "Gauss1": "b1*exp(-b2*x)+b3*exp(-(x-b4)**2/b5**2)+b6*exp(-(x-b7)**2/b8**2)",
    "Gauss2": "b1*exp(-b2*x)+b3*exp(-(x-b4)**2/b5**2)+b6*exp(-(x-b7)**2/b8**2)",
    "Gauss3": "b1*exp(-b2*x)+b3*exp(-(x-b4)**2/b5**2)+b6*exp(-(x-b7)**2/b8**2)",
    "Kirby2": "(b1+b2*x+b3*x**2)/(1+b4*x+b5*x**2)",
    "Hahn1": "(b1+b2*x+b3*x**2+b4*x**3)/(1+b5*x+b6*x**2+b7*x**3)",
    "Thurber": "(b1+b2*x+b3*x**2+b4*x**3)/(1+b5*x+b6*x**2+b7*x**3)",
    "Nelson": "b1-b2*x*exp(-b3*x2)",
    "MGH17": "b1+b2*exp(-x*b4)+b3*exp(-x*b5)",
    "ENSO": "b1+b2*cos(2*pi*x/12)+b3*sin(2*pi*x/12)+b5*cos(2*pi*x/b4)+b6*sin(2*pi*x/b4)"
            "+b8*cos(2*pi*x/b7)+b9*sin(2*pi*x/b7)",
    "MGH09": "b1*(x**2+x*b2)/(x**2+x*b3+b4)",
    "MGH10": "b1*exp(b2/(x+b3))",
    "Eckerle4": "(b1/b2)*exp(-0.5*((x-b3)/b2)**2)",
    "Rat42": "b1/(1+exp(b2-b3*x))",
    "Rat43": "b1/((1+exp(b2-b3*x))**(1/b4))",
    "Bennett5": "b1*(b2+x)**(-1/b3)",
    "Roszman1": "b1-b2*x-atan2(b3, x-b4)/pi",
}


def read(path):
    lines = path.read_text().splitlines()
    starts, cert = ([], []), []
    for l in lines:
        m = re.match(r"\s*b\d+\s*=\s*(.*)", l)
        if m:
            v = [float(t) for t in m.group(1).split()]
            if len(v) == 4:
                starts[0].append(v[0]); starts[1].append(v[1]); cert.append(v[2])
    head = max(i for i, l in enumerate(lines) if l.lstrip().startswith("Data:"))
    rows = []
    for l in lines[head + 1:]:
        try:
            v = [float(t) for t in l.split()]
        except ValueError:
            continue
        if len(v) >= 2:
            rows.append(v)
    return starts, np.array(cert), np.array(rows)


def lre(b, c):
    rel = np.abs(b - c) / np.abs(c)
    return float(np.min(np.where(rel == 0, 11.0, np.clip(-np.log10(np.maximum(rel, 1e-300)), 0, 11))))


def main():
    root = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else "../shared/data/nist")
    totals = {"lm": [0, 0.0], "trf": [0, 0.0]}
    cases = 0
    print(f"{'problem':<10} {'start':>5} {'LRE lm':>7} {'LRE trf':>8}")
    for f in sorted(root.glob("*.dat")):
        name = f.stem
        if name not in MODELS:
            continue
        starts, cert, rows = read(f)
        n = len(cert)
        b = sp.symbols(f"b1:{n + 1}")
        x, x2 = sp.symbols("x x2")
        expr = sp.sympify(MODELS[name], locals={"x": x, "x2": x2, **{str(s): s for s in b}})
        y = np.log(rows[:, 0]) if name == "Nelson" else rows[:, 0]
        args = (b, x, x2)
        f_np = sp.lambdify(args, expr, "numpy")
        j_np = [sp.lambdify(args, sp.diff(expr, bi), "numpy") for bi in b]
        xa = rows[:, 1]
        xb = rows[:, 2] if rows.shape[1] > 2 else np.zeros_like(xa)
        res = lambda p: y - f_np(p, xa, xb)
        jac = lambda p: -np.column_stack([np.broadcast_to(j(p, xa, xb), xa.shape) for j in j_np])
        out = []
        for k, s0 in enumerate(starts):
            cases += 1
            row = []
            for method in ("lm", "trf"):
                t = time.perf_counter()
                try:
                    r = least_squares(res, np.array(s0), jac=jac, method=method)
                    score = lre(r.x, cert)
                except Exception:
                    score = 0.0
                totals[method][1] += time.perf_counter() - t
                totals[method][0] += score >= 4
                row.append(score)
            print(f"{name:<10} {k + 1:>5} {row[0]:>7.1f} {row[1]:>8.1f}")
    for m, (solved, secs) in totals.items():
        label = "MINPACK LM (scipy method='lm')" if m == "lm" else "scipy trf"
        print(f"{label}, default options: {solved} of {cases} solved (LRE >= 4), {secs:.3f} s in all")


if __name__ == "__main__":
    main()

"""The Python package against the command line on the same input, against
scipy on a custom-factor fit, and on bad input.

Real data come from $TUMBLE_DATA (else ../shared/data beside the repository);
the command line from $TUMBLE_CLI (else target/debug/tumble). Tests that need
either skip with the reason when it is absent.
"""

import json
import os
import pathlib
import subprocess

import numpy as np
import pytest

import tumble

REPO = pathlib.Path(__file__).resolve().parents[2]
DATA = pathlib.Path(os.environ.get("TUMBLE_DATA", REPO.parent / "shared" / "data"))
CLI = pathlib.Path(os.environ.get("TUMBLE_CLI", REPO / "target" / "debug" / "tumble"))


def data(rel):
    p = DATA / rel
    if not p.exists():
        pytest.skip(f"{p} is absent (docs/datasets.md)")
    return p


def cli(*args):
    if not CLI.exists():
        pytest.skip(f"{CLI} is absent: build the command line (cargo build) or set TUMBLE_CLI")
    return subprocess.run([str(CLI), *map(str, args)], check=True, capture_output=True, text=True).stdout


def test_version():
    assert tumble.__version__.count(".") == 2


def test_calibrate_equals_the_command_line_on_xsens(tmp_path):
    acc, gyr = data("imu_tk_xsens/xsens_acc.mat"), data("imu_tk_xsens/xsens_gyro.mat")
    t, gyro, accel, _ = tumble.read_imu(acc, gyro_file=gyr)
    cal = tumble.calibrate(t, accel, gyro, gravity=9.81744)
    cli("calibrate", "--accel", acc, "--gyro", gyr, "--format", "imu-tk", "--gravity", "9.81744", "--out", tmp_path)
    want = json.loads((tmp_path / "calibration.json").read_text())
    assert cal.verdict == want["verdict"] == "ok"
    for key in ["T_a", "K_a", "b_a", "T_g", "K_g", "b_g", "K_a_std", "b_g_std"]:
        assert np.array_equal(np.array(cal.to_dict()[key]), np.array(want[key])), key
    assert np.allclose(np.diag(cal.accel.K), want["K_a"]) and cal.gyro.T.shape == (3, 3)
    assert cal.accel.b_std.shape == (3,)


def test_allan_equals_the_command_line_on_the_adis_log(tmp_path):
    log = data("adis16405_static/adis_16405_imu1.csv.gz")
    units = dict(columns="gx,gy,gz,ax,ay,az", rate=100.0, gyro_unit="deg/s", accel_unit="g")
    t, gyro, accel, _ = tumble.read_imu(log, **units)
    # The same samples as the reader gives the command line, in SI.
    result = tumble.allan(np.hstack([gyro, accel]), 100.0)
    cli("allan", log, "--columns", "gx,gy,gz,ax,ay,az", "--rate", "100", "--gyro-unit", "deg/s",
        "--accel-unit", "g", "--out", tmp_path)
    yaml = dict(
        line.split(":", 1) for line in (tmp_path / "imu.yaml").read_text().splitlines()
        if ":" in line and not line.startswith((" ", "#", "%"))
    )
    for key in ["gyroscope_noise_density", "gyroscope_random_walk", "accelerometer_noise_density",
                "accelerometer_random_walk"]:
        assert getattr(result, key) == pytest.approx(float(yaml[key].split("#")[0]), rel=1e-12), key
    assert result.adev.shape == (6, len(result.tau)) and np.all(np.diff(result.tau) > 0)
    assert "sensors" in result.to_dict() or result.to_dict()


def test_solve_g2o_equals_the_command_line(tmp_path):
    g2o = data("pose_graphs/intel.g2o")
    s = tumble.solve_g2o(g2o)
    out = cli("solve", g2o)
    line = next(l for l in out.splitlines() if "final chi2" in l or "χ²" in l)
    printed = line.replace("=", " ").split()[-1]
    # Equal to the last printed digit.
    assert s.converged and f"{s.final_chi2:.{len(printed.split('.')[1])}f}" == printed
    assert len(s.poses) > 1000 and len(next(iter(s.poses.values()))) == 3


def circle_points(n=300, seed=3):
    rng = np.random.default_rng(seed)
    th = rng.uniform(0, 2 * np.pi, n)
    pts = np.c_[1 + 3 * np.cos(th), -2 + 3 * np.sin(th)] + rng.normal(0, 0.01, (n, 2))
    pts[:10] += rng.normal(0, 1.0, (10, 2))  # outliers
    return pts


def test_a_custom_fit_matches_scipy():
    from scipy.optimize import least_squares

    pts = circle_points()
    p = tumble.Problem()
    p.add_variable("c", np.zeros(2))
    p.add_variable("r", np.array([1.0]))
    for q in pts:
        p.add_residual(lambda c, r, q=q: np.array([np.linalg.norm(q - c) - r[0]]), ["c", "r"],
                       loss=tumble.Cauchy(0.05))
    s = p.solve()
    ref = least_squares(lambda x: np.linalg.norm(pts - x[:2], axis=1) - x[2], [0, 0, 1.0],
                        loss="cauchy", f_scale=0.05, xtol=1e-12, ftol=1e-12, gtol=1e-12)
    assert s.converged, s.termination
    assert np.allclose(s.values["c"], ref.x[:2], atol=1e-6) and abs(s.values["r"][0] - ref.x[2]) < 1e-6
    assert s.final_cost == pytest.approx(ref.cost, rel=1e-6)
    assert s.covariance("c").shape == (2, 2)


def test_analytic_jacobians_and_manifold_variables():
    # A rotation fitted to rotated vectors, with the Jacobian given (d(R Exp(δ) v)/dδ = −R [v]×).
    rng = np.random.default_rng(4)
    truth = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    truth *= np.sign(np.linalg.det(truth))
    p = tumble.Problem()
    p.add_variable("R", np.eye(3), kind="so3")
    for _ in range(20):
        v = rng.normal(size=3)
        w = truth @ v

        def f(R, v=v, w=w):
            hat = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
            return R @ v - w, [-R @ hat]

        p.add_residual(f, ["R"])
    s = p.solve()
    assert np.allclose(s.values["R"], truth, atol=1e-9), s
    p.add_variable("T", np.eye(4), kind="se3")
    p.set_constant("T")


def test_evaluate_aligns_and_measures():
    t = np.arange(100) * 0.1
    gt = np.c_[t, np.cos(t), np.sin(t), 0.1 * t, np.zeros((100, 3)), np.ones(100)]
    est = gt.copy()
    est[:, 1] += 5.0  # a shift the se3 alignment removes
    e = tumble.evaluate(est, gt, align="se3")
    assert e.ate_rmse_m < 1e-9 and e.rotation_rmse_deg < 1e-6
    assert tumble.evaluate(est, gt, align="none").ate_rmse_m == pytest.approx(5.0)
    assert "rpe" in e.to_dict()


def test_bad_inputs_raise_clear_errors():
    with pytest.raises(tumble.TumbleError, match=r"\(N, 6\)"):
        tumble.allan(np.zeros((10, 5)), 100.0)
    bad = np.zeros((100, 6))
    bad[17, 2] = np.nan
    with pytest.raises(tumble.TumbleError, match="row 17"):
        tumble.allan(bad, 100.0)
    with pytest.raises(tumble.TumbleError, match="gyro-unit"):
        tumble.allan(np.zeros((100, 6)), 100.0, gyro_unit="furlongs/s")
    with pytest.raises(tumble.TumbleError, match="rate_hz"):
        tumble.allan(np.zeros((100, 6)), 0.0)
    with pytest.raises(tumble.TumbleError, match="accel must be an"):
        tumble.calibrate(np.arange(10.0), np.zeros((10, 2)), np.zeros((10, 3)), gravity=9.81)
    with pytest.raises(tumble.TumbleError, match="quaternion"):
        tumble.evaluate(np.c_[np.arange(5.0), np.zeros((5, 7))], np.c_[np.arange(5.0), np.zeros((5, 7))])
    with pytest.raises(tumble.TumbleError, match="no variable"):
        tumble.Problem().add_residual(lambda x: x, ["x"])
    with pytest.raises(tumble.TumbleError, match="does not exist"):
        tumble.read_imu("/nonexistent/imu.csv")
    with pytest.raises(tumble.TumbleError, match="unknown option"):
        p = tumble.Problem()
        p.add_variable("x", np.zeros(1))
        p.add_residual(lambda x: x - 1.0, ["x"])
        p.solve(tolerance=1)
    # A recording that cannot be calibrated (no motion) raises CalibrationFailed.
    t = np.arange(3000) * 0.01
    still = np.tile([0.0, 0.0, 9.81], (3000, 1)) + np.random.default_rng(0).normal(0, 0.01, (3000, 3))
    with pytest.raises(tumble.CalibrationFailed):
        tumble.calibrate(t, still, np.zeros((3000, 3)), gravity=9.81)

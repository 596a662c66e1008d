"""tumble from Python: IMU calibration without a turntable, Allan noise
identification, trajectory evaluation, pose graphs, and a sparse
Levenberg–Marquardt solver for residuals written in Python.

Arrays in, result objects out; every result has ``to_dict()`` (the JSON the
command line writes). Errors are ``tumble.TumbleError`` (a ``ValueError``)
with the library's message: the file, line or option, and what was wrong.
See docs/python.md.
"""

import json as _json

import numpy as _np

from . import _tumble
from ._tumble import Cauchy, CalibrationFailed, Huber, Problem, TumbleError, __version__

__all__ = [
    "__version__",
    "allan",
    "calibrate",
    "evaluate",
    "read_imu",
    "solve_g2o",
    "Problem",
    "Huber",
    "Cauchy",
    "TumbleError",
    "CalibrationFailed",
    "AllanResult",
    "Calibration",
    "SensorCalibration",
    "Evaluation",
    "PoseGraphSolution",
]


class AllanResult:
    """Allan deviations of a static log and the noise identified from them.

    ``tau`` (T,) [s]; ``adev`` (6, T): gyro x y z [rad/s] then accel x y z
    [m/s²] (NaN past an axis' last τ); the four Kalibr figures (continuous
    time, SI; None for raw counts) as ``tumble allan`` writes them to
    imu.yaml; ``notes`` (reader and fit remarks); ``disturbances`` (knocks and
    steps found).
    """

    def __init__(self, raw):
        self._dict = _json.loads(raw["json"])
        self.tau = raw["tau"]
        self.adev = raw["adev"]
        kalibr = raw.get("kalibr") or {}
        self.gyroscope_noise_density = kalibr.get("gyroscope_noise_density")
        self.gyroscope_random_walk = kalibr.get("gyroscope_random_walk")
        self.accelerometer_noise_density = kalibr.get("accelerometer_noise_density")
        self.accelerometer_random_walk = kalibr.get("accelerometer_random_walk")
        self.notes = list(raw["notes"]) + list(raw.get("kalibr_notes", []))
        self.disturbances = list(raw["disturbances"])

    def to_dict(self):
        """``allan.json`` as a dict."""
        return self._dict

    def __repr__(self):
        return (
            f"AllanResult(gyroscope_noise_density={self.gyroscope_noise_density}, "
            f"accelerometer_noise_density={self.accelerometer_noise_density}, {len(self.tau)} τ)"
        )


def allan(samples, rate_hz, *, gyro_unit="rad/s", accel_unit="m/s^2", progress=None):
    """Allan analysis of a static log: ``samples`` (N, 6) gyro x y z then
    accel x y z at ``rate_hz``; units ``rad/s``/``deg/s``/``counts[:SCALE[:OFFSET]]``
    and ``m/s^2``/``g``/``counts[…]``. ``progress(done, total)`` is called as
    the deviations are computed. Returns an :class:`AllanResult`."""
    samples = _np.ascontiguousarray(samples, dtype=_np.float64)
    return AllanResult(_tumble.allan(samples, float(rate_hz), gyro_unit, accel_unit, progress))


class SensorCalibration:
    """One sensor's calibration, ``calibrated = T·K·(raw − b)`` (the paper's
    eq. 1): ``T`` (3×3) misalignment, ``K`` (3×3, diagonal) scale, ``b`` (3,)
    bias, and their standard deviations ``T_std``, ``K_std``, ``b_std``."""

    def __init__(self, d, s):
        self.T = _np.array(d[f"T_{s}"])
        self.T_std = _np.array(d[f"T_{s}_std"])
        self.K = _np.diag(d[f"K_{s}"])
        self.K_std = _np.diag(d[f"K_{s}_std"])
        self.b = _np.array(d[f"b_{s}"])
        self.b_std = _np.array(d[f"b_{s}_std"])

    def __repr__(self):
        return f"SensorCalibration(K={_np.diag(self.K)}, b={self.b})"


class Calibration:
    """A calibration: ``verdict`` ("ok" or "weak"), ``accel`` and ``gyro``
    (:class:`SensorCalibration`), ``to_dict()`` (calibration.json)."""

    def __init__(self, text):
        self._dict = _json.loads(text)
        self.verdict = self._dict["verdict"]
        self.accel = SensorCalibration(self._dict, "a")
        self.gyro = SensorCalibration(self._dict, "g")
        self.warnings = list(self._dict.get("warnings", []))

    def to_dict(self):
        """``calibration.json`` as a dict."""
        return self._dict

    def __repr__(self):
        return f"Calibration(verdict={self.verdict!r})"


def calibrate(t, accel, gyro, *, gravity):
    """Calibrate accelerometer and gyro from a hand tumble without a turntable:
    ``t`` (N,) [s], ``accel`` and ``gyro`` (N, 3) in the recording's units
    (raw counts, or SI when the accelerometer reads ≈ 1 g at rest, as for
    imu_tk's files); ``gravity`` the local gravity [m/s²]. Returns a
    :class:`Calibration`; raises :class:`CalibrationFailed` (its ``diagnosis``
    the failed calibration's dict, when there is one)."""
    arrays = [_np.ascontiguousarray(a, dtype=_np.float64) for a in (t, accel, gyro)]
    try:
        return Calibration(_tumble.calibrate(*arrays, gravity=float(gravity)))
    except CalibrationFailed as e:
        message, diagnosis = e.args if len(e.args) == 2 else (str(e), None)
        failed = CalibrationFailed(message)
        failed.diagnosis = _json.loads(diagnosis) if diagnosis else None
        raise failed from None


def read_imu(path, **options):
    """Read an IMU recording with the command line's readers (ASL folders,
    bags, MCAP, CSV/text, imu_tk pairs, phone exports). Options:
    ``columns``, ``rate``, ``time_unit``, ``gyro_unit``, ``accel_unit``,
    ``gyro_file``, ``topic`` (as in a recordings file). Returns
    ``(t, gyro, accel, notes)``: ``t`` (N,) [s] from the first sample,
    ``gyro`` and ``accel`` (N, 3), ``notes`` the reader's warnings."""
    return _tumble.read_imu(str(path), **{k: (str(v) if k == "gyro_file" else v) for k, v in options.items()})


class Evaluation:
    """Errors of an estimate against a ground truth: ``ate_rmse_m``,
    ``rotation_rmse_deg``, and everything of metrics.json in ``to_dict()``."""

    def __init__(self, text):
        self._dict = _json.loads(text)
        self.ate_rmse_m = self._dict["ate_rmse_m"]
        self.rotation_rmse_deg = self._dict["rotation_rmse_deg"]

    def to_dict(self):
        """``metrics.json`` as a dict."""
        return self._dict

    def __repr__(self):
        return f"Evaluation(ate_rmse_m={self.ate_rmse_m:.4f}, rotation_rmse_deg={self.rotation_rmse_deg:.3f})"


def evaluate(estimate, groundtruth, *, align="se3"):
    """Compare trajectories given as TUM rows (N, 8) ``t x y z qx qy qz qw``
    [s, m]; ``align`` one of ``se3``, ``sim3``, ``posyaw``, ``none``.
    Returns an :class:`Evaluation`."""
    est = _np.ascontiguousarray(estimate, dtype=_np.float64)
    gt = _np.ascontiguousarray(groundtruth, dtype=_np.float64)
    return Evaluation(_tumble.evaluate(est, gt, align=align))


class PoseGraphSolution:
    """A solved pose graph: ``final_chi2``, ``iterations``, ``converged``,
    ``termination``, ``poses`` (id → ``[x, y, θ]`` or ``[x, y, z, qx, qy, qz, qw]``)."""

    def __init__(self, raw):
        self.final_chi2, self.iterations, self.converged, self.termination, self.poses = raw

    def __repr__(self):
        return f"PoseGraphSolution(final_chi2={self.final_chi2:.6f}, iterations={self.iterations}, {self.termination})"


def solve_g2o(path):
    """Solve a g2o pose graph (2D or 3D) with tumble's defaults."""
    return PoseGraphSolution(_tumble.solve_g2o(str(path)))

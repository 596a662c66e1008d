"""Calibrate an IMU, identify its noise and evaluate a trajectory, all from
numpy arrays (pip install ./python). Uses tumble's own simulator through the
command line for the data, so it runs from a clone with nothing downloaded:

    cargo build && python examples/python/imu_from_arrays.py
"""

import pathlib
import subprocess
import tempfile

import numpy as np

import tumble

REPO = pathlib.Path(__file__).resolve().parents[2]
CLI = REPO / "target" / "debug" / "tumble"


def simulate(scenario, out, *extra):
    subprocess.run([str(CLI), "sim", scenario, "--out", str(out), *extra], check=True, capture_output=True)
    return out


with tempfile.TemporaryDirectory() as tmp:
    tmp = pathlib.Path(tmp)
    # 1. A hand tumble with known errors → calibration from arrays.
    t, gyro, accel, notes = tumble.read_imu(simulate("tumble", tmp / "tumble"))
    cal = tumble.calibrate(t, accel, gyro, gravity=9.81)
    print(f"calibration: {cal.verdict}; accel scales {np.diag(cal.accel.K)} ± {np.diag(cal.accel.K_std)}")

    # 2. 20 minutes at rest → noise by Allan variance.
    t, gyro, accel, _ = tumble.read_imu(simulate("static", tmp / "static", "--duration", "1200"))
    rate = (len(t) - 1) / (t[-1] - t[0])
    noise = tumble.allan(np.hstack([gyro, accel]), rate)
    print(f"gyro white noise {noise.gyroscope_noise_density:.3e} rad/s/√Hz, "
          f"accel white noise {noise.accelerometer_noise_density:.3e} m/s²/√Hz")

    # 3. A trajectory against its truth (here the truth moved by 1 m: aligned away).
    ts = np.arange(200) * 0.05
    truth = np.c_[ts, np.cos(ts), np.sin(ts), 0.1 * ts, np.zeros((200, 3)), np.ones(200)]
    estimate = truth + np.r_[0, 1.0, 0, 0, 0, 0, 0, 0]
    print(tumble.evaluate(estimate, truth, align="se3"))

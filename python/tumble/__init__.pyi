from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

__version__: str

class TumbleError(ValueError): ...
class CalibrationFailed(TumbleError):
    diagnosis: Optional[Dict[str, Any]]

class AllanResult:
    tau: npt.NDArray[np.float64]
    adev: npt.NDArray[np.float64]
    gyroscope_noise_density: Optional[float]
    gyroscope_random_walk: Optional[float]
    accelerometer_noise_density: Optional[float]
    accelerometer_random_walk: Optional[float]
    notes: List[str]
    disturbances: List[str]
    def to_dict(self) -> Dict[str, Any]: ...

def allan(
    samples: npt.ArrayLike,
    rate_hz: float,
    *,
    gyro_unit: str = ...,
    accel_unit: str = ...,
    progress: Optional[Callable[[int, int], None]] = ...,
) -> AllanResult: ...

class SensorCalibration:
    T: npt.NDArray[np.float64]
    T_std: npt.NDArray[np.float64]
    K: npt.NDArray[np.float64]
    K_std: npt.NDArray[np.float64]
    b: npt.NDArray[np.float64]
    b_std: npt.NDArray[np.float64]

class Calibration:
    verdict: str
    accel: SensorCalibration
    gyro: SensorCalibration
    warnings: List[str]
    def to_dict(self) -> Dict[str, Any]: ...

def calibrate(t: npt.ArrayLike, accel: npt.ArrayLike, gyro: npt.ArrayLike, *, gravity: float) -> Calibration: ...
def read_imu(
    path: Any, **options: Any
) -> Tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64], List[str]]: ...

class Evaluation:
    ate_rmse_m: float
    rotation_rmse_deg: float
    def to_dict(self) -> Dict[str, Any]: ...

def evaluate(estimate: npt.ArrayLike, groundtruth: npt.ArrayLike, *, align: str = ...) -> Evaluation: ...

class PoseGraphSolution:
    final_chi2: float
    iterations: int
    converged: bool
    termination: str
    poses: Dict[int, npt.NDArray[np.float64]]

def solve_g2o(path: Any) -> PoseGraphSolution: ...

class Huber:
    k: float
    def __init__(self, k: float) -> None: ...

class Cauchy:
    k: float
    def __init__(self, k: float) -> None: ...

class Solution:
    values: Dict[str, npt.NDArray[np.float64]]
    final_cost: float
    initial_cost: float
    iterations: int
    termination: str
    converged: bool
    def covariance(self, name: str) -> npt.NDArray[np.float64]: ...

Residual = Callable[..., Union[npt.ArrayLike, Tuple[npt.ArrayLike, Sequence[npt.ArrayLike]]]]

class Problem:
    def __init__(self) -> None: ...
    def add_variable(self, name: str, value: npt.ArrayLike, *, kind: str = ...) -> None: ...
    def add_residual(self, func: Residual, names: Sequence[str], *, loss: Optional[Union[Huber, Cauchy]] = ...) -> None: ...
    def set_constant(self, name: str) -> None: ...
    def solve(self, **options: Any) -> Solution: ...

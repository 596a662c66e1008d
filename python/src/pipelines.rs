//! The pipelines as functions: arrays in, the library's results out as
//! arrays and the JSON the command line writes (the Python package turns it
//! into result objects).

use crate::{tumble_error, CalibrationFailed, TumbleError};
use numpy::{PyArray1, PyArray2, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::Path;
use tumble::allan::{run_allan_with_progress, AllanRunOptions};
use tumble::calib::CalibOptions;
use tumble::io::validate::ValidateOptions;
use tumble::io::{recording_from_samples, AccelUnit, GyroUnit, ImuRecording};

/// The rows of an (N, `k`) array as fixed-size arrays, or a TumbleError
/// naming the argument and the shape it has.
fn rows<const K: usize>(name: &str, a: &PyReadonlyArray2<'_, f64>) -> PyResult<Vec<[f64; K]>> {
    let view = a.as_array();
    if view.ncols() != K {
        return Err(TumbleError::new_err(format!(
            "{name} must be an (N, {K}) array, got shape ({}, {})",
            view.nrows(),
            view.ncols()
        )));
    }
    Ok(view.rows().into_iter().map(|r| std::array::from_fn(|k| r[k])).collect())
}

/// A progress callback `f(done, total)` as the library takes it (errors the
/// callback raises are ignored: progress never stops the work).
fn progress_fn(callback: Option<Py<PyAny>>) -> impl Fn(usize, usize) + Sync {
    move |done, total| {
        if let Some(cb) = &callback {
            Python::attach(|py| {
                let _ = cb.call1(py, (done, total));
            });
        }
    }
}

/// Allan deviations and noise identification of a static log:
/// `samples` (N, 6) gyro x y z then accel x y z at `rate_hz`.
#[pyfunction]
#[pyo3(signature = (samples, rate_hz, gyro_unit = "rad/s", accel_unit = "m/s^2", progress = None))]
pub fn allan<'py>(
    py: Python<'py>,
    samples: PyReadonlyArray2<'py, f64>,
    rate_hz: f64,
    gyro_unit: &str,
    accel_unit: &str,
    progress: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    if !(rate_hz.is_finite() && rate_hz > 0.0) {
        return Err(TumbleError::new_err(format!("rate_hz must be a positive number of Hz, got {rate_hz}")));
    }
    let six = rows::<6>("samples", &samples)?;
    let units =
        (GyroUnit::parse(gyro_unit).map_err(tumble_error)?, AccelUnit::parse(accel_unit).map_err(tumble_error)?);
    let gyro: Vec<[f64; 3]> = six.iter().map(|r| [r[0], r[1], r[2]]).collect();
    let accel: Vec<[f64; 3]> = six.iter().map(|r| [r[3], r[4], r[5]]).collect();
    let t = (0..six.len()).map(|i| i as f64 / rate_hz).collect();
    let rec = recording_from_samples("samples", t, &gyro, &accel, units, &ValidateOptions::default())
        .map_err(tumble_error)?;
    let report = py
        .detach(|| run_allan_with_progress(&rec, &AllanRunOptions::default(), &progress_fn(progress)))
        .map_err(tumble_error)?;
    let curves: Vec<&tumble::allan::AllanCurve> =
        report.sensors.iter().flat_map(|s| s.axes.iter().map(|a| &a.curve)).collect();
    let longest = curves.iter().max_by_key(|c| c.tau.len()).map(|c| c.tau.clone()).unwrap_or_default();
    let adev: Vec<Vec<f64>> = curves
        .iter()
        .map(|c| (0..longest.len()).map(|k| c.dev.get(k).copied().unwrap_or(f64::NAN)).collect())
        .collect();
    let out = PyDict::new(py);
    out.set_item("json", report.to_json().to_string())?;
    out.set_item("tau", PyArray1::from_vec(py, longest))?;
    out.set_item("adev", PyArray2::from_vec2(py, &adev).map_err(|e| TumbleError::new_err(e.to_string()))?)?;
    if let Some(k) = &report.kalibr {
        let kalibr = PyDict::new(py);
        kalibr.set_item("gyroscope_noise_density", k.gyroscope_noise_density)?;
        kalibr.set_item("gyroscope_random_walk", k.gyroscope_random_walk)?;
        kalibr.set_item("accelerometer_noise_density", k.accelerometer_noise_density)?;
        kalibr.set_item("accelerometer_random_walk", k.accelerometer_random_walk)?;
        out.set_item("kalibr", kalibr)?;
        out.set_item("kalibr_notes", k.notes.clone())?;
    }
    out.set_item("notes", report.warnings.clone())?;
    out.set_item("disturbances", report.disturbances.iter().map(|d| d.to_string()).collect::<Vec<_>>())?;
    Ok(out)
}

/// Calibrate from a hand tumble held in arrays, in the recording's units
/// (raw counts or SI, recognised from the data as for imu_tk's files).
/// Returns `calibration.json`'s text; a failed calibration raises
/// CalibrationFailed with the diagnosis's JSON as its second argument.
#[pyfunction]
#[pyo3(signature = (t, accel, gyro, *, gravity))]
pub fn calibrate(
    py: Python<'_>,
    t: PyReadonlyArray1<'_, f64>,
    accel: PyReadonlyArray2<'_, f64>,
    gyro: PyReadonlyArray2<'_, f64>,
    gravity: f64,
) -> PyResult<String> {
    let t: Vec<f64> = t.as_array().to_vec();
    let (accel, gyro) = (rows::<3>("accel", &accel)?, rows::<3>("gyro", &gyro)?);
    let raw = (GyroUnit::Counts { scale: None, offset: 0.0 }, AccelUnit::Counts { scale: None, offset: 0.0 });
    let mut rec =
        recording_from_samples("arrays", t, &gyro, &accel, raw, &ValidateOptions::default()).map_err(tumble_error)?;
    tumble::io::recognise_imu_tk_units(&mut rec);
    let opts = CalibOptions { gravity, ..CalibOptions::default() };
    match py.detach(|| tumble::calib::calibrate(&rec, &opts)) {
        Ok(result) => Ok(result.to_json(&opts)),
        Err(e) => {
            let diagnosis = e.diagnosis.as_ref().map(|d| d.to_json(&opts));
            Err(CalibrationFailed::new_err((e.to_string(), diagnosis)))
        }
    }
}

/// Read an IMU recording through the command line's readers: returns
/// `(t, gyro, accel, notes)`, `t` in seconds from the first sample.
#[pyfunction]
#[pyo3(signature = (path, *, columns = None, rate = None, time_unit = None, gyro_unit = None, accel_unit = None, gyro_file = None, topic = None))]
#[allow(clippy::too_many_arguments, clippy::type_complexity)]
pub fn read_imu<'py>(
    py: Python<'py>,
    path: std::path::PathBuf,
    columns: Option<String>,
    rate: Option<f64>,
    time_unit: Option<String>,
    gyro_unit: Option<String>,
    accel_unit: Option<String>,
    gyro_file: Option<std::path::PathBuf>,
    topic: Option<String>,
) -> PyResult<(Bound<'py, PyArray1<f64>>, Bound<'py, PyArray2<f64>>, Bound<'py, PyArray2<f64>>, Vec<String>)> {
    let spec = tumble::io::recordings::RecordingSpec {
        path,
        columns,
        rate,
        time_unit,
        gyro_unit,
        accel_unit,
        gyro_file,
        topic,
        ..Default::default()
    };
    let source = spec.source().map_err(tumble_error)?;
    let rec: ImuRecording = py.detach(|| source.open()).map_err(tumble_error)?;
    let to2 = |v: &[[f64; 3]]| PyArray2::from_vec2(py, &v.iter().map(|r| r.to_vec()).collect::<Vec<_>>());
    let err = |e: numpy::FromVecError| TumbleError::new_err(e.to_string());
    Ok((
        PyArray1::from_vec(py, rec.t.clone()),
        to2(&rec.gyro).map_err(err)?,
        to2(&rec.accel).map_err(err)?,
        rec.warnings,
    ))
}

/// Evaluate an estimated trajectory against a ground truth, both TUM rows
/// (N, 8): `t x y z qx qy qz qw`. Returns `metrics.json`'s text.
#[pyfunction]
#[pyo3(signature = (estimate, groundtruth, *, align = "se3"))]
pub fn evaluate(
    estimate: PyReadonlyArray2<'_, f64>,
    groundtruth: PyReadonlyArray2<'_, f64>,
    align: &str,
) -> PyResult<String> {
    use tumble::io::trajectory::Trajectory;
    let est = Trajectory::from_tum_rows("estimate", &rows::<8>("estimate", &estimate)?).map_err(tumble_error)?;
    let gt =
        Trajectory::from_tum_rows("groundtruth", &rows::<8>("groundtruth", &groundtruth)?).map_err(tumble_error)?;
    let alignment = tumble::eval::Alignment::parse(align).map_err(tumble_error)?;
    let opts = tumble::eval::EvalOptions { alignment, ..Default::default() };
    let e = tumble::eval::evaluate(&est, None, &gt, &opts).map_err(tumble_error)?;
    serde_json::to_string(&e.metrics).map_err(|e| TumbleError::new_err(e.to_string()))
}

/// Solve a g2o pose graph: `(final_chi2, iterations, converged, termination, poses)`,
/// poses a dict id → array (x y θ for 2D, x y z qx qy qz qw for 3D).
#[pyfunction]
#[allow(clippy::type_complexity)]
pub fn solve_g2o<'py>(
    py: Python<'py>,
    path: std::path::PathBuf,
) -> PyResult<(f64, usize, bool, String, Bound<'py, PyDict>)> {
    let opts = tumble::posegraph::SolveFileOptions::default();
    let solved =
        py.detach(|| tumble::posegraph::solve_file(Path::new(&path), &opts, &mut |_| {})).map_err(tumble_error)?;
    let poses = PyDict::new(py);
    for (id, pose) in tumble::posegraph::poses(&solved.solution) {
        poses.set_item(id, PyArray1::from_vec(py, pose))?;
    }
    let s = &solved.summary;
    Ok((2.0 * s.final_cost, s.iterations, s.converged(), format!("{:?}", s.termination), poses))
}

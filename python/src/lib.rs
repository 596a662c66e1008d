//! Python bindings of tumble: `import tumble`.
//!
//! This layer maps Python arguments (numpy arrays, keywords) to library calls
//! and library results back to arrays and JSON; it decides nothing. The
//! Python package `tumble` (python/tumble/__init__.py) wraps what this module
//! returns into result objects. Long work runs with the interpreter released.

use pyo3::prelude::*;

mod pipelines;
mod problem;

pyo3::create_exception!(
    _tumble,
    TumbleError,
    pyo3::exceptions::PyValueError,
    "An input, option or solve tumble refused; the message names the file, line or option."
);
pyo3::create_exception!(
    _tumble,
    CalibrationFailed,
    TumbleError,
    "A calibration that could not be made; the message is the calibration's diagnosis."
);

/// A library error as the Python exception carrying its message (the cause
/// chain joined, as the command line prints it).
pub(crate) fn tumble_error(e: impl std::error::Error) -> PyErr {
    let mut message = e.to_string();
    let mut cause = e.source();
    while let Some(c) = cause {
        let text = c.to_string();
        if !message.contains(&text) {
            message.push_str(&format!(": {text}"));
        }
        cause = c.source();
    }
    TumbleError::new_err(message)
}

#[pymodule]
fn _tumble(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("TumbleError", m.py().get_type::<TumbleError>())?;
    m.add("CalibrationFailed", m.py().get_type::<CalibrationFailed>())?;
    m.add_function(wrap_pyfunction!(pipelines::allan, m)?)?;
    m.add_function(wrap_pyfunction!(pipelines::calibrate, m)?)?;
    m.add_function(wrap_pyfunction!(pipelines::read_imu, m)?)?;
    m.add_function(wrap_pyfunction!(pipelines::evaluate, m)?)?;
    m.add_function(wrap_pyfunction!(pipelines::solve_g2o, m)?)?;
    m.add_class::<problem::Problem>()?;
    m.add_class::<problem::Huber>()?;
    m.add_class::<problem::Cauchy>()?;
    Ok(())
}

//! Bundle Adjustment in the Large text files (Agarwal et al. 2010).
//!
//! Header `cameras points observations`, then one `camera point x y` line per
//! observation, then 9 numbers per camera and 3 per point (whitespace-separated,
//! any line breaking). Cameras become `C(i)` (R^9), points `L(j)` (R^3); the
//! points are meant to be eliminated by the Schur complement (`eliminate = ['l']`).

use crate::error::InputError;
use crate::io::tokens::{parse_f64, parse_usize, read_text};
use nalgebra::{SVector, Vector3};
use std::path::Path;
use tumble_factors::SnavelyReprojection;
use tumble_solvers::{Graph, NoiseModel, Values, C, L};

/// A bundle-adjustment problem.
pub struct BalProblem {
    /// One reprojection factor per observation (unit noise, pixels).
    pub graph: Graph,
    /// Cameras and points.
    pub values: Values,
    /// Number of cameras.
    pub cameras: usize,
    /// Number of points.
    pub points: usize,
    /// Number of observations.
    pub observations: usize,
}

/// Read a BAL file.
pub fn read_bal(path: &Path) -> Result<BalProblem, InputError> {
    parse_bal(path, &read_text(path)?)
}

/// Parse BAL text; `path` is only used in messages.
pub fn parse_bal(path: &Path, text: &str) -> Result<BalProblem, InputError> {
    // Token stream that remembers line numbers.
    let mut toks = text.lines().enumerate().flat_map(|(i, l)| l.split_whitespace().map(move |t| (i + 1, t)));
    let mut last_line = 1;
    let mut next = |what: &str| -> Result<(usize, &str), InputError> {
        match toks.next() {
            Some((l, t)) => {
                last_line = l;
                Ok((l, t))
            }
            None => Err(InputError::at(path, last_line, format!("file ends early: missing {what}"))),
        }
    };
    let num = |path: &Path, (l, t): (usize, &str), what: &str| parse_f64(path, l, t, what);
    let int = |path: &Path, (l, t): (usize, &str), what: &str| parse_usize(path, l, t, what);
    let nc = int(path, next("camera count")?, "camera count")?;
    let np = int(path, next("point count")?, "point count")?;
    let no = int(path, next("observation count")?, "observation count")?;
    if nc == 0 || np == 0 || no == 0 {
        return Err(InputError::at(
            path,
            1,
            format!("header says {nc} cameras, {np} points, {no} observations: nothing to solve"),
        ));
    }
    let mut graph = Graph::new();
    let mut observation_lines = Vec::with_capacity(no);
    for _ in 0..no {
        let tc = next("observation camera index")?;
        let c = int(path, tc, "camera index")?;
        let p = int(path, next("observation point index")?, "point index")?;
        if c >= nc {
            return Err(InputError::at(path, tc.0, format!("camera index {c} out of range (file has {nc} cameras)")));
        }
        if p >= np {
            return Err(InputError::at(path, tc.0, format!("point index {p} out of range (file has {np} points)")));
        }
        let x = num(path, next("observation x")?, "observation x")?;
        let y = num(path, next("observation y")?, "observation y")?;
        graph.add(SnavelyReprojection::new(C(c as u64), L(p as u64), [x, y]), NoiseModel::Unit);
        observation_lines.push((tc.0, c, p));
    }
    // Camera and point parameters: `n` numbers named "<what> <k>".
    let mut read_block = |what: &str, n: usize| -> Result<Vec<f64>, InputError> {
        (1..=n)
            .map(|k| {
                let label = format!("{what} {k}");
                num(path, next(&label)?, &label)
            })
            .collect()
    };
    let mut values = Values::new();
    for c in 0..nc {
        let v = read_block(&format!("camera {c} parameter"), 9)?;
        values.insert(C(c as u64), SVector::<f64, 9>::from_column_slice(&v));
    }
    for p in 0..np {
        let v = read_block(&format!("point {p} coordinate"), 3)?;
        values.insert(L(p as u64), Vector3::from_column_slice(&v));
    }
    if let Some((l, t)) = toks.next() {
        return Err(InputError::at(path, l, format!("unexpected extra data '{t}' after the last point")));
    }
    check_projections(path, &graph, &values, &observation_lines)?;
    Ok(BalProblem { graph, values, cameras: nc, points: np, observations: no })
}

/// Every observation's projection at the file's values must be finite, with
/// its derivatives: a point at its camera's centre (depth 0) has none, and
/// the solver could only say which factor failed, not which line.
fn check_projections(
    path: &Path,
    graph: &Graph,
    values: &Values,
    observations: &[(usize, usize, usize)],
) -> Result<(), InputError> {
    for (k, (entry, &(line, c, p))) in graph.entries().iter().zip(observations).enumerate() {
        let finite = values.linearize(entry.factor.as_ref()).is_some_and(|l| {
            l.residual.iter().all(|v| v.is_finite()) && l.jacobians.iter().all(|j| j.iter().all(|v| v.is_finite()))
        });
        if !finite {
            return Err(InputError::at(
                path,
                line,
                format!("observation {k}: point {p} cannot be projected by camera {c} (it lies at the camera's centre, depth 0, or the projection overflows)"),
            )
            .with_hint("move the point off the camera centre in the file's initial values, or drop the observation"));
        }
    }
    Ok(())
}

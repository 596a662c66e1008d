//! Several recordings of one sensor (`tumble calibrate --inputs`): each
//! recording calibrated alone (its own detection, its own biases — every
//! power-on differs —, its own halves check), then the sensor's own
//! parameters, scales and misalignments, pooled and checked for agreement
//! ([`crate::model::consensus`]). The biases are written as their consensus
//! with the σ a new power-on's bias is known to.
//!
//! A misalignment a recording's poses do not determine (its estimate is the
//! prior's, see `observability`) is left out of that parameter's pool: the
//! prior would otherwise count once per recording.

use super::options::CalibOptions;
use super::result::{Assessment, CalibError, CalibrationResult, Verdict};
use super::solve::calibrate;
use super::split::entries;
use crate::io::ImuRecording;
use crate::model::calibration::{ImuCalibration, Triad};
use crate::model::consensus::{Consensus, RecordingsCheck};

/// Everything [`calibrate_recordings`] found.
#[derive(Debug, Clone)]
pub struct RecordingsResult {
    /// The sensor's calibration: pooled scales and misalignments with their
    /// σ, the biases' consensus with a new power-on's σ.
    pub calibration: ImuCalibration,
    /// Each recording's own calibration, in the order given.
    pub each: Vec<CalibrationResult>,
    /// Scales and misalignments across the recordings.
    pub check: RecordingsCheck,
    /// The biases across the recordings (they differ at every power-on: reported, not judged).
    pub biases: RecordingsCheck,
    /// The verdict: the worst of the recordings', `weak` where they disagree.
    pub assessment: Assessment,
    /// Every recording's warnings, named.
    pub warnings: Vec<String>,
}

/// Calibrate one sensor from several recordings `recs`, each named by
/// `names` (same order; at least two). The first recording that cannot be
/// calibrated stops the run with its error (its diagnosis kept).
pub fn calibrate_recordings(
    recs: &[ImuRecording],
    names: &[String],
    opts: &CalibOptions,
) -> Result<RecordingsResult, CalibError> {
    check_recordings(recs, names)?;
    let each = calibrate_each(recs, names, opts)?;
    let check = pool(&each, names, false);
    let biases = pool(&each, names, true);
    let calibration = combined_calibration(&each[0].calibration, &check, &biases);
    let assessment = assess(&each, names, &check);
    let warnings =
        each.iter().zip(names).flat_map(|(r, name)| r.warnings.iter().map(move |w| format!("{name}: {w}"))).collect();
    Ok(RecordingsResult { calibration, each, check, biases, assessment, warnings })
}

/// Refuse what cannot be pooled: fewer than two recordings, names that do
/// not match them, recordings in different raw units.
fn check_recordings(recs: &[ImuRecording], names: &[String]) -> Result<(), CalibError> {
    let err = |message: String| CalibError {
        source: recs.first().map_or("<none>".into(), ImuRecording::source_name),
        message,
        hint: None,
        diagnosis: None,
    };
    if recs.len() < 2 || names.len() != recs.len() {
        return Err(err(format!(
            "several recordings of one sensor are pooled: {} given ({} names); calibrate one recording alone",
            recs.len(),
            names.len()
        )));
    }
    let units = |r: &ImuRecording| (r.accel_units, r.gyro_units);
    if let Some(i) = recs.iter().position(|r| units(r) != units(&recs[0])) {
        return Err(err(format!(
            "{} stores (accelerometer, gyro) as {:?} and {} as {:?}: one sensor's scales compare only in one raw unit",
            names[0],
            units(&recs[0]),
            names[i],
            units(&recs[i])
        )));
    }
    Ok(())
}

/// Each recording calibrated alone; the first failure, named, stops the run.
fn calibrate_each(
    recs: &[ImuRecording],
    names: &[String],
    opts: &CalibOptions,
) -> Result<Vec<CalibrationResult>, CalibError> {
    recs.iter()
        .zip(names)
        .map(|(rec, name)| {
            calibrate(rec, opts).map_err(|e| CalibError {
                message: format!("{name} (one of {} recordings): {}", recs.len(), e.message),
                ..e
            })
        })
        .collect()
}

/// The parameters of both triads across the recordings: scales and
/// misalignments, or (`biases`) the biases. A misalignment a recording does
/// not determine is left out of that parameter's pool.
fn pool(each: &[CalibrationResult], names: &[String], biases: bool) -> RecordingsCheck {
    let mut parameters = Vec::new();
    for sensor in ["accelerometer", "gyroscope"] {
        let triad = |c: &ImuCalibration| if sensor == "accelerometer" { c.accel.clone() } else { c.gyro.clone() };
        let per: Vec<Vec<(String, f64, f64)>> =
            each.iter().map(|r| entries(sensor, &triad(&r.calibration), true)).collect();
        for (name, _, _) in &per[0] {
            if name.contains(" bias ") != biases {
                continue;
            }
            let undetermined = |r: &CalibrationResult| {
                r.assessment.not_determined.iter().any(|n| n.replace(" T[", " misalignment T[") == *name)
            };
            let found: Vec<Option<(f64, f64)>> =
                per.iter().map(|e| e.iter().find(|x| x.0 == *name).map(|x| (x.1, x.2))).collect();
            let estimates: Vec<(f64, f64)> = found.iter().map(|f| f.unwrap_or((f64::NAN, f64::NAN))).collect();
            let leave_out: Vec<bool> = each.iter().map(undetermined).collect();
            parameters.push(Consensus::without(name.clone(), "", &estimates, &leave_out));
        }
    }
    RecordingsCheck { recordings: names.to_vec(), parameters }
}

/// The first recording's calibration with the pooled values: scales and
/// misalignments from `check`, biases from `biases` with a new power-on's σ.
/// A parameter no recording determined keeps the first recording's value.
fn combined_calibration(first: &ImuCalibration, check: &RecordingsCheck, biases: &RecordingsCheck) -> ImuCalibration {
    let mut c = first.clone();
    for (sensor, t) in [("accelerometer", &mut c.accel), ("gyroscope", &mut c.gyro)] {
        set_pooled(t, sensor, check, biases);
    }
    c
}

/// Set one triad's entries to their pooled values.
fn set_pooled(t: &mut Triad, sensor: &str, check: &RecordingsCheck, biases: &RecordingsCheck) {
    let pooled = |name: String| check.get(&name).or(biases.get(&name)).filter(|c| c.value.is_finite());
    for (i, axis) in ["x", "y", "z"].iter().enumerate() {
        if let Some(c) = pooled(format!("{sensor} scale {axis}")) {
            (t.k[i], t.k_std[i]) = (c.value, c.sigma);
        }
        if let Some(c) = pooled(format!("{sensor} bias {axis}")) {
            (t.b[i], t.b_std[i]) = (c.value, c.new_recording_sigma());
        }
        for col in 0..3 {
            if let Some(c) = pooled(format!("{sensor} misalignment T[{i}][{col}]")) {
                (t.t[(i, col)], t.t_std[(i, col)]) = (c.value, c.sigma);
            }
        }
    }
}

/// The worst of the recordings' verdicts (their reasons named), `weak`
/// where the recordings disagree; not determined: what no recording determined.
fn assess(each: &[CalibrationResult], names: &[String], check: &RecordingsCheck) -> Assessment {
    let mut verdict = each.iter().map(|r| r.assessment.verdict).max().unwrap_or(Verdict::Ok);
    let mut reasons: Vec<String> = each
        .iter()
        .zip(names)
        .flat_map(|(r, name)| r.assessment.reasons.iter().map(move |x| format!("{name}: {x}")))
        .collect();
    for line in check.disagreement_lines() {
        verdict = verdict.max(Verdict::Weak);
        reasons.push(format!(
            "{line}: a property of the sensor the recordings do not agree on (an effect one of them excites, \
             `tumble audit` on each names it)"
        ));
    }
    let not_determined = each[0]
        .assessment
        .not_determined
        .iter()
        .filter(|n| each.iter().all(|r| r.assessment.not_determined.contains(n)))
        .cloned()
        .collect();
    Assessment { verdict, reasons, not_determined }
}

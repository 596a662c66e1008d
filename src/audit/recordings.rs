//! Several recordings of one sensor audited (`tumble audit --inputs`): each
//! recording audited alone, with its own calibration; then every effect
//! added in any of them compared across all. Its coefficients in each
//! recording come from that recording's final model where the effect was
//! added, and from the last round's fit of the effect on top of that model
//! where it was not (a coefficient with its σ either way); they are pooled
//! per coefficient ([`crate::model::consensus`]).
//!
//! An effect **repeats** — a property of the sensor — when the recordings
//! agree on its coefficients (no Cochran's `Q` beyond the 1 % family-wise
//! false alarm) and the pooled coefficients differ from zero (their Wald
//! χ² beyond the audit's `alpha`); it is then added to the sensor's
//! calibration with the pooled coefficients. Otherwise it is named with the
//! recordings it appeared in and not added: one recording's accident, or a
//! model the recordings do not agree on. A recording whose search chose
//! another form of the effect's family (or stopped at `max_effects`) has no
//! coefficient for it and is left out of that effect's pool.
//!
//! The pooled scales and misalignments stay those of the calibration given
//! (`tumble calibrate --inputs`): they were estimated without the effects,
//! which the single-recording audit re-solves them with.

use super::report::{put_file, write_unstaged};
use super::{audit_with_progress, Audit, AuditError, AuditOptions};
use crate::io::ImuRecording;
use crate::model::calibration::{EffectTerm, ImuCalibration, ModelEffects};
use crate::model::consensus::{Consensus, RecordingsCheck};
use serde::Serialize;
use statrs::distribution::{ChiSquared, ContinuousCDF};
use tumble_factors::imu_effects::Effect;

/// One effect across the recordings.
#[derive(Debug, Clone, Serialize)]
pub struct EffectAcross {
    /// The effect's identifier (`gyro_g_sensitivity`, …).
    pub effect: String,
    /// Whether each recording's audit added it.
    pub added_in: Vec<bool>,
    /// Each coefficient per recording and pooled.
    pub parameters: Vec<Consensus>,
    /// The chance of pooled coefficients this far from zero if the effect were absent (Wald χ²).
    pub pooled_p: f64,
    /// No coefficient's `Q` beyond the family-wise false alarm ([`RecordingsCheck::disagreements`]).
    pub agree: bool,
    /// It repeats: added to the sensor's calibration.
    pub repeats: bool,
}

/// Everything [`audit_recordings`] found.
pub struct RecordingsAudit {
    /// The recordings' names, in order.
    pub names: Vec<String>,
    /// Each recording's own audit.
    pub each: Vec<Audit>,
    /// Every effect added in any recording, in the order first found.
    pub effects: Vec<EffectAcross>,
    /// The pooled calibration given, with the effects that repeat.
    pub calibration: ImuCalibration,
}

impl RecordingsAudit {
    /// One line per effect: whether it repeats.
    pub fn verdict_lines(&self) -> Vec<String> {
        if self.effects.is_empty() {
            return vec!["no recording shows an effect beyond the model".into()];
        }
        self.effects
            .iter()
            .map(|e| {
                let seen: Vec<&str> =
                    self.names.iter().zip(&e.added_in).filter(|(_, a)| **a).map(|(n, _)| n.as_str()).collect();
                if e.repeats {
                    format!(
                        "{}: repeats (added in {}; pooled p {:.1e}, the recordings agree): a property of the sensor, added",
                        e.effect,
                        seen.join(", "),
                        e.pooled_p
                    )
                } else if !e.agree {
                    format!(
                        "{}: in {} only, the recordings disagree on its size: not added",
                        e.effect,
                        seen.join(", ")
                    )
                } else {
                    format!(
                        "{}: in {} only, pooled it is not significant (p {:.1e}): not added",
                        e.effect,
                        seen.join(", "),
                        e.pooled_p
                    )
                }
            })
            .collect()
    }
}

/// Audit each of `recs` (named `names`) with its own calibration `cals`,
/// then compare the effects across them and add those that repeat to
/// `pooled` (the sensor's calibration from the same recordings);
/// `progress` gets each recording's messages, prefixed with its name.
pub fn audit_recordings(
    recs: &[ImuRecording],
    cals: &[ImuCalibration],
    names: &[String],
    pooled: &ImuCalibration,
    opts: &AuditOptions,
    progress: &mut dyn FnMut(&str),
) -> Result<RecordingsAudit, AuditError> {
    if recs.len() < 2 || cals.len() != recs.len() || names.len() != recs.len() {
        return Err(AuditError(format!(
            "a joint audit takes several recordings, each with its calibration and name: {} recordings, {} \
             calibrations, {} names",
            recs.len(),
            cals.len(),
            names.len()
        )));
    }
    let mut each = Vec::new();
    for ((rec, cal), name) in recs.iter().zip(cals).zip(names) {
        let audit = audit_with_progress(rec, cal, opts, &mut |m| progress(&format!("{name}: {m}")))
            .map_err(|e| AuditError(format!("{name}: {}", e.0)))?;
        each.push(audit);
    }
    let effects: Vec<EffectAcross> = effects_found(&each).into_iter().map(|e| across(e, &each, opts.alpha)).collect();
    let mut calibration = pooled.clone();
    let repeating: Vec<EffectTerm> = effects.iter().filter(|e| e.repeats).map(pooled_term).collect();
    if !repeating.is_empty() {
        let reference = each.iter().find_map(|a| a.calibration.effects.as_ref());
        calibration.effects = Some(ModelEffects {
            reference_temperature_c: reference.map_or(25.0, |r| r.reference_temperature_c),
            reference_time_s: reference.map_or(0.0, |r| r.reference_time_s),
            effects: repeating,
        });
    }
    Ok(RecordingsAudit { names: names.to_vec(), each, effects, calibration })
}

/// Every effect an audit added, in the order first found.
fn effects_found(each: &[Audit]) -> Vec<Effect> {
    let mut found: Vec<Effect> = Vec::new();
    for e in each.iter().flat_map(Audit::effects_added) {
        if !found.contains(&e) {
            found.push(e);
        }
    }
    found
}

/// One recording's coefficients of `effect` with their σ: the final
/// model's where it was added, the last round's fit where it was not.
fn coefficients(a: &Audit, effect: Effect) -> Option<(Vec<f64>, Vec<f64>)> {
    let names = effect.param_names();
    if let Some(term) = a.calibration.effects.as_ref().and_then(|m| m.effects.iter().find(|t| t.id == effect.id())) {
        let get = |map: &std::collections::BTreeMap<String, f64>| {
            names.iter().map(|n| map.get(*n).copied().unwrap_or(f64::NAN)).collect::<Vec<_>>()
        };
        return Some((get(&term.params), get(&term.std)));
    }
    a.last_round.iter().find(|c| c.effect == effect.id()).map(|c| (c.params.clone(), c.params_std.clone()))
}

/// `effect` across the recordings: pooled per coefficient, tested.
fn across(effect: Effect, each: &[Audit], alpha: f64) -> EffectAcross {
    let per: Vec<Option<(Vec<f64>, Vec<f64>)>> = each.iter().map(|a| coefficients(a, effect)).collect();
    let parameters: Vec<Consensus> = effect
        .param_names()
        .iter()
        .enumerate()
        .map(|(j, p)| {
            let estimates: Vec<(f64, f64)> =
                per.iter().map(|c| c.as_ref().map_or((f64::NAN, f64::NAN), |(v, s)| (v[j], s[j]))).collect();
            Consensus::new(format!("{} {p}", effect.id()), "", &estimates)
        })
        .collect();
    let check = RecordingsCheck { recordings: Vec::new(), parameters };
    let agree = check.disagreements().is_empty();
    let parameters = check.parameters;
    let wald: f64 = parameters.iter().map(|c| (c.value / c.sigma).powi(2)).filter(|x| x.is_finite()).sum();
    let pooled_p = ChiSquared::new(parameters.len().max(1) as f64).map_or(1.0, |c| 1.0 - c.cdf(wald));
    EffectAcross {
        effect: effect.id().to_string(),
        added_in: each.iter().map(|a| a.effects_added().contains(&effect)).collect(),
        repeats: agree && pooled_p < alpha,
        agree,
        pooled_p,
        parameters,
    }
}

/// The pooled coefficients of an effect as a calibration term.
fn pooled_term(e: &EffectAcross) -> EffectTerm {
    let effect = Effect::from_id(&e.effect).expect("effects come from the vocabulary");
    let values: Vec<f64> = e.parameters.iter().map(|c| c.value).collect();
    let std: Vec<f64> = e.parameters.iter().map(|c| c.sigma).collect();
    EffectTerm::new(effect, &values, Some(&std))
}

/// `audit.json` of a joint audit.
#[derive(Serialize)]
struct JointOutput<'a> {
    recordings: &'a [String],
    effects: &'a [EffectAcross],
    verdict: Vec<String>,
}

impl RecordingsAudit {
    /// `audit_recordings.md`: each effect's coefficients per recording and pooled, and whether it repeats.
    pub fn markdown(&self) -> String {
        let mut s = String::from("# One sensor, several recordings: the audit\n\n");
        for line in self.verdict_lines() {
            s.push_str(&format!("- {line}\n"));
        }
        s.push_str("\n| coefficient | ");
        s.push_str(&self.names.iter().map(|n| format!("{n} |")).collect::<Vec<_>>().join(" "));
        s.push_str(" pooled | p (recordings agree) |\n|---|");
        s.push_str(&"---|".repeat(self.names.len() + 2));
        s.push('\n');
        for e in &self.effects {
            for c in &e.parameters {
                s.push_str(&format!("| {} |", c.parameter));
                for r in 0..c.values.len() {
                    let added = if e.added_in[r] { " (added)" } else { "" };
                    s.push_str(&format!(" {}{added} |", c.estimate_text(r)));
                }
                s.push_str(&format!(" {:.3e} ± {:.1e} | {:.2} |\n", c.value, c.sigma, c.p_value));
            }
        }
        s
    }

    /// Write `calibration.json` (the pooled calibration with the effects
    /// that repeat), `audit.json`, `audit_recordings.md` and each
    /// recording's audit in a folder of its own (`folders`, in order) into
    /// `dir`; returns the files written.
    pub fn write(&self, folders: &[String], dir: &std::path::Path) -> Result<Vec<String>, AuditError> {
        let written = crate::io::staging::write_staged(dir, |stage| -> Result<Vec<std::path::PathBuf>, AuditError> {
            let file = crate::model::calibration::CalibrationFile::from(&self.calibration);
            let out = JointOutput { recordings: &self.names, effects: &self.effects, verdict: self.verdict_lines() };
            let mut names = vec![
                put_file(stage, "calibration.json", serde_json::to_string_pretty(&file).unwrap_or_default())?,
                put_file(stage, "audit.json", serde_json::to_string_pretty(&out).unwrap_or_default())?,
                put_file(stage, "audit_recordings.md", self.markdown())?,
            ];
            for (a, folder) in self.each.iter().zip(folders) {
                let sub = stage.join(folder);
                std::fs::create_dir_all(&sub).map_err(|e| AuditError(format!("{}: {e}", sub.display())))?;
                names.extend(write_unstaged(a, &sub)?.iter().map(|n| format!("{folder}/{n}")));
            }
            Ok(names.iter().map(|n| stage.join(n)).collect())
        })?;
        Ok(written.iter().map(|p| p.strip_prefix(dir).unwrap_or(p).display().to_string()).collect())
    }
}

//! Audit outputs: `audit.json`, `audit.md`, `calibration.json` with the
//! effects, and the figures (`audit_gap.png`, one `audit_<effect>.png` per
//! effect added: residuals before and after against the effect's regressor).

use super::fit::{self, Fit};
use super::AuditError;
use super::{Audit, CandidateScore, Effect, BOUND_SIGMAS};
use crate::plot::{ScatterChart, Series, AXIS_COLORS};
use plotters::style::RGBColor;
use std::fmt::Write as _;
use std::path::Path;

/// One entry of `audit.json`'s `iterations`: the effect, its parameters by
/// name with their σ, its score (ΔBIC), p-value, F, the gaps and every candidate's score.
pub fn iteration_json(
    effect: Effect,
    score: &CandidateScore,
    gap_before: f64,
    gap_after: f64,
    candidates: &[CandidateScore],
) -> serde_json::Value {
    use serde_json::json;
    let named = |v: &[f64]| -> serde_json::Map<String, serde_json::Value> {
        effect.param_names().iter().zip(v).map(|(n, x)| (n.to_string(), json!(x))).collect()
    };
    json!({
        "effect": effect.id(),
        "family": effect.family(),
        "form": effect.form(),
        "params": named(&score.params),
        "params_std": named(&score.params_std),
        "score": score.delta_bic,
        "p_value": score.p_value,
        "f": score.f,
        "gap_before": gap_before,
        "gap_after": gap_after,
        "candidates": candidates,
    })
}

/// `audit.json` in the issue's layout (plus details).
pub fn json(a: &Audit) -> serde_json::Value {
    use serde_json::json;
    let iterations: Vec<serde_json::Value> = a
        .iterations
        .iter()
        .map(|it| {
            let mut j = iteration_json(it.effect, &it.score, it.gap_before, it.gap_after, &it.candidates);
            j["form_determined"] = json!(it.form_determined());
            j["other_forms"] = it.other_forms.iter().map(|(e, b)| json!({"effect": e.id(), "delta_bic": b})).collect();
            j["confounded_with"] = it.confounded_with.iter().map(|e| json!(e.id())).collect();
            j["description"] = json!(it.describe());
            j
        })
        .collect();
    let fit = a.final_fit();
    let groups: serde_json::Map<String, serde_json::Value> = fit::GROUPS
        .iter()
        .enumerate()
        .map(|(i, g)| (g.to_string(), json!({"chi2": fit.chi2_groups[i], "residuals": fit.dims[i]})))
        .collect();
    json!({
        "iterations": iterations,
        "effects_added": a.effects_added().iter().map(|e| e.id()).collect::<Vec<_>>(),
        "initial_gap": a.base.gap(),
        "final_gap": fit.gap(),
        "final_chi2_per_dof": fit.chi2() / fit.dof() as f64,
        "final_gap_p_value": fit.p_value(),
        "structure": a.structure,
        "within_intervals": a.data.within,
        "random_walk_estimated": a.walks_estimated,
        "random_walk_degrees_of_freedom": a.walk_degrees_of_freedom,
        "final_groups": groups,
        "last_round": a.last_round,
        "bounds": a.bounds(),
        "static_intervals": a.data.statics.len(),
        "motions": a.data.motions.len(),
        "random_walk_raw": {"gyro": a.random_walk().0, "accel": a.random_walk().1},
        "random_walk_raw_axes": {"gyro": a.random_walk_axes.0, "accel": a.random_walk_axes.1},
        "verdict": a.verdict(),
        "notes": a.notes,
    })
}

/// The terminal summary: gap per step and the scores of each round.
pub fn summary_table(a: &Audit) -> String {
    let mut s = String::new();
    let b = &a.base;
    let _ = writeln!(
        s,
        "{} static intervals, {} motions; calibration as given: χ²/dof {:.3} (gap {:.3})",
        a.data.statics.len(),
        a.data.motions.len(),
        b.chi2() / b.dof() as f64,
        b.gap()
    );
    let round = |s: &mut String, scores: &[super::CandidateScore]| {
        let w = scores.iter().map(|c| c.effect.len()).max().unwrap_or(0).max("candidate".len());
        let _ = writeln!(
            s,
            "  {:<w$} {:>4} {:>10} {:>10} {:>10} {:>10} {:>8}",
            "candidate", "dof", "Δχ²", "Wald", "ΔBIC", "p", "gap"
        );
        for c in scores {
            let _ = writeln!(
                s,
                "  {:<w$} {:>4} {:>10.1} {:>10.1} {:>10.1} {:>10.2e} {:>8.3}{}",
                c.effect,
                c.dof_added,
                c.delta_chi2,
                c.wald,
                c.delta_bic,
                c.p_value,
                c.gap,
                if c.significant {
                    "  *"
                } else if !c.testable {
                    "  (not testable: Δχ² and Wald disagree)"
                } else {
                    ""
                }
            );
        }
    };
    for (i, it) in a.iterations.iter().enumerate() {
        let _ = writeln!(s, "round {}: added {} — gap {:.3} → {:.3}", i + 1, it.effect, it.gap_before, it.gap_after);
        round(&mut s, &it.candidates);
    }
    if !a.last_round.is_empty() {
        let _ = writeln!(s, "round {}: nothing significant", a.iterations.len() + 1);
        round(&mut s, &a.last_round);
    }
    let f = a.final_fit();
    let _ = writeln!(
        s,
        "left: χ²/dof {:.3} (gap {:.3}, p {:.1e}); structure of the residuals left:",
        f.chi2() / f.dof() as f64,
        f.gap(),
        f.p_value()
    );
    let _ = writeln!(s, "  {:<18} {:<20} {:>5} {:>9} {:>10} {:>8}", "residual", "against", "dof", "T", "p", "share");
    for t in &a.structure {
        let _ = writeln!(
            s,
            "  {:<18} {:<20} {:>5} {:>9.1} {:>10.2e} {:>7.0}%{}",
            t.residual,
            t.regressor,
            t.dof,
            t.statistic,
            t.p_value,
            100.0 * t.share_of_gap,
            if t.significant { "  *" } else { "" }
        );
    }
    let unsettled = crate::calib::detect::unsettled(&a.data.within, a.alpha);
    for w in &a.data.within {
        let _ = writeln!(
            s,
            "  {:<18} {:<20} {:>5} {:>9.1} {:>10.2e} {:>8}{}",
            w.reading,
            "halves of intervals",
            w.intervals,
            w.ratio * w.intervals as f64,
            w.p_value,
            "",
            if unsettled.contains(&w) { "  *" } else { "" }
        );
    }
    s
}

/// Write `text` to `dir/name` (creating `dir`); the name back, or an error naming the file.
pub(super) fn put_file(dir: &Path, name: &str, text: String) -> Result<String, AuditError> {
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let p = dir.join(name);
    std::fs::write(&p, text).map_err(|e| format!("{}: {e}", p.display()))?;
    Ok(name.to_string())
}

/// Write `audit.json`, `calibration.json` (with the effects), `audit.md` and the figures into `dir`.
pub fn write(a: &Audit, dir: &Path) -> Result<Vec<String>, AuditError> {
    let paths = crate::io::staging::write_staged(dir, |stage| {
        write_unstaged(a, stage).map(|names| names.iter().map(|n| stage.join(n)).collect::<Vec<_>>())
    })?;
    Ok(paths.iter().filter_map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned())).collect())
}

pub(super) fn write_unstaged(a: &Audit, dir: &Path) -> Result<Vec<String>, AuditError> {
    let put = |name: &str, text: String| put_file(dir, name, text);
    let mut written = vec![put("audit.json", serde_json::to_string_pretty(&json(a)).map_err(|e| e.to_string())?)?];
    let file = crate::model::calibration::CalibrationFile::from(&a.calibration);
    written.push(put("calibration.json", serde_json::to_string_pretty(&file).map_err(|e| e.to_string())?)?);
    let mut figures = vec![gap_figure(a, &dir.join("audit_gap.png"))?];
    let mut prev = &a.base;
    for it in &a.iterations {
        let name = format!("audit_{}.png", it.effect.id());
        figures.push(effect_figure(a, prev, &it.fit, it.effect, &dir.join(&name)).map(|_| name)?);
        prev = &it.fit;
    }
    written.push(put("audit.md", markdown(a, &figures))?);
    written.extend(figures);
    Ok(written)
}

fn gap_figure(a: &Audit, path: &Path) -> Result<String, AuditError> {
    let mut pts = vec![(0.0, a.base.gap())];
    pts.extend(a.iterations.iter().enumerate().map(|(i, it)| ((i + 1) as f64, it.gap_after)));
    let labels: Vec<String> =
        std::iter::once("as given".to_string()).chain(a.iterations.iter().map(|i| format!("+{}", i.effect))).collect();
    ScatterChart {
        title: format!("Gap χ²/dof − 1 per step: {}", labels.join(" → ")),
        x_label: "effects added".into(),
        y_label: "gap".into(),
        series: vec![
            Series { label: String::new(), color: RGBColor(90, 90, 90), points: pts.clone(), line: true },
            Series { label: "gap".into(), color: AXIS_COLORS[2], points: pts, line: false },
        ],
        ..Default::default()
    }
    .write_png(path, 900, 500)?;
    Ok("audit_gap.png".into())
}

/// Residuals before (previous model) and after adding `effect`, against its regressor.
fn effect_figure(a: &Audit, prev: &Fit, next: &Fit, effect: Effect, path: &Path) -> Result<(), AuditError> {
    let data = &a.data;
    let before = fit::residuals(data, &prev.layout, &prev.values)?;
    let j = next.layout.effects.len() - 1;
    let mut with_values = prev.values.clone();
    with_values.insert_dyn(fit::key_effect(j), Box::new(tumble_solvers::DynVector::from_slice(&next.effect(j))));
    let explained = fit::residuals(data, &next.layout, &with_values)?;
    let after = fit::residuals(data, &next.layout, &next.values)?;
    // Per group: (component names, rows before/explained/after, regressor per row).
    let flat = |r: &fit::Residuals, comps: std::ops::Range<usize>, rot: bool| -> Vec<Vec<f64>> {
        if rot {
            r.1.iter().map(|x| comps.clone().map(|c| x[c]).collect()).collect()
        } else {
            r.0.iter().map(|x| comps.clone().map(|c| x[c]).collect()).collect()
        }
    };
    let groups =
        [("‖a‖ − g [m/s²]", 0..1, false), ("static rate [rad/s]", 1..4, false), ("rotation error [rad]", 0..2, true)];
    // The group the effect explains the largest fraction of.
    let share = |(_, comps, rot): &(&str, std::ops::Range<usize>, bool)| {
        let b = flat(&before, comps.clone(), *rot);
        let e = flat(&explained, comps.clone(), *rot);
        let num: f64 = b.iter().zip(&e).flat_map(|(x, y)| x.iter().zip(y).map(|(p, q)| (p - q).powi(2))).sum();
        let den: f64 = b.iter().flatten().map(|x| x * x).sum::<f64>().max(1e-300);
        num / den
    };
    let (label, comps, rot) =
        groups.iter().max_by(|x, y| share(x).total_cmp(&share(y))).cloned().unwrap_or(groups[1].clone());
    let (b, e, f) =
        (flat(&before, comps.clone(), rot), flat(&explained, comps.clone(), rot), flat(&after, comps.clone(), rot));
    let context = |i: usize| {
        if rot {
            let c = &data.motions[i].context;
            let n = c.len().max(1) as f64;
            (c.iter().map(|x| x.dtemp).sum::<f64>() / n, c.iter().map(|x| x.time).sum::<f64>() / n)
        } else {
            (data.statics[i].context.dtemp, data.statics[i].context.time)
        }
    };
    let (x_label, x_of): (String, Box<dyn Fn(usize, usize) -> f64>) = match effect {
        e if e.needs_temperature() => {
            ("temperature [°C]".into(), Box::new(|i, _| context(i).0 + data.reference_temperature))
        }
        Effect::BiasDrift => ("time [s]".into(), Box::new(|i, _| context(i).1 + data.reference_time)),
        _ => (format!("{effect} predicted contribution"), Box::new(|i, c| b[i][c] - e[i][c])),
    };
    let names = if comps.len() == 3 { ["x", "y", "z"] } else { ["1", "2", "3"] };
    let mut series = Vec::new();
    for c in 0..comps.len() {
        let color = AXIS_COLORS[c % 3];
        let light = RGBColor(
            ((color.0 as u16 + 2 * 255) / 3) as u8,
            ((color.1 as u16 + 2 * 255) / 3) as u8,
            ((color.2 as u16 + 2 * 255) / 3) as u8,
        );
        series.push(Series {
            label: format!("{} before", names[c]),
            color: light,
            points: (0..b.len()).map(|i| (x_of(i, c), b[i][c])).collect(),
            line: false,
        });
    }
    for c in 0..comps.len() {
        series.push(Series {
            label: format!("{} after", names[c]),
            color: AXIS_COLORS[c % 3],
            points: (0..f.len()).map(|i| (x_of(i, c), f[i][c])).collect(),
            line: false,
        });
    }
    ScatterChart {
        title: format!("{label}: before and after adding {effect}"),
        x_label,
        y_label: label.into(),
        series,
        ..Default::default()
    }
    .write_png(path, 900, 560)?;
    Ok(())
}

fn markdown(a: &Audit, figures: &[String]) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "# Model-discrepancy audit\n\n**{}**\n", a.verdict());
    let _ = writeln!(
        s,
        "{} static intervals and {} motions compared. The gap is χ²/dof − 1 of the whitened residuals \
         (0 when the noise explains them).\n",
        a.data.statics.len(),
        a.data.motions.len()
    );
    let _ = writeln!(s, "| step | effect | ΔBIC | p-value | gap before | gap after |\n|---|---|---|---|---|---|");
    for (i, it) in a.iterations.iter().enumerate() {
        let _ = writeln!(
            s,
            "| {} | `{}` | {:.1} | {:.2e} | {:.3} | {:.3} |",
            i + 1,
            it.effect,
            it.score.delta_bic,
            it.score.p_value,
            it.gap_before,
            it.gap_after
        );
    }
    if a.iterations.is_empty() {
        let _ = writeln!(s, "| – | none | | | {:.3} | {:.3} |", a.base.gap(), a.base.gap());
    }
    for it in &a.iterations {
        let _ = writeln!(s, "\n## `{}`: {}\n\n| parameter | value | std |\n|---|---|---|", it.effect, it.describe());
        for ((n, v), sd) in it.effect.param_names().iter().zip(&it.score.params).zip(&it.score.params_std) {
            let _ = writeln!(s, "| {n} | {v:.4e} | {sd:.1e} |");
        }
    }
    let bounds = a.bounds();
    if !bounds.is_empty() {
        let _ = writeln!(
            s,
            "\n## What the recording bounds\n\nThe effects not added, fitted against the final model: each \
             parameter's estimate and the size it is below with 95 % confidence (|value| + {BOUND_SIGMAS} σ), in \
             the calibrated frame{}.\n\n| effect | parameter | value | std | below | unit |\n|---|---|---|---|---|---|",
            if a.walks_undetermined().is_some() {
                "; the walks are not determined by this recording, and the bounds on slow drifts rest on them"
            } else {
                ""
            }
        );
        for b in &bounds {
            let _ = writeln!(
                s,
                "| `{}` | {} | {:.3e} | {:.1e} | {:.2e} | {} |",
                b.effect, b.parameter, b.value, b.std, b.bound, b.unit
            );
        }
    }
    let _ = writeln!(s, "\n## Scores\n\n```text\n{}```\n", summary_table(a));
    for f in figures {
        let _ = writeln!(s, "![{f}]({f})\n");
    }
    if !a.notes.is_empty() {
        let _ = writeln!(s, "## Notes\n");
        for n in &a.notes {
            let _ = writeln!(s, "- {n}");
        }
    }
    s
}

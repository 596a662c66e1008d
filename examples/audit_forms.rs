//! The audit on simulated hand tumbles with every form of every effect
//! family hidden, sized per seed, with and without a noise file: one table.
//!
//! `cargo run --release --example audit_forms -- [--seeds N] [--first-seed S] [--mode file|estimated|both] [CASE ...]`
//! (cases: `--list`; default every case, 10 seeds, 20 for the clean one, both modes).

use rayon::prelude::*;
use tumble::audit::trials::{run_trial, same_form, Case, Expect, NoiseMode, Trial};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut seeds = 10u64;
    let mut first = 100u64;
    let mut modes = vec![NoiseMode::File, NoiseMode::Estimated];
    let mut names = Vec::new();
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let mut value = |what: &str| args.next().ok_or_else(|| format!("{a} needs {what}"));
        match a.as_str() {
            "--seeds" => seeds = value("a count")?.parse()?,
            "--first-seed" => first = value("a seed")?.parse()?,
            "--mode" => {
                modes = match value("file, estimated or both")?.as_str() {
                    "file" => vec![NoiseMode::File],
                    "estimated" => vec![NoiseMode::Estimated],
                    "both" => vec![NoiseMode::File, NoiseMode::Estimated],
                    m => return Err(format!("--mode: unknown `{m}` (file, estimated or both)").into()),
                }
            }
            "--list" => {
                for c in Case::all() {
                    println!("{}", c.name);
                }
                return Ok(());
            }
            name => names.push(name.to_string()),
        }
    }
    let cases: Vec<Case> =
        Case::all().into_iter().filter(|c| names.is_empty() || names.iter().any(|n| n == c.name)).collect();
    if cases.is_empty() {
        return Err(format!("no case named {names:?} (see --list)").into());
    }
    println!(
        "| case | sizes | noise | passed | named first (family, form) | of which the form determined (exactly) | gap before | gap of the clean recording | \
         shrink (min–median) | shrink of the effect's gap (min–median) |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|");
    for case in &cases {
        for &mode in &modes {
            let n = if case.expect == Expect::Nothing { 2 * seeds } else { seeds };
            let t0 = std::time::Instant::now();
            let trials: Vec<Result<Trial, tumble::audit::AuditError>> =
                (first..first + n).into_par_iter().map(|s| run_trial(case, s, mode)).collect();
            let ok: Vec<&Trial> = trials.iter().filter_map(|t| t.as_ref().ok()).collect();
            for (s, t) in (first..).zip(&trials) {
                match t {
                    Ok(t) if !t.passed => eprintln!("{} {mode:?} seed {s}: {}", case.name, t.verdict),
                    Err(e) => eprintln!("{} {mode:?} seed {s}: error {e}", case.name),
                    _ => {}
                }
            }
            let passed = ok.iter().filter(|t| t.passed).count();
            let named = ok
                .iter()
                .filter(|t| match &case.expect {
                    Expect::First(e) => t.found.first().is_some_and(|f| same_form(*f, *e)),
                    _ => t.passed,
                })
                .count();
            let determined = ok
                .iter()
                .filter(|t| match &case.expect {
                    Expect::First(e) => t.found.first() == Some(e) && t.form_determined,
                    _ => false,
                })
                .count();
            let determined_s =
                if matches!(case.expect, Expect::First(_)) { format!("{determined}/{named}") } else { "–".into() };
            let sizes =
                case.hidden
                    .iter()
                    .map(|(h, lo, hi)| {
                        if h.contains("_nonlinearity_") {
                            format!("{lo}–{hi} % FS")
                        } else {
                            format!("×{lo}–{hi}")
                        }
                    })
                    .collect::<Vec<_>>()
                    .join(", ");
            let range = |v: Vec<f64>| {
                let v: Vec<f64> = v.into_iter().filter(|x| x.is_finite()).collect();
                v.iter().fold((f64::MAX, f64::MIN), |(a, b), &x| (a.min(x), b.max(x)))
            };
            let min_median = |mut v: Vec<f64>| {
                v.sort_by(f64::total_cmp);
                if matches!(case.expect, Expect::Nothing) || v.is_empty() {
                    "–".to_string()
                } else {
                    format!("{:.0}–{:.0} %", 100.0 * v[0], 100.0 * v[v.len() / 2])
                }
            };
            let gap = range(ok.iter().map(|t| t.gaps.0).collect());
            let clean = range(ok.iter().filter_map(|t| t.gap_clean).collect());
            let clean_s = if clean.0 <= clean.1 { format!("{:.2}–{:.2}", clean.0, clean.1) } else { "–".into() };
            println!(
                "| {} | {} | {} | {passed}/{n} | {named}/{n} | {determined_s} | {:.2}–{:.2} | {clean_s} | {} | {} |",
                case.name,
                if sizes.is_empty() { "–".into() } else { sizes },
                if mode == NoiseMode::File { "file" } else { "estimated" },
                gap.0,
                gap.1,
                min_median(ok.iter().map(|t| t.shrink).collect()),
                min_median(ok.iter().map(|t| t.shrink_of_effect).collect()),
            );
            eprintln!("  ({} in {:.0} s)", case.name, t0.elapsed().as_secs_f64());
        }
    }
    Ok(())
}

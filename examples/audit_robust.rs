//! The audit on hand tumbles unlike the trials' (`audit_forms`): other sample
//! rates, hold lengths, turn speeds, noise levels and an axis-aligned
//! (box-on-its-faces) protocol, each on seeds 200–205 with and without a
//! noise file. A recording another user makes differs from the trials in
//! exactly these ways; a clean one must get nothing added and a hidden
//! effect must still be found.
//!
//! ```sh
//! cargo run --release --example audit_robust -- clean axis slow
//! cargo run --release --example audit_robust -- g_sensitivity 100hz noise3
//! cargo run --release --example audit_robust -- --list
//! ```
//! The first argument is a case of [`Case::all`]; the others are variants.
use rayon::prelude::*;
use tumble::audit::trials::{config, Case, Expect, NoiseMode};
use tumble::audit::Effect;
use tumble::audit::{audit, AuditOptions};
use tumble::calib::{calibrate, CalibOptions};
use tumble::io::ImuNoise;
use tumble::sim::{simulate, Scenario, SimConfig};

/// A variant: name, what it changes, and the change.
type Variant = (&'static str, &'static str, fn(&mut SimConfig));

/// Every variant.
const VARIANTS: [Variant; 12] = [
    ("base", "the trials' own settings", |_| {}),
    ("100hz", "sampled at 100 Hz", |c| c.imu.rate_hz = 100.0),
    ("400hz", "sampled at 400 Hz", |c| c.imu.rate_hz = 400.0),
    ("poses25", "25 poses instead of 50", |c| c.tumble.poses = 25),
    ("poses80", "80 poses", |c| c.tumble.poses = 80),
    ("long_holds", "holds of 4–8 s", |c| c.tumble.hold_s = [4.0, 8.0]),
    ("short_holds", "holds of 1–1.5 s", |c| c.tumble.hold_s = [1.0, 1.5]),
    ("rest10", "a 10 s initial rest", |c| c.tumble.initial_static_s = 10.0),
    ("fast", "turns at 3 rad/s on average", |c| c.tumble.turn_rate = 3.0),
    ("slow", "turns at 0.5 rad/s on average", |c| c.tumble.turn_rate = 0.5),
    ("noise3", "3× the noise, walk and instability", |c| {
        for t in [&mut c.imu.gyro, &mut c.imu.accel] {
            for v in [&mut t.noise_density, &mut t.random_walk, &mut t.bias_instability] {
                v.iter_mut().for_each(|x| *x *= 3.0);
            }
        }
    }),
    ("axis", "quarter turns about the body axes (an IMU in a box laid on each face)", |c| c.tumble.axis_aligned = true),
];

fn main() -> Result<(), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let cases = Case::all();
    if args.is_empty() || args[0] == "--list" {
        println!("usage: audit_robust CASE VARIANT…");
        println!("cases: {}", cases.iter().map(|c| c.name).collect::<Vec<_>>().join(", "));
        for (name, what, _) in VARIANTS {
            println!("  {name:12} {what}");
        }
        return Ok(());
    }
    let case = cases.iter().find(|c| c.name == args[0]).ok_or(format!("no case named `{}` (see --list)", args[0]))?;
    println!("| case | variant | noise | nothing added | hidden effect named first | seeds with something else |");
    println!("|---|---|---|---|---|---|");
    for v in &args[1..] {
        let (_, _, change) =
            VARIANTS.iter().find(|x| x.0 == v.as_str()).ok_or(format!("no variant named `{v}` (see --list)"))?;
        for mode in [NoiseMode::File, NoiseMode::Estimated] {
            let seeds: Vec<u64> = (200..206).collect();
            let found: Vec<Result<Vec<Effect>, String>> = seeds
                .par_iter()
                .map(|&seed| {
                    let (mut cfg, _, _) = config(case, seed).map_err(|e| e.to_string())?;
                    change(&mut cfg);
                    let rec = simulate(Scenario::Tumble, &cfg, seed).map_err(|e| e.to_string())?.imu.to_recording();
                    let cal = calibrate(&rec, &CalibOptions { gravity: cfg.gravity, ..Default::default() })
                        .map_err(|e| format!("seed {seed}: {}", e.message))?;
                    let noise = (mode == NoiseMode::File).then(|| ImuNoise::from_model(&cfg.imu));
                    let a = audit(&rec, &cal.calibration, &AuditOptions { noise, ..Default::default() })
                        .map_err(|e| format!("seed {seed}: {}", e.0))?;
                    Ok(a.effects_added())
                })
                .collect();
            // The family of the effect hidden first (the case's expectation).
            let wanted = match &case.expect {
                Expect::First(e) | Expect::Confounded(e, _) => Some(e.family()),
                Expect::All(es) => es.first().map(|e| e.family()),
                Expect::Nothing => None,
            };
            let first_is_hidden = |f: &[Effect]| f.first().is_some_and(|e| Some(e.family()) == wanted);
            let nothing = found.iter().filter(|f| f.as_ref().is_ok_and(|f| f.is_empty())).count();
            let named = found.iter().filter(|f| f.as_ref().is_ok_and(|f| first_is_hidden(f))).count();
            let other: Vec<String> = found
                .iter()
                .zip(&seeds)
                .filter_map(|(f, s)| match f {
                    Ok(f) if !f.is_empty() && !first_is_hidden(f) => {
                        Some(format!("{s}: {}", f.iter().map(|e| e.to_string()).collect::<Vec<_>>().join(" + ")))
                    }
                    Err(e) => Some(e.clone()),
                    _ => None,
                })
                .collect();
            let n = seeds.len();
            println!(
                "| {} | {v} | {} | {nothing}/{n} | {} | {} |",
                case.name,
                if mode == NoiseMode::File { "file" } else { "estimated" },
                if wanted.is_none() { "—".to_string() } else { format!("{named}/{n}") },
                if other.is_empty() { "—".to_string() } else { other.join("; ") },
            );
        }
    }
    Ok(())
}

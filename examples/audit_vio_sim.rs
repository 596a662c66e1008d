//! The VIO audit on a simulated walk with a hidden time offset, over seeds:
//! `cargo run --example audit_vio_sim -- camera_imu_time_offset 1 3 20`
//! (effect from `tumble sim --hide`'s names or `none`, strength, seeds, walk
//! seconds, features per frame). Several effects hide together when joined by
//! `+` (`camera_imu_time_offset+accel_gyro_time_offset`): a seed counts when
//! the audit adds every one of them and nothing else. `NAME:S` gives one effect
//! its own strength (`camera_imu_time_offset:1+accel_gyro_time_offset:2`, as
//! `tumble sim --hide` takes it).

use tumble::audit::vio::{audit_vio, VioAuditOptions};
use tumble::sim::{hide_effect, simulate, Scenario, SimConfig};
use tumble::vio::{VioInput, VioOptions};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let effect = args.first().map(String::as_str).unwrap_or("camera_imu_time_offset");
    let strength: f64 = args.get(1).map_or(Ok(1.0), |s| s.parse()).map_err(|e| format!("strength: {e}"))?;
    let seeds: u64 = args.get(2).map_or(Ok(3), |s| s.parse()).map_err(|e| format!("seeds: {e}"))?;
    let duration: f64 = args.get(3).map_or(Ok(40.0), |s| s.parse()).map_err(|e| format!("duration: {e}"))?;
    let features: usize = args.get(4).map_or(Ok(150), |s| s.parse()).map_err(|e| format!("features: {e}"))?;
    let mut hidden: Vec<&str> = effect.split('+').map(|e| e.split(':').next().unwrap_or(e)).collect();
    hidden.sort_unstable();
    let (mut first, mut shrunk, mut added_any) = (0, 0, 0);
    for seed in 0..seeds {
        let mut cfg = SimConfig { duration_s: Some(duration), ..SimConfig::default() };
        cfg.camera.max_features = features;
        for e in effect.split('+') {
            let (name, s) = match e.split_once(':') {
                Some((n, s)) => (n, s.parse().map_err(|err| format!("strength of {n}: {err}"))?),
                None => (e, strength),
            };
            hide_effect(&mut cfg, name, s)?;
        }
        let sim = simulate(Scenario::Walk, &cfg, 500 + seed)?;
        let input = VioInput::from_simulation(&sim)?;
        let opts = VioAuditOptions::new(VioOptions::for_simulation(&cfg));
        let t = std::time::Instant::now();
        let a = audit_vio(&input, &opts, None)?;
        println!("seed {seed}: {} ({:.1} s)", a.verdict(), t.elapsed().as_secs_f64());
        let added = a.effects_added();
        added_any += usize::from(!added.is_empty());
        let mut ids: Vec<&str> = added.iter().map(|e| e.id()).collect();
        let named = if hidden.len() > 1 {
            ids.sort_unstable();
            ids == hidden
        } else {
            ids.first() == hidden.first()
        };
        first += usize::from(named);
        let (g0, g1) = (a.base.gap(), a.final_tally.gap());
        shrunk += usize::from(g0 > 0.0 && g1 <= 0.2 * g0);
        for p in &a.profiles {
            let pts: Vec<String> = p.points.iter().map(|(x, c)| format!("{:+.1}ms:{:.4}", x * 1e3, c)).collect();
            println!("  {} round {}: {}", p.effect, p.round, pts.join(" "));
        }
        for s in a.iterations.iter().flat_map(|i| &i.candidates).chain(&a.last_round) {
            println!(
                "  {} {:+.2} ± {:.2} ms  Δχ² {:.1}  F {:.1}  p {:.1e}  ΔBIC {:.1}  gap {:.4}",
                s.effect,
                1e3 * s.params[0],
                1e3 * s.params_std[0],
                s.delta_chi2,
                s.f,
                s.p_value,
                s.delta_bic,
                s.gap
            );
        }
        println!("  base {:?}", a.base);
    }
    if effect == "none" {
        println!("{effect}: an effect added on {added_any} of {seeds} seeds");
    } else {
        println!(
            "{effect} (strength {strength}): {} on {first} of {seeds} seeds, gap ≥ 80 % smaller on {shrunk}",
            if hidden.len() > 1 { "all found (and nothing else)" } else { "named first" }
        );
    }
    Ok(())
}

//! Hide an effect in a simulated tumble recording, calibrate without it, and
//! let the audit find it: `cargo run --example audit_sim -- [effect] [seed] [strength]`
//! (effect: g_sensitivity, temperature_bias, temperature_scale, gyro_nonlinearity,
//! accel_nonlinearity, bias_drift or none).

use tumble::audit::{audit, AuditOptions};
use tumble::calib::{calibrate, CalibOptions};
use tumble::sim::{simulate, Scenario, SimConfig};
use tumble::vio::ImuNoise;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let effect = args.get(1).map(String::as_str).unwrap_or("g_sensitivity");
    let seed: u64 = args.get(2).map(|s| s.parse()).transpose()?.unwrap_or(1);
    let strength: f64 = args.get(3).map(|s| s.parse()).transpose()?.unwrap_or(1.0);
    let mut cfg = SimConfig::default();
    tumble::sim::hide_effect(&mut cfg, effect, strength)?;
    let sim = simulate(Scenario::Tumble, &cfg, seed)?;
    let rec = sim.imu.to_recording();
    let t0 = std::time::Instant::now();
    let cal = calibrate(&rec, &CalibOptions { gravity: cfg.gravity, ..Default::default() })?;
    let opts = AuditOptions { noise: Some(ImuNoise::from_model(&cfg.imu)), ..Default::default() };
    let result = audit(&rec, &cal.calibration, &opts)?;
    println!(
        "hidden: {effect}, seed {seed}, {:.1} s recording, {} static intervals",
        rec.duration(),
        result.data.statics.len()
    );
    let b = &result.base;
    println!("base: chi2/dof {:.3} groups {:?} dims {:?}", b.chi2() / b.dof() as f64, b.chi2_groups, b.dims);
    for it in &result.iterations {
        println!(
            "  + {} (ΔBIC {:.1}, p {:.2e}) gap {:.3} → {:.3}; params {:?}",
            it.effect, it.score.delta_bic, it.score.p_value, it.gap_before, it.gap_after, it.score.params
        );
        for c in &it.candidates {
            println!(
                "      {:<26} Δχ² {:9.1} ΔBIC {:9.1} p {:.2e} {}",
                c.effect,
                c.delta_chi2,
                c.delta_bic,
                c.p_value,
                if c.significant { "*" } else { "" }
            );
        }
    }
    for c in &result.last_round {
        println!(
            "   last: {:<26} Δχ² {:9.1} ΔBIC {:9.1} p {:.2e} {:?}",
            c.effect, c.delta_chi2, c.delta_bic, c.p_value, c.params
        );
    }
    println!("{}  ({:.1} s)", result.verdict(), t0.elapsed().as_secs_f64());
    Ok(())
}

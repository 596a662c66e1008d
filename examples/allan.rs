//! Noise identification on one simulated gyro axis with known truth:
//! overlapping Allan deviation, the IEEE read-offs and the weighted fit.
//!
//! ```sh
//! cargo run --example allan
//! ```

use tumble::allan::{allan_deviation, identify, AllanOptions, Coefficient};
use tumble::sim::{noise_series, AxisNoise};

fn main() {
    // Two hours at 200 Hz of a gyro axis: white noise, flicker floor, random walk.
    let truth = AxisNoise {
        noise_density: 1.0e-3,  // N [rad/s/√Hz]
        bias_instability: 3e-4, // B [rad/s]
        random_walk: 2e-5,      // K [rad/s/√s]
        bias_instability_band: [1e-3, 1e5],
        angle_quantization: 0.0, // Q [rad]
    };
    let rate = 200.0;
    let y = noise_series(&truth, rate, 2 * 3600 * 200, 1);
    let curve = allan_deviation(&y, 1.0 / rate, &AllanOptions::default()).expect("valid series");
    let id = identify(&curve).expect("enough τ");
    let show = |c: Option<Coefficient>| match c {
        Some(c) => format!("{:.3e} [{:.3e}, {:.3e}]", c.value, c.lo, c.hi),
        None => "not supported by the data".into(),
    };
    println!("{} τ from {:.3} s to {:.0} s", curve.tau.len(), curve.tau[0], curve.tau[curve.tau.len() - 1]);
    println!("N  truth {:.3e}  fit {}  read-off {}", truth.noise_density, show(id.fit.N), show(id.readoff.N));
    println!("B  truth {:.3e}  fit {}  read-off {}", truth.bias_instability, show(id.fit.B), show(id.readoff.B));
    println!("K  truth {:.3e}  fit {}  read-off {}", truth.random_walk, show(id.fit.K), show(id.readoff.K));
    for note in &id.notes {
        println!("note: {note}");
    }
}

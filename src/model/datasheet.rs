//! Datasheet noise figures → Kalibr's continuous-time `imu.yaml` (`tumble
//! noise`), each conversion explained: the unit confusion the VIO trackers'
//! issue threads are full of.
//!
//! | datasheet figure | unit examples | Kalibr key |
//! |---|---|---|
//! | angle random walk (ARW) | °/√h, °/s/√Hz, mdps/√Hz, rad/s/√Hz | `gyroscope_noise_density` \[rad/s/√Hz\] |
//! | velocity random walk / noise density | m/s/√h, µg/√Hz, mg/√Hz, m/s²/√Hz | `accelerometer_noise_density` \[m/s²/√Hz\] |
//! | rate random walk | °/h/√h, rad/s²/√Hz | `gyroscope_random_walk` \[rad/s²/√Hz\] |
//! | acceleration random walk | m/s/h^1.5 (= m/s²/√h), m/s³/√Hz | `accelerometer_random_walk` \[m/s³/√Hz\] |
//! | bias instability | °/h, °/s, µg, mg | (random walk when none is given) |
//!
//! A datasheet rarely gives the random walks. Without one, the bias
//! instability B stands in through [`super::noise::estimator_random_walk`]:
//! the random walk whose Allan deviation at τ = 10 s reaches the flicker
//! floor 0.664 B — what the estimator's window of seconds needs, and said so
//! in the file.

use super::noise::{estimator_random_walk, ImuNoise, ImuNoiseAxes, BIAS_INSTABILITY_MATCH_S};
use super::ModelError;
use std::f64::consts::PI;

const DEG: f64 = PI / 180.0;
/// Standard gravity \[m/s²\] (CGPM 1901): the g of datasheets' µg and mg.
const G0: f64 = 9.80665;

/// Which figure a value is (decides the units accepted).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Figure {
    /// Gyro angle random walk / noise density.
    GyroNoise,
    /// Accelerometer velocity random walk / noise density.
    AccelNoise,
    /// Gyro rate random walk.
    GyroWalk,
    /// Accelerometer acceleration random walk.
    AccelWalk,
    /// Gyro bias instability.
    GyroInstability,
    /// Accelerometer bias instability.
    AccelInstability,
}

impl Figure {
    fn name(self) -> &'static str {
        match self {
            Figure::GyroNoise => "gyro noise (ARW)",
            Figure::AccelNoise => "accelerometer noise (VRW)",
            Figure::GyroWalk => "gyro rate random walk",
            Figure::AccelWalk => "accelerometer random walk",
            Figure::GyroInstability => "gyro bias instability",
            Figure::AccelInstability => "accelerometer bias instability",
        }
    }
    /// (unit spellings, factor to SI, SI unit) accepted for this figure.
    fn units(self) -> &'static [(&'static [&'static str], f64, &'static str)] {
        const GN: &[(&[&str], f64, &str)] = &[
            (&["deg/sqrt(h)", "deg/rt(h)", "deg/√h", "°/√h", "°/sqrt(h)", "deg/sqrt(hr)"], DEG / 60.0, "rad/s/√Hz"),
            (&["deg/s/sqrt(Hz)", "dps/sqrt(Hz)", "°/s/√Hz", "deg/s/√Hz", "dps/√Hz"], DEG, "rad/s/√Hz"),
            (&["mdps/sqrt(Hz)", "mdps/√Hz"], DEG * 1e-3, "rad/s/√Hz"),
            (&["deg/h/sqrt(Hz)", "°/h/√Hz", "deg/hr/sqrt(Hz)"], DEG / 3600.0, "rad/s/√Hz"),
            (&["rad/s/sqrt(Hz)", "rad/s/√Hz"], 1.0, "rad/s/√Hz"),
        ];
        const AN: &[(&[&str], f64, &str)] = &[
            (&["m/s/sqrt(h)", "m/s/√h", "m/s/sqrt(hr)"], 1.0 / 60.0, "m/s²/√Hz"),
            (&["ug/sqrt(Hz)", "µg/√Hz", "µg/sqrt(Hz)", "ug/√Hz"], 1e-6 * G0, "m/s²/√Hz"),
            (&["mg/sqrt(Hz)", "mg/√Hz"], 1e-3 * G0, "m/s²/√Hz"),
            (&["m/s^2/sqrt(Hz)", "m/s2/sqrt(Hz)", "m/s²/√Hz"], 1.0, "m/s²/√Hz"),
        ];
        const GW: &[(&[&str], f64, &str)] = &[
            (&["deg/h/sqrt(h)", "deg/h^1.5", "°/h/√h", "deg/hr/sqrt(hr)"], DEG / 3600.0 / 60.0, "rad/s²/√Hz"),
            (&["deg/s/sqrt(s)", "deg/s^1.5", "°/s/√s"], DEG, "rad/s²/√Hz"),
            (&["rad/s^2/sqrt(Hz)", "rad/s2/sqrt(Hz)", "rad/s²/√Hz"], 1.0, "rad/s²/√Hz"),
        ];
        const AW: &[(&[&str], f64, &str)] = &[
            (&["m/s/h^1.5", "m/s^2/sqrt(h)", "m/s²/√h", "m/s/hr^1.5"], 1.0 / 3600.0 / 60.0, "m/s³/√Hz"),
            (&["ug/sqrt(s)", "µg/√s", "µg/sqrt(s)"], 1e-6 * G0, "m/s³/√Hz"),
            (&["m/s^3/sqrt(Hz)", "m/s3/sqrt(Hz)", "m/s³/√Hz"], 1.0, "m/s³/√Hz"),
        ];
        const GI: &[(&[&str], f64, &str)] = &[
            (&["deg/h", "°/h", "deg/hr", "dph"], DEG / 3600.0, "rad/s"),
            (&["deg/s", "°/s", "dps"], DEG, "rad/s"),
            (&["rad/s"], 1.0, "rad/s"),
        ];
        const AI: &[(&[&str], f64, &str)] = &[
            (&["ug", "µg"], 1e-6 * G0, "m/s²"),
            (&["mg"], 1e-3 * G0, "m/s²"),
            (&["m/s^2", "m/s2", "m/s²"], 1.0, "m/s²"),
        ];
        match self {
            Figure::GyroNoise => GN,
            Figure::AccelNoise => AN,
            Figure::GyroWalk => GW,
            Figure::AccelWalk => AW,
            Figure::GyroInstability => GI,
            Figure::AccelInstability => AI,
        }
    }

    /// Parse `"0.15 deg/sqrt(h)"` (space optional) into SI, with a sentence saying how.
    pub fn parse(self, text: &str) -> Result<(f64, String), ModelError> {
        let t = text.trim();
        let split =
            t.find(|c: char| !(c.is_ascii_digit() || matches!(c, '.' | 'e' | 'E' | '-' | '+'))).unwrap_or(t.len());
        let (num, unit) = t.split_at(split);
        let value: f64 = num
            .parse()
            .map_err(|_| ModelError::from(format!("{}: '{t}' does not start with a number", self.name())))?;
        if !(value.is_finite() && value > 0.0) {
            return Err(format!("{}: {value} must be a positive number", self.name()).into());
        }
        let unit = unit.trim().replace(' ', "");
        let all = self.units();
        let Some((spellings, factor, si)) =
            all.iter().find(|(sp, _, _)| sp.iter().any(|s| s.eq_ignore_ascii_case(&unit)))
        else {
            let known: Vec<&str> = all.iter().map(|(sp, _, _)| sp[0]).collect();
            return Err(format!("{}: unit '{unit}' not known (use {})", self.name(), known.join(", ")).into());
        };
        let v = value * factor;
        Ok((v, format!("{}: {value} {} = {v:.4e} {si} (×{factor:.6e})", self.name(), spellings[0])))
    }
}

/// Datasheet figures as given (text with units), per sensor.
#[derive(Debug, Clone, Default)]
pub struct Datasheet {
    /// Gyro angle random walk or noise density.
    pub gyro_noise: Option<String>,
    /// Accelerometer velocity random walk or noise density.
    pub accel_noise: Option<String>,
    /// Gyro rate random walk.
    pub gyro_walk: Option<String>,
    /// Accelerometer random walk.
    pub accel_walk: Option<String>,
    /// Gyro bias instability.
    pub gyro_instability: Option<String>,
    /// Accelerometer bias instability.
    pub accel_instability: Option<String>,
}

impl Datasheet {
    /// The continuous-time noise and one line per conversion made.
    pub fn to_noise(&self) -> Result<(ImuNoise, Vec<String>), ModelError> {
        let mut lines = Vec::new();
        let mut get = |v: &Option<String>, f: Figure| -> Result<Option<f64>, ModelError> {
            match v {
                Some(t) => {
                    let (x, line) = f.parse(t)?;
                    lines.push(line);
                    Ok(Some(x))
                }
                None => Ok(None),
            }
        };
        let gn = get(&self.gyro_noise, Figure::GyroNoise)?.ok_or("the gyro noise (ARW) is required")?;
        let an = get(&self.accel_noise, Figure::AccelNoise)?.ok_or("the accelerometer noise (VRW) is required")?;
        let gk = get(&self.gyro_walk, Figure::GyroWalk)?;
        let ak = get(&self.accel_walk, Figure::AccelWalk)?;
        let gb = get(&self.gyro_instability, Figure::GyroInstability)?;
        let ab = get(&self.accel_instability, Figure::AccelInstability)?;
        let mut walk = |k: Option<f64>, b: Option<f64>, what: &str| -> Result<(f64, f64), ModelError> {
            match (k, b) {
                (Some(k), b) => Ok((k, estimator_random_walk(k, b.unwrap_or(0.0)))),
                (None, Some(b)) => {
                    let w = estimator_random_walk(0.0, b);
                    lines.push(format!(
                        "{what} random walk not given: {w:.4e} from the bias instability (the walk reaching its \
                         Allan floor 0.664·B at τ = {BIAS_INSTABILITY_MATCH_S} s)"
                    ));
                    Ok((w, w))
                }
                (None, None) => Err(format!("give the {what} random walk or bias instability").into()),
            }
        };
        let (gw, gw_axes) = walk(gk, gb, "gyro")?;
        let (aw, aw_axes) = walk(ak, ab, "accelerometer")?;
        let noise = ImuNoise {
            accelerometer_noise_density: an,
            accelerometer_random_walk: aw,
            gyroscope_noise_density: gn,
            gyroscope_random_walk: gw,
            axes: Some(ImuNoiseAxes {
                accelerometer_noise_density: [an; 3],
                accelerometer_random_walk: [aw_axes; 3],
                gyroscope_noise_density: [gn; 3],
                gyroscope_random_walk: [gw_axes; 3],
            }),
        };
        Ok((noise, lines))
    }
}

/// The `imu.yaml` text for `noise` at `rate_hz` on `rostopic`, with the conversions as comments.
pub fn datasheet_yaml(noise: &ImuNoise, rate_hz: f64, rostopic: &str, lines: &[String]) -> String {
    let mut s = String::from("# IMU noise from datasheet figures (`tumble noise`): continuous time, SI.\n");
    for l in lines {
        s.push_str(&format!("# {l}\n"));
    }
    s.push_str("# Datasheet figures are typical values at rest: measure your unit with `tumble allan`.\n");
    s.push_str(&format!("rostopic: {rostopic}\n"));
    s.push_str(&super::noise::kalibr_keys(
        [
            noise.gyroscope_noise_density,
            noise.accelerometer_noise_density,
            noise.gyroscope_random_walk,
            noise.accelerometer_random_walk,
        ],
        rate_hz,
    ));
    if let Some(a) = &noise.axes {
        s.push_str("# Per axis for tumble's estimator (random walks include the bias instability):\n");
        s.push_str(&a.yaml_block());
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn datasheet_units_convert() {
        // BMI088-like: 0.014 °/s/√Hz, 175 µg/√Hz; ADIS16465: 0.15 °/√h, 0.012 m/s/√h, 2 °/h, 3.6 µg.
        let close = |a: f64, b: f64| (a / b - 1.0).abs() < 1e-12;
        assert!(close(Figure::GyroNoise.parse("0.014 deg/s/sqrt(Hz)").unwrap().0, 0.014 * DEG));
        assert!(close(Figure::GyroNoise.parse("0.15deg/√h").unwrap().0, 0.15 * DEG / 60.0));
        assert!(close(Figure::AccelNoise.parse("175 ug/sqrt(Hz)").unwrap().0, 175e-6 * 9.80665));
        assert!(close(Figure::AccelNoise.parse("0.012 m/s/sqrt(h)").unwrap().0, 0.0002));
        assert!(close(Figure::GyroInstability.parse("2 deg/h").unwrap().0, 2.0 * DEG / 3600.0));
        assert!(close(Figure::GyroWalk.parse("1 deg/h/sqrt(h)").unwrap().0, DEG / 216000.0));
        let e = Figure::GyroNoise.parse("0.1 deg/h").unwrap_err().to_string();
        assert!(e.contains("unit 'deg/h' not known") && e.contains("deg/sqrt(h)"), "{e}");
        assert!(Figure::GyroNoise.parse("-1 deg/sqrt(h)").is_err());
        let ds = Datasheet {
            gyro_noise: Some("0.15 deg/sqrt(h)".into()),
            accel_noise: Some("0.012 m/s/sqrt(h)".into()),
            gyro_instability: Some("2 deg/h".into()),
            accel_instability: Some("3.6 ug".into()),
            ..Default::default()
        };
        let (n, lines) = ds.to_noise().unwrap();
        assert!(close(n.gyroscope_random_walk, estimator_random_walk(0.0, 2.0 * DEG / 3600.0)));
        assert!(lines.iter().any(|l| l.contains("gyro random walk not given")));
        let y = datasheet_yaml(&n, 200.0, "/imu", &lines);
        let back: ImuNoise = serde_saphyr::from_str(&y).unwrap();
        assert!(close(back.gyroscope_noise_density, 0.15 * DEG / 60.0));
        assert!(Datasheet { gyro_noise: Some("1 deg/sqrt(h)".into()), ..Default::default() }.to_noise().is_err());
    }
}

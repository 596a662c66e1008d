//! The `tumble allan` stage: a static recording in, the noise coefficients of
//! all six axes out, as `allan.json`, Kalibr's `imu.yaml`, one PNG per sensor
//! and a terminal table.

use super::identify::{basis, extra_basis, TERM_NAMES};
use super::{AllanCurve, AllanError, AllanOptions, Coefficient, Identification};
use crate::plot::{Layer, LogLogChart, AXIS_COLORS};
use serde::{Deserialize, Serialize};
use serde_json::{json, Value};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// How the three axes of a sensor are combined into Kalibr's one number.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum AxisStat {
    /// The worst (largest) axis: conservative, the default.
    #[default]
    Max,
    /// The mean of the three axes.
    Mean,
}

impl AxisStat {
    /// The names `FromStr` takes, in order.
    pub const NAMES: [&'static str; 2] = ["max", "mean"];
}

impl std::str::FromStr for AxisStat {
    type Err = AllanError;
    fn from_str(s: &str) -> Result<AxisStat, AllanError> {
        match s.trim() {
            "max" => Ok(AxisStat::Max),
            "mean" => Ok(AxisStat::Mean),
            _ => Err(AllanError::Invalid(format!("unknown axis statistic `{s}` (use max or mean)"))),
        }
    }
}

/// Options of [`run_allan`](crate::allan::run_allan).
#[derive(Clone, Debug)]
pub struct AllanRunOptions {
    /// Estimator, τ grid and confidence level.
    pub allan: AllanOptions,
    /// Combination of axes for `imu.yaml`.
    pub axis_stat: AxisStat,
    /// Analyse only the longest span free of knocks and steps
    /// (`super::disturbance`); they are reported either way. `tumble allan
    /// --span` turns it off (the span given is analysed as it is).
    pub cut_disturbances: bool,
}

impl Default for AllanRunOptions {
    fn default() -> Self {
        AllanRunOptions { allan: AllanOptions::default(), axis_stat: AxisStat::default(), cut_disturbances: true }
    }
}

impl AllanRunOptions {
    /// Check every option once (see [`AllanOptions::validate`]).
    pub fn validate(&self) -> Result<(), AllanError> {
        self.allan.validate()
    }
}

/// One axis: its curve and (for Allan curves) its identified noise.
#[derive(Clone, Debug)]
pub struct AxisResult {
    /// Deviation curve.
    pub curve: AllanCurve,
    /// Noise coefficients (None for curves other than Allan deviations).
    pub id: Option<Identification>,
}

/// One sensor (gyro or accelerometer): three axes.
#[derive(Clone, Debug)]
pub struct SensorResult {
    /// "gyro" or "accel".
    pub name: &'static str,
    /// Unit of the samples ("rad/s", "m/s^2" or "counts").
    pub unit: &'static str,
    /// x, y, z.
    pub axes: Vec<AxisResult>,
}

/// Kalibr's noise parameters (continuous time, SI units).
#[derive(Clone, Debug, PartialEq)]
pub struct KalibrNoise {
    /// Accelerometer white noise density \[m/s²/√Hz\].
    pub accelerometer_noise_density: f64,
    /// Accelerometer bias random walk \[m/s³/√Hz\].
    pub accelerometer_random_walk: f64,
    /// Gyro white noise density \[rad/s/√Hz\].
    pub gyroscope_noise_density: f64,
    /// Gyro bias random walk \[rad/s²/√Hz\].
    pub gyroscope_random_walk: f64,
    /// Sample rate \[Hz\].
    pub update_rate: f64,
    /// Where a value is a bound rather than an estimate, and why.
    pub notes: Vec<String>,
    /// Per-axis figures for the estimator: white noise N and the random walk
    /// with the bias instability folded in ([`crate::io::noise::estimator_random_walk`]).
    pub axes: crate::io::ImuNoiseAxes,
}

impl KalibrNoise {
    /// The four coefficients as the audit and the VIO take them.
    pub fn imu_noise(&self) -> crate::io::ImuNoise {
        crate::io::ImuNoise {
            accelerometer_noise_density: self.accelerometer_noise_density,
            accelerometer_random_walk: self.accelerometer_random_walk,
            gyroscope_noise_density: self.gyroscope_noise_density,
            gyroscope_random_walk: self.gyroscope_random_walk,
            axes: Some(self.axes),
        }
    }
}

/// Everything the Allan stage found.
#[derive(Clone, Debug)]
pub struct AllanReport {
    /// Recording name.
    pub source: String,
    /// The ROS topic(s) the samples came from (see [`crate::io::ImuRecording::topic`]).
    pub topic: Option<String>,
    /// Samples per axis.
    pub samples: usize,
    /// Sample rate used (1/τ0) \[Hz\].
    pub rate_hz: f64,
    /// Record length \[s\].
    pub duration_s: f64,
    /// Gyro and accelerometer.
    pub sensors: Vec<SensorResult>,
    /// Kalibr parameters (None for raw counts or non-Allan curves).
    pub kalibr: Option<KalibrNoise>,
    /// Options used.
    pub axis_stat: AxisStat,
    /// Reader warnings and remarks.
    pub warnings: Vec<String>,
    /// Knocks and steps found in the (gap-free) record.
    pub disturbances: Vec<super::disturbance::Disturbance>,
}

fn num(v: f64) -> Value {
    if v.is_finite() {
        json!(v)
    } else {
        Value::Null
    }
}

fn coef_json(c: Option<Coefficient>) -> Value {
    c.map_or(Value::Null, |c| json!({"value": num(c.value), "lo": num(c.lo), "hi": num(c.hi)}))
}

fn terms_json(t: &super::NoiseTerms) -> Value {
    let mut m = serde_json::Map::new();
    for (k, name) in TERM_NAMES.iter().enumerate() {
        m.insert(name.to_string(), coef_json(t.get(k)));
    }
    if !t.extra.is_empty() {
        let extra: Vec<Value> = t
            .extra
            .iter()
            .map(|e| json!({ "kind": e.kind, "amplitude": coef_json(Some(e.amplitude)), "time_s": num(e.time_s) }))
            .collect();
        m.insert("extra".into(), Value::Array(extra));
    }
    Value::Object(m)
}

impl AllanReport {
    /// The `allan.json` document.
    pub fn to_json(&self) -> Value {
        let mut root = serde_json::Map::new();
        root.insert("source".into(), json!(self.source));
        root.insert("samples".into(), json!(self.samples));
        root.insert("rate_hz".into(), num(self.rate_hz));
        root.insert("duration_s".into(), num(self.duration_s));
        let first = &self.sensors[0].axes[0].curve;
        root.insert("deviation".into(), json!(first.kind));
        root.insert("confidence".into(), json!(first.confidence));
        root.insert("disturbances".into(), json!(self.disturbances));
        root.insert("coefficient_confidence".into(), json!(0.95));
        for s in &self.sensors {
            let mut sensor = serde_json::Map::new();
            sensor.insert("unit".into(), json!(s.unit));
            for (a, ax) in s.axes.iter().zip(["x", "y", "z"]) {
                let c = &a.curve;
                let arr = |v: &[f64]| Value::Array(v.iter().map(|&x| num(x)).collect());
                let mut o = serde_json::Map::new();
                o.insert("tau".into(), arr(&c.tau));
                o.insert("adev".into(), arr(&c.dev));
                o.insert("adev_lo".into(), arr(&c.dev_lo));
                o.insert("adev_hi".into(), arr(&c.dev_hi));
                o.insert("m".into(), json!(c.m));
                o.insert("alpha".into(), json!(c.alpha));
                o.insert("edf".into(), arr(&c.edf));
                match &a.id {
                    Some(id) => {
                        o.insert("fit".into(), terms_json(&id.fit));
                        o.insert("readoff".into(), terms_json(&id.readoff));
                        o.insert("supported".into(), json!(id.supported));
                        o.insert("fit_chi2_dof".into(), num(id.fit_chi2_dof));
                        o.insert("follows_data".into(), json!(id.follows_data));
                        o.insert(
                            "worst_misfit".into(),
                            id.worst_misfit.map_or(Value::Null, |(t, r)| json!({ "tau": num(t), "ratio": num(r) })),
                        );
                        o.insert("notes".into(), json!(id.notes));
                    }
                    None => {
                        o.insert("fit".into(), Value::Null);
                        o.insert("readoff".into(), Value::Null);
                    }
                }
                sensor.insert(ax.into(), Value::Object(o));
            }
            root.insert(s.name.into(), Value::Object(sensor));
        }
        if let Some(k) = &self.kalibr {
            root.insert(
                "kalibr".into(),
                json!({
                    "accelerometer_noise_density": num(k.accelerometer_noise_density),
                    "accelerometer_random_walk": num(k.accelerometer_random_walk),
                    "gyroscope_noise_density": num(k.gyroscope_noise_density),
                    "gyroscope_random_walk": num(k.gyroscope_random_walk),
                    "update_rate": num(k.update_rate),
                    "axis_stat": format!("{:?}", self.axis_stat).to_lowercase(),
                    "notes": k.notes,
                }),
            );
        }
        root.insert("warnings".into(), json!(self.warnings));
        Value::Object(root)
    }

    /// Kalibr's `imu.yaml` text (None when there are no Kalibr parameters).
    pub fn kalibr_yaml(&self) -> Option<String> {
        let k = self.kalibr.as_ref()?;
        let mut s = String::new();
        let _ = writeln!(s, "# IMU noise for Kalibr / OpenVINS / VINS-Mono, from `tumble allan` on {}", self.source);
        let _ = writeln!(
            s,
            "# Continuous-time values, SI units, {} of the three axes.",
            match self.axis_stat {
                AxisStat::Max => "worst",
                AxisStat::Mean => "mean",
            }
        );
        for n in &k.notes {
            let _ = writeln!(s, "# note: {n}");
        }
        match self.topic.as_deref().map(|t| t.split_once(" + ")) {
            Some(Some((accel, gyro))) => {
                let _ = writeln!(s, "# Recorded as split streams {accel} and {gyro}: Kalibr reads one sensor_msgs/Imu");
                let _ = writeln!(s, "# topic holding both (e.g. RealSense's unite_imu_method); name it here.");
                let _ = writeln!(s, "rostopic: {gyro}");
            }
            Some(None) => {
                let _ = writeln!(s, "rostopic: {}", self.topic.as_deref().unwrap_or("/imu0"));
            }
            None => {
                let _ = writeln!(s, "rostopic: /imu0  # the recording had no topic: the name Kalibr's examples use");
            }
        }
        s.push_str(&crate::model::noise::kalibr_keys(
            [
                k.gyroscope_noise_density,
                k.accelerometer_noise_density,
                k.gyroscope_random_walk,
                k.accelerometer_random_walk,
            ],
            k.update_rate,
        ));
        let a = &k.axes;
        let _ = writeln!(s, "# Per axis [x, y, z] for tumble's estimator (Kalibr ignores the key); the random");
        let _ = writeln!(
            s,
            "# walks include the bias instability matched over {} s:",
            crate::io::noise::BIAS_INSTABILITY_MATCH_S
        );
        s.push_str(&a.yaml_block());
        Some(s)
    }

    /// The terminal summary: one row per axis and method.
    pub fn summary_table(&self) -> String {
        let mut s = String::new();
        let c0 = &self.sensors[0].axes[0].curve;
        let _ = writeln!(
            s,
            "{}: {} samples, {:.1} s at {:.3} Hz; {} at {} τ, fit intervals 95 %, read-off intervals {:.1} %",
            self.source,
            self.samples,
            self.duration_s,
            self.rate_hz,
            c0.kind.name(),
            c0.tau.len(),
            100.0 * c0.confidence
        );
        let cell = |c: Option<Coefficient>| match c {
            Some(c) => {
                let half = 0.5 * (c.hi - c.lo) / c.value.abs().max(1e-300) * 100.0;
                format!("{:>10.3e} ±{:<5.1}%", c.value, half.min(999.9))
            }
            None => format!("{:>10} {:6}", "—", ""),
        };
        for sensor in &self.sensors {
            let u = sensor.unit;
            let _ = writeln!(
                s,
                "\n{:<5} {:<4} {:<7} {:>18} {:>18} {:>18} {:>18} {:>18}",
                sensor.name,
                "axis",
                "method",
                format!("Q [{u}·s]"),
                format!("N [{u}/√Hz]"),
                format!("B [{u}]"),
                format!("K [{u}·√Hz]"),
                format!("R [{u}/s]")
            );
            for (a, ax) in sensor.axes.iter().zip(["x", "y", "z"]) {
                let Some(id) = &a.id else {
                    let _ = writeln!(s, "{:<5} {ax:<4} (no identification for this deviation)", "");
                    continue;
                };
                for (label, t) in [("fit", &id.fit), ("readoff", &id.readoff)] {
                    let _ = write!(s, "{:<5} {ax:<4} {label:<7}", "");
                    for k in 0..5 {
                        let _ = write!(s, " {}", cell(t.get(k)));
                    }
                    let _ = writeln!(s);
                }
            }
        }
        if let Some(k) = &self.kalibr {
            let dt = 1.0 / k.update_rate;
            let _ = writeln!(
                s,
                "\nKalibr imu.yaml ({} axis, continuous time):",
                match self.axis_stat {
                    AxisStat::Max => "worst",
                    AxisStat::Mean => "mean",
                }
            );
            let rows = [
                (
                    "gyroscope_noise_density",
                    k.gyroscope_noise_density,
                    "rad/s/√Hz",
                    "σ_d = N/√Δt",
                    1.0 / dt.sqrt(),
                    "rad/s",
                ),
                ("gyroscope_random_walk", k.gyroscope_random_walk, "rad/s²/√Hz", "σ_bd = K·√Δt", dt.sqrt(), "rad/s"),
                (
                    "accelerometer_noise_density",
                    k.accelerometer_noise_density,
                    "m/s²/√Hz",
                    "σ_d = N/√Δt",
                    1.0 / dt.sqrt(),
                    "m/s²",
                ),
                (
                    "accelerometer_random_walk",
                    k.accelerometer_random_walk,
                    "m/s³/√Hz",
                    "σ_bd = K·√Δt",
                    dt.sqrt(),
                    "m/s²",
                ),
            ];
            for (name, v, unit, what, f, dunit) in rows {
                let _ = writeln!(
                    s,
                    "  {name:<28} {v:.4e} {unit:<11} discrete at {:.0} Hz: {what} = {:.4e} {dunit}",
                    k.update_rate,
                    v * f
                );
            }
            for n in &k.notes {
                let _ = writeln!(s, "  note: {n}");
            }
        }
        for w in &self.warnings {
            let _ = writeln!(s, "warning: {w}");
        }
        s
    }

    /// Draw one log-log PNG per sensor into `dir`; returns the files.
    pub fn write_plots(&self, dir: &Path) -> Result<Vec<PathBuf>, AllanError> {
        let mut files = Vec::new();
        for sensor in &self.sensors {
            let mut layers = Vec::new();
            for (k, a) in sensor.axes.iter().enumerate() {
                let c = &a.curve;
                let color = AXIS_COLORS[k];
                layers.push(Layer::Band { x: c.tau.clone(), lo: c.dev_lo.clone(), hi: c.dev_hi.clone(), color });
            }
            for (k, (a, ax)) in sensor.axes.iter().zip(["x", "y", "z"]).enumerate() {
                let c = &a.curve;
                let color = AXIS_COLORS[k];
                layers.push(Layer::Line {
                    points: c.tau.iter().copied().zip(c.dev.iter().copied()).collect(),
                    color,
                    width: 2,
                    label: format!("{ax} data ({:.1} % CI band)", 100.0 * c.confidence),
                });
                let Some(id) = &a.id else { continue };
                // Fitted model and its terms, over the τ range of the data.
                let (t0, t1) = (c.tau[0], *c.tau.last().expect("non-empty curve"));
                let grid: Vec<f64> = (0..=240).map(|i| t0 * (t1 / t0).powf(i as f64 / 240.0)).collect();
                layers.push(Layer::Line {
                    points: grid.iter().map(|&t| (t, id.fit.model_dev(t))).collect(),
                    color: color.mix_with_black(0.55),
                    width: 1,
                    label: {
                        // The fitted terms by name: the thin lines in the axis' lighter colour.
                        let mut names: Vec<String> = TERM_NAMES
                            .iter()
                            .enumerate()
                            .filter(|(t, _)| id.fit.get(*t).is_some())
                            .map(|(_, n)| n.to_string())
                            .collect();
                        names.extend(id.fit.extra.iter().map(|e| format!("{} {:.3} s", e.kind.name(), e.time_s)));
                        format!("{ax} fit (darker) = {} (thin)", names.join(" + "))
                    },
                });
                for term in 0..5 {
                    if let Some(cf) = id.fit.get(term) {
                        layers.push(Layer::Line {
                            points: grid.iter().map(|&t| (t, cf.value * basis(t)[term].sqrt())).collect(),
                            color: color.mix_with_white(0.45),
                            width: 1,
                            label: String::new(),
                        });
                    }
                }
                for e in &id.fit.extra {
                    let amp2 = e.amplitude.value.powi(2);
                    layers.push(Layer::Line {
                        points: grid
                            .iter()
                            .map(|&t| (t, (amp2 * extra_basis(e.kind, e.time_s, t)).sqrt()))
                            .filter(|p| p.1 > 0.0)
                            .collect(),
                        color: color.mix_with_white(0.45),
                        width: 1,
                        label: String::new(),
                    });
                }
                // Read-off points: on the curve, at the τ each was read.
                let pts: Vec<(f64, f64)> = id
                    .readoff_tau
                    .iter()
                    .flatten()
                    .filter_map(|&t| c.tau.iter().position(|&x| x == t).map(|i| (t, c.dev[i])))
                    .collect();
                layers.push(Layer::Points {
                    points: pts,
                    color: color.mix_with_black(0.3),
                    label: if k == 0 { "read-offs (where each term's slope was read)".into() } else { String::new() },
                });
            }
            let chart = LogLogChart {
                title: format!("{} — {} ({})", self.source, sensor.name, sensor.axes[0].curve.kind.name()),
                x_label: "averaging time τ [s]".into(),
                y_label: format!("σ(τ) [{}]", sensor.unit),
                layers,
            };
            let path = dir.join(format!("allan_{}.png", sensor.name));
            chart.write_png(&path, 1100, 760)?;
            files.push(path);
        }
        Ok(files)
    }

    /// Write `allan.json`, `imu.yaml` (when SI) and the plots into `dir`
    /// (created if needed), all or nothing (`crate::io::staging`); returns
    /// the files written.
    pub fn write_all(&self, dir: &Path) -> Result<Vec<PathBuf>, AllanError> {
        crate::io::staging::write_staged(dir, |stage| self.write_unstaged(stage))
    }

    fn write_unstaged(&self, dir: &Path) -> Result<Vec<PathBuf>, AllanError> {
        let mut files = Vec::new();
        let json_path = dir.join("allan.json");
        let text = serde_json::to_string_pretty(&self.to_json()).map_err(|e| e.to_string())?;
        std::fs::write(&json_path, text).map_err(|e| format!("{}: {e}", json_path.display()))?;
        files.push(json_path);
        if let Some(y) = self.kalibr_yaml() {
            let p = dir.join("imu.yaml");
            std::fs::write(&p, y).map_err(|e| format!("{}: {e}", p.display()))?;
            files.push(p);
        }
        files.extend(self.write_plots(dir)?);
        Ok(files)
    }
}

trait Shade {
    fn mix_with_black(self, f: f64) -> plotters::style::RGBColor;
    fn mix_with_white(self, f: f64) -> plotters::style::RGBColor;
}

impl Shade for plotters::style::RGBColor {
    fn mix_with_black(self, f: f64) -> plotters::style::RGBColor {
        let s = |c: u8| (c as f64 * (1.0 - f)) as u8;
        plotters::style::RGBColor(s(self.0), s(self.1), s(self.2))
    }
    fn mix_with_white(self, f: f64) -> plotters::style::RGBColor {
        let s = |c: u8| (c as f64 + (255.0 - c as f64) * f) as u8;
        plotters::style::RGBColor(s(self.0), s(self.1), s(self.2))
    }
}

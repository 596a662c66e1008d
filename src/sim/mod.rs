//! The simulator: scenarios (hand tumble, long static log, hand-held loop,
//! EuRoC-like flight, laps of a corridor), the paper's full IMU error model, a camera with feature
//! tracks, and a writer of the same ASL folder layout real data uses plus a
//! `truth.json` with every parameter.
//!
//! ```
//! use tumble::sim::{simulate, Scenario, SimConfig};
//! let mut cfg = SimConfig::default();
//! cfg.duration_s = Some(20.0);
//! let sim = simulate(Scenario::Static, &cfg, 7).unwrap();
//! assert_eq!(sim.imu.t.len(), 4001); // 20 s at 200 Hz, both ends
//! ```

pub(crate) mod camera;
pub(crate) mod corridor;
pub mod images;
pub(crate) mod imu;
pub use crate::model::imu_model as model;
pub(crate) mod motion;
pub mod render;
pub(crate) mod replay_bands;
pub mod replay_recording;
pub mod rig_recording;
pub(crate) mod smoothed;
pub mod target;
pub(crate) mod writer;

pub use camera::{CameraSettings, Scene, SimulatedTracks};
pub use corridor::{Corridor, CorridorWalk};
pub use imu::{noise_series, simulate_imu, AxisNoise, SimulatedImu};
pub use model::{Effects, ImuModel, TemperatureTrace, TriadModel};
pub use motion::{Kinematics, Loop, Motion, Static, Tumble, TumbleSettings};
pub use smoothed::SmoothedReplay;
pub use writer::{groundtruth, simulate_and_write, simulate_and_write_with, write_asl};

use crate::error::InputError;
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// What is simulated.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Scenario {
    /// The paper's hand-tumble calibration recording (≥ 50 s static, ≥ 50 held poses).
    Tumble,
    /// A long static log for Allan variance (default 2 h).
    Static,
    /// The paper's 6-minute hand-held loop in a 1 m cube, with a camera
    /// (time-scaled to the duration; at least ~35 s, see [`MAX_LOOP_ACCELERATION`]).
    Walk,
    /// An EuRoC-like flight in a room (default 120 s), with a camera
    /// (time-scaled like the walk; at least ~20 s).
    Flight,
    /// The paper's walk as a person walks it (default 6 minutes): whole laps
    /// of a corridor at about 1 m/s, back at the start, with a camera looking
    /// along it (see [`corridor::CorridorWalk`]; at least 20 s).
    Corridor,
}

impl Scenario {
    /// Whether the scenario moves through a scene (walk, flight, corridor):
    /// it has a camera by default and may pause.
    pub fn moves(self) -> bool {
        matches!(self, Scenario::Walk | Scenario::Flight | Scenario::Corridor)
    }
    /// The names [`Scenario`]'s `FromStr` takes, in order.
    pub const NAMES: [&'static str; 5] = ["tumble", "static", "walk", "flight", "corridor"];
    const ALL: [Scenario; 5] =
        [Scenario::Tumble, Scenario::Static, Scenario::Walk, Scenario::Flight, Scenario::Corridor];
}

impl std::str::FromStr for Scenario {
    type Err = SimError;
    fn from_str(s: &str) -> Result<Scenario, SimError> {
        let k = Scenario::NAMES.iter().position(|n| *n == s.trim()).ok_or_else(|| {
            SimError::Invalid(format!("unknown scenario `{s}` (scenarios: {})", Scenario::NAMES.join(", ")))
        })?;
        Ok(Scenario::ALL[k])
    }
}

/// Why a simulation cannot be made.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// A setting that cannot be simulated (named in the message).
    #[error("{0}")]
    Invalid(String),
    /// A config file that cannot be read.
    #[error(transparent)]
    Input(#[from] InputError),
    /// The IMU model cannot be simulated.
    #[error(transparent)]
    Model(#[from] crate::model::ModelError),
}

crate::error::message_error_conversions!(SimError, SimError::Invalid);

/// `START,LENGTH` seconds of one pause (`tumble sim --pause`; the simulator
/// checks the values against the motion).
pub fn parse_pause(s: &str) -> Result<[f64; 2], SimError> {
    let bad = || SimError::Invalid(format!("--pause: expected START,LENGTH in seconds, got `{s}`"));
    let (a, b) = s.split_once(',').ok_or_else(bad)?;
    let num = |v: &str| v.trim().parse::<f64>().ok().filter(|x| x.is_finite()).ok_or_else(bad);
    Ok([num(a)?, num(b)?])
}

/// [`hide_effect`] from `EFFECT` or `EFFECT:STRENGTH` (`tumble sim --hide`).
pub fn hide_effect_spec(config: &mut SimConfig, spec: &str) -> Result<(), SimError> {
    let (name, strength) = match spec.split_once(':') {
        Some((n, s)) => (
            n,
            s.parse::<f64>()
                .map_err(|e| SimError::Invalid(format!("--hide {spec}: strength `{s}` is not a number ({e})")))?,
        ),
        None => (spec, 1.0),
    };
    hide_effect(config, name, strength).map_err(|e| SimError::Invalid(format!("--hide {spec}: {e}")))
}

/// Everything a simulation can be told (all optional in YAML).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SimConfig {
    /// Gravity magnitude \[m/s²\].
    pub gravity: f64,
    /// Length of static, walk, flight and corridor scenarios \[s\] (scenario default when absent).
    pub duration_s: Option<f64>,
    /// The IMU and its error model.
    pub imu: ImuModel,
    /// Settings of the tumble scenario.
    pub tumble: TumbleSettings,
    /// Camera (walk, flight and corridor have one by default; set `camera_enabled` to change).
    pub camera: CameraSettings,
    /// Geometry of the corridor scenario.
    pub corridor: Corridor,
    /// Whether to simulate the camera (scenario default when absent).
    pub camera_enabled: Option<bool>,
    /// Rate of the written ground truth \[Hz\] (IMU rate when moving, 10 Hz static, when absent).
    pub groundtruth_rate_hz: Option<f64>,
    /// Stops on the way of a walk, flight or corridor walk: `[start, length]` \[s\] each. The
    /// motion slows to a standstill over 1 s from `start`, stands still for
    /// `length` and speeds up again over 1 s; each pause makes the recording
    /// `length + 1` s longer than `duration_s` (see `motion::Paused`).
    pub pauses_s: Vec<[f64; 2]>,
    /// Absolute time of the first sample \[ns\].
    pub t0_ns: i64,
    /// Render the camera's frames as images (`tumble sim --images`): how they
    /// are exposed. Absent: feature tracks only.
    pub images: Option<render::ImageSettings>,
}

impl Default for SimConfig {
    fn default() -> Self {
        SimConfig {
            gravity: 9.81,
            duration_s: None,
            imu: ImuModel::bmi055(),
            tumble: TumbleSettings::default(),
            camera: CameraSettings::default(),
            corridor: Corridor::default(),
            camera_enabled: None,
            groundtruth_rate_hz: None,
            pauses_s: Vec::new(),
            t0_ns: DEFAULT_T0_NS,
            images: None,
        }
    }
}

impl SimConfig {
    /// Read a YAML config (every key optional; unknown keys are errors).
    pub fn read(path: &Path) -> Result<SimConfig, InputError> {
        let cfg: SimConfig = crate::io::yaml::read_yaml(path)?;
        cfg.check().map_err(|m| InputError::file(path, m))?;
        Ok(cfg)
    }
    /// Whether `scenario` is simulated with a camera: `camera_enabled`, or
    /// by default when it [moves](Scenario::moves).
    pub fn has_camera(&self, scenario: Scenario) -> bool {
        self.camera_enabled.unwrap_or(scenario.moves())
    }
    /// Check for values that cannot be simulated.
    pub fn check(&self) -> Result<(), SimError> {
        if !(self.gravity.is_finite() && self.gravity > 0.0) {
            return Err(format!("gravity must be positive, found {}", self.gravity).into());
        }
        if let Some(d) = self.duration_s {
            if !(d.is_finite() && d > 10.0) {
                return Err(format!("duration_s must be more than 10 s, found {d}").into());
            }
            let samples = d * self.imu.rate_hz;
            if samples > MAX_SIMULATED_SAMPLES {
                return Err(format!(
                    "duration_s {d} s at {} Hz is {samples:.2e} IMU samples, more than the {MAX_SIMULATED_SAMPLES:.0e} \
                     the simulator holds in memory (about {:.0} GB): simulate shorter recordings",
                    self.imu.rate_hz,
                    samples * BYTES_PER_SIMULATED_SAMPLE / 1e9
                )
                .into());
            }
        }
        if let Some(r) = self.groundtruth_rate_hz {
            if !(r.is_finite() && r > 0.0) {
                return Err(format!("groundtruth_rate_hz must be positive, found {r}").into());
            }
        }
        if self.tumble.poses == 0 || self.tumble.hold_s[0] <= 0.0 || self.tumble.hold_s[1] < self.tumble.hold_s[0] {
            return Err("tumble: poses must be ≥ 1 and 0 < hold_s[0] ≤ hold_s[1]".into());
        }
        let (rate, ratio) = (self.tumble.turn_rate, self.tumble.turn_rate_ratio);
        if !(rate.is_finite() && rate > 0.0 && ratio.is_finite() && ratio >= 1.0) {
            return Err(format!(
                "tumble: turn_rate must be positive and turn_rate_ratio ≥ 1, found {rate} and {ratio}"
            )
            .into());
        }
        self.imu.check()?;
        self.corridor.check()?;
        if let Some(images) = &self.images {
            images.check()?;
        }
        self.camera.check()
    }
}

/// Most IMU samples one simulation holds (a 200 Hz IMU for 29 days): the
/// samples, their true biases and the writer's buffers stay in memory.
pub const MAX_SIMULATED_SAMPLES: f64 = 5e8;

/// Memory one simulated sample takes, roughly \[bytes\] (time, six axes, biases, temperature).
const BYTES_PER_SIMULATED_SAMPLE: f64 = 80.0;

/// Camera–IMU time offset `hide_effect` sets at strength 1 \[s\] (a frame stamped
/// `t` shows the motion at `t + offset`).
pub const CAMERA_IMU_TIME_OFFSET_S: f64 = 0.01;

/// Accelerometer–gyro time offset `hide_effect` sets at strength 1 \[s\].
pub const ACCEL_GYRO_TIME_OFFSET_S: f64 = 0.005;

/// Switch on one effect the calibration model lacks, as the audit's tests and
/// `tumble demo` hide it: `g_sensitivity`, `temperature_bias`,
/// `temperature_bias_quadratic`, `temperature_scale`,
/// `temperature_scale_quadratic`, `gyro_nonlinearity`, `accel_nonlinearity`,
/// `bias_drift`, `camera_imu_time_offset`, `accel_gyro_time_offset`, or
/// `none`, with the model's coefficients of that effect multiplied by
/// `strength` (the time offsets: [`CAMERA_IMU_TIME_OFFSET_S`] and
/// [`ACCEL_GYRO_TIME_OFFSET_S`] times `strength`).
///
/// `gyro_nonlinearity_FORM` and `accel_nonlinearity_FORM`, FORM one of `even`,
/// `odd`, `cubic`, `asymmetric`, hide a scale nonlinearity of that shape sized
/// as datasheets give it: `strength` is the deviation at full scale in **% of
/// full scale** (the triad's `range`), with the signs of the model's
/// coefficients (`gyro_nonlinearity` and `accel_nonlinearity` are the even
/// form with the model's coefficients times `strength`).
///
/// Temperature effects also get a warm-up of [`HIDDEN_WARMUP_C`] from 10 °C
/// (time constant 150 s) so the temperature changes during a tumble recording;
/// the nonlinearity of the other triad stays zero.
pub fn hide_effect(config: &mut SimConfig, effect: &str, strength: f64) -> Result<(), SimError> {
    if !(strength.is_finite() && strength >= 0.0) {
        return Err(format!("effect strength must be ≥ 0, found {strength}").into());
    }
    // Each arm below scales only the named effect's coefficients, so that
    // effects hidden one after the other keep their own strengths.
    let scale3 = |v: &mut [f64; 3]| v.iter_mut().for_each(|x| *x *= strength);
    let warm = |c: &mut SimConfig| {
        c.imu.temperature = TemperatureTrace {
            start: 10.0,
            end: 10.0 + HIDDEN_WARMUP_C,
            warmup_s: 150.0,
            reference: 10.0,
            ..Default::default()
        };
    };
    let zero = |v: &mut [f64; 3]| *v = [0.0; 3];
    if let Some((triad, form)) = effect.split_once("_nonlinearity_") {
        let shape = match form {
            "even" => model::NonlinearityShape::Even,
            "odd" => model::NonlinearityShape::Odd,
            "cubic" => model::NonlinearityShape::Cubic,
            "asymmetric" => model::NonlinearityShape::Asymmetric,
            other => {
                return Err(format!("unknown nonlinearity form `{other}`: use even, odd, cubic or asymmetric").into())
            }
        };
        let (on, off) = match triad {
            "gyro" => (&mut config.imu.gyro, &mut config.imu.accel),
            "accel" => (&mut config.imu.accel, &mut config.imu.gyro),
            other => return Err(format!("unknown triad `{other}`: use gyro or accel").into()),
        };
        zero(&mut off.nonlinearity);
        // Deviation at full scale: c·h(range) = strength % · range (the model's
        // coefficients give the signs).
        let size = 0.01 * strength * on.range / shape.eval(on.range).abs();
        for c in on.nonlinearity.iter_mut() {
            *c = if *c == 0.0 { 0.0 } else { c.signum() * size };
        }
        on.nonlinearity_form = shape;
        config.imu.effects.nonlinearity = true;
        return Ok(());
    }
    let m = &mut config.imu;
    // Which temperature terms stay: bias or scale, linear or linear + quadratic.
    let scale_only = effect.starts_with("temperature_scale");
    let linear_only = !effect.ends_with("_quadratic");
    match effect {
        "none" => {}
        "g_sensitivity" => {
            m.g_sensitivity.iter_mut().for_each(scale3);
            m.effects.g_sensitivity = true;
        }
        "gyro_nonlinearity" => {
            scale3(&mut m.gyro.nonlinearity);
            m.effects.nonlinearity = true;
            zero(&mut m.accel.nonlinearity);
        }
        "accel_nonlinearity" => {
            scale3(&mut m.accel.nonlinearity);
            m.effects.nonlinearity = true;
            zero(&mut m.gyro.nonlinearity);
        }
        "bias_drift" => {
            for t in [&mut m.gyro, &mut m.accel] {
                scale3(&mut t.bias_drift);
            }
            m.effects.bias_drift = true;
        }
        "camera_imu_time_offset" => config.camera.time_offset_s = CAMERA_IMU_TIME_OFFSET_S * strength,
        "accel_gyro_time_offset" => config.imu.accel_time_offset_s = ACCEL_GYRO_TIME_OFFSET_S * strength,
        "temperature_bias" | "temperature_bias_quadratic" | "temperature_scale" | "temperature_scale_quadratic" => {
            m.effects.temperature = true;
            for t in [&mut m.accel, &mut m.gyro] {
                if scale_only {
                    scale3(&mut t.temperature_scale);
                    scale3(&mut t.temperature_scale_quadratic);
                    zero(&mut t.temperature_bias);
                    zero(&mut t.temperature_bias_quadratic);
                } else {
                    scale3(&mut t.temperature_bias);
                    scale3(&mut t.temperature_bias_quadratic);
                    zero(&mut t.temperature_scale);
                    zero(&mut t.temperature_scale_quadratic);
                }
                if linear_only {
                    zero(&mut t.temperature_bias_quadratic);
                    zero(&mut t.temperature_scale_quadratic);
                }
            }
            warm(config);
        }
        other => {
            return Err(format!(
                "unknown effect `{other}`: use g_sensitivity, temperature_bias, temperature_bias_quadratic, \
                 temperature_scale, temperature_scale_quadratic, gyro_nonlinearity, accel_nonlinearity, \
                 gyro_nonlinearity_FORM or accel_nonlinearity_FORM (FORM: even, odd, cubic, asymmetric), \
                 bias_drift, camera_imu_time_offset, accel_gyro_time_offset or none"
            )
            .into())
        }
    }
    Ok(())
}

/// Temperature rise of the warm-up [`hide_effect`] gives the temperature effects \[°C\].
pub const HIDDEN_WARMUP_C: f64 = 10.0;

/// Rate of the written ground truth \[Hz\] (IMU rate when moving, 10 Hz for static logs).
pub fn groundtruth_rate(scenario: Scenario, config: &SimConfig) -> f64 {
    config.groundtruth_rate_hz.unwrap_or(if scenario == Scenario::Static { 10.0 } else { config.imu.rate_hz })
}

/// A finished simulation: the truth and the measurements.
pub struct Simulation {
    /// What was simulated.
    pub scenario: Scenario,
    /// Seed used.
    pub seed: u64,
    /// The configuration used.
    pub config: SimConfig,
    /// The true motion.
    pub motion: Box<dyn Motion>,
    /// What the camera sees.
    pub scene: Scene,
    /// IMU samples and true biases.
    pub imu: SimulatedImu,
    /// Camera tracks, when a camera was simulated.
    pub tracks: Option<SimulatedTracks>,
    /// True still intervals `[start, end]` \[s\] (tumble: the holds; static:
    /// all; walk, flight and corridor: the standstills of their pauses).
    pub static_intervals: Vec<[f64; 2]>,
}

impl Simulation {
    /// World-frame centre of the motion (the room's centre; the corridor's
    /// at eye height) \[m\].
    pub fn centre(&self) -> Vector3<f64> {
        match self.scene {
            Scene::Room(c) => c,
            Scene::Corridor(_) => Vector3::new(0.0, 0.0, corridor::EYE_HEIGHT),
        }
    }
    /// The written stamp \[ns\] of simulation time `t` \[s\] (frames' names and `data.csv` rows).
    pub fn stamp_ns(&self, t: f64) -> i64 {
        self.config.t0_ns + (t * 1e9).round() as i64
    }
}

/// Absolute time of a simulated recording's first IMU sample unless configured \[ns\] (November 2023).
pub(crate) const DEFAULT_T0_NS: i64 = 1_700_000_000_000_000_000;

/// Run a scenario. Deterministic: the same seed and config give the same samples.
pub fn simulate(scenario: Scenario, config: &SimConfig, seed: u64) -> Result<Simulation, SimError> {
    simulate_with(scenario, config, seed, &mut |_, _| {})
}

/// A motion of one's own (`motion`, e.g. [`Loop::planar`]) through `scene`,
/// recorded by `config`'s IMU and camera as `scenario`'s would be (its
/// ground-truth rate, [`groundtruth_rate`]), with no still intervals.
/// `scenario` only labels it otherwise. Deterministic in `seed`.
pub fn simulate_motion(
    scenario: Scenario,
    motion: Box<dyn Motion>,
    scene: Scene,
    config: &SimConfig,
    seed: u64,
) -> Result<Simulation, SimError> {
    config.check()?;
    let bias_every = ((config.imu.rate_hz / groundtruth_rate(scenario, config)).round() as usize).max(1);
    let imu = simulate_imu(motion.as_ref(), &config.imu, config.gravity, seed, bias_every);
    let tracks = Some(camera::simulate_tracks(motion.as_ref(), &config.camera, &scene, seed));
    Ok(Simulation { scenario, seed, config: config.clone(), motion, scene, imu, tracks, static_intervals: Vec::new() })
}

/// Largest acceleration a walk or flight may reach \[m/s²\] (4 g): the loops
/// are time-scaled to their duration, so a short one shakes harder, and beyond
/// this it is no longer a hand-held or flying motion.
pub const MAX_LOOP_ACCELERATION: f64 = 4.0 * crate::io::STANDARD_GRAVITY;

/// Refuse a loop whose duration compresses it into implausible dynamics.
fn check_dynamics(scenario: Scenario, motion: &dyn Motion) -> Result<(), SimError> {
    let d = motion.duration();
    let peak = (0..=(d * 50.0) as usize).map(|k| motion.at(k as f64 / 50.0).acceleration.norm()).fold(0.0, f64::max);
    if peak <= MAX_LOOP_ACCELERATION {
        return Ok(());
    }
    // Accelerations scale with the inverse square of the moving time (duration − 10 s).
    let shortest = (d - 10.0) * (peak / MAX_LOOP_ACCELERATION).sqrt() + 10.0;
    Err(format!(
        "a {d:.0} s {} time-compresses its loop to accelerations of {peak:.0} m/s² ({:.1} g), \
         beyond the {:.0} g of a real one: give a duration of at least {:.0} s",
        match scenario {
            Scenario::Flight => "flight",
            Scenario::Corridor => "corridor walk",
            _ => "walk",
        },
        peak / crate::io::STANDARD_GRAVITY,
        MAX_LOOP_ACCELERATION / crate::io::STANDARD_GRAVITY,
        shortest.ceil()
    )
    .into())
}

/// A scenario's motion, the scene its camera sees and its still intervals `[start, end]` \[s\].
type Staged = (Box<dyn Motion>, Scene, Vec<[f64; 2]>);

/// A motion with the config's pauses (none: the motion itself), its scene and its standstills.
fn with_pauses<M: Motion + 'static>(m: M, scene: Scene, pauses_s: &[[f64; 2]]) -> Result<Staged, SimError> {
    if pauses_s.is_empty() {
        return Ok((Box::new(m), scene, Vec::new()));
    }
    let m = motion::Paused::new(m, pauses_s).map_err(|e| format!("pauses_s: {e}"))?;
    let standstills = m.standstills();
    Ok((Box::new(m), scene, standstills))
}

/// [`simulate`], handing each finished chunk of IMU samples to `on_chunk`.
pub fn simulate_with(
    scenario: Scenario,
    config: &SimConfig,
    seed: u64,
    on_chunk: &mut dyn FnMut(&SimulatedImu, std::ops::Range<usize>),
) -> Result<Simulation, SimError> {
    config.check()?;
    let (motion, scene, intervals): Staged = match scenario {
        Scenario::Tumble => {
            let m = Tumble::new(&config.tumble, seed);
            let iv = m.static_intervals();
            (Box::new(m), Scene::Room(Vector3::zeros()), iv)
        }
        Scenario::Static => {
            let d = config.duration_s.unwrap_or(7200.0);
            (
                Box::new(Static { rotation: nalgebra::Matrix3::identity(), duration: d }),
                Scene::Room(Vector3::zeros()),
                vec![[0.0, d]],
            )
        }
        Scenario::Walk => {
            let m = Loop::handheld(config.duration_s.unwrap_or(360.0), seed);
            with_pauses(m, Scene::Room(Vector3::new(0.0, 0.0, 1.2)), &config.pauses_s)?
        }
        Scenario::Flight => {
            let m = Loop::flight(config.duration_s.unwrap_or(120.0), seed);
            with_pauses(m, Scene::Room(Vector3::new(0.0, 0.0, 1.5)), &config.pauses_s)?
        }
        Scenario::Corridor => {
            let m = CorridorWalk::new(config.corridor, config.duration_s.unwrap_or(360.0), seed)?;
            with_pauses(m, Scene::Corridor(config.corridor), &config.pauses_s)?
        }
    };
    let moving = scenario.moves();
    if !config.pauses_s.is_empty() && !moving {
        return Err("pauses_s: only a walk, a flight or a corridor walk can pause".into());
    }
    if moving {
        check_dynamics(scenario, motion.as_ref())?;
    }
    let bias_every = ((config.imu.rate_hz / groundtruth_rate(scenario, config)).round() as usize).max(1);
    let imu = imu::simulate_imu_streaming(motion.as_ref(), &config.imu, config.gravity, seed, bias_every, on_chunk);
    let camera = config.has_camera(scenario);
    let tracks = camera.then(|| camera::simulate_tracks(motion.as_ref(), &config.camera, &scene, seed));
    Ok(Simulation { scenario, seed, config: config.clone(), motion, scene, imu, tracks, static_intervals: intervals })
}

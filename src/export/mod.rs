//! `tumble export`: tumble's results as the configuration files of other
//! estimators — Kalibr, VINS-Mono, VINS-Fusion, OpenVINS, ORB-SLAM3 and
//! Basalt — each in its own keys, units, frames and file format.
//!
//! What goes in:
//! - the IMU noise (`imu.yaml` from `tumble allan`), converted to each
//!   estimator's convention ([`NoiseConvention`]) and inflated only by factors
//!   derived from the audit of the same recording ([`Inflation`]);
//! - the calibration (`calibration.json`), as intrinsics where the estimator
//!   models them (OpenVINS, Basalt) — otherwise the files say to feed the
//!   estimator the recording corrected by `tumble apply`;
//! - the cameras of an ASL folder (`mav0/camN/sensor.yaml` with `T_BS`),
//!   with the calibration's camera–IMU time offset when it has one.
//!
//! Each target's keys come from the project's own example configurations
//! (cited in `docs/export.md`); the tests parse every written file back.

pub mod intrinsics;
mod targets;

use crate::error::{InputError, OutputError};
use crate::io::ImuNoise;
use crate::model::calibration::ImuCalibration;
use crate::model::target::RigCamera;
use std::path::{Path, PathBuf};

/// The estimators tumble writes configuration for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Target {
    /// Kalibr: `imu.yaml` and `camchain-imucam.yaml`.
    Kalibr,
    /// VINS-Mono: one OpenCV YAML configuration.
    VinsMono,
    /// VINS-Fusion: a configuration plus one file per camera.
    VinsFusion,
    /// OpenVINS: `kalibr_imu_chain.yaml` (with IMU intrinsics) and `kalibr_imucam_chain.yaml`.
    OpenVins,
    /// ORB-SLAM3: one settings file (format 1.0).
    OrbSlam3,
    /// Basalt: `calibration.json` with accelerometer and gyro intrinsics.
    Basalt,
}

impl Target {
    /// Every target.
    pub const ALL: [Target; 6] =
        [Target::Kalibr, Target::VinsMono, Target::VinsFusion, Target::OpenVins, Target::OrbSlam3, Target::Basalt];
    /// The name on the command line.
    pub fn id(self) -> &'static str {
        match self {
            Target::Kalibr => "kalibr",
            Target::VinsMono => "vins-mono",
            Target::VinsFusion => "vins-fusion",
            Target::OpenVins => "openvins",
            Target::OrbSlam3 => "orbslam3",
            Target::Basalt => "basalt",
        }
    }
    /// How this estimator reads IMU noise.
    pub fn convention(self) -> NoiseConvention {
        match self {
            Target::VinsMono | Target::VinsFusion => NoiseConvention::DiscretePerSample,
            _ => NoiseConvention::Continuous,
        }
    }
}

impl std::str::FromStr for Target {
    type Err = String;
    fn from_str(s: &str) -> Result<Target, String> {
        Target::ALL
            .into_iter()
            .find(|t| t.id() == s)
            .ok_or_else(|| format!("unknown target '{s}' (use {})", Target::ALL.map(|t| t.id()).join(", ")))
    }
}

/// How an estimator reads its four noise figures.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NoiseConvention {
    /// Continuous-time densities (Kalibr's): white noise in unit/√Hz, bias
    /// random walk in unit/s/√Hz. Kalibr, OpenVINS, ORB-SLAM3 (it multiplies
    /// by √rate itself) and Basalt.
    Continuous,
    /// Standard deviations per IMU sample at the update rate f: white σ·√f,
    /// random walk σ_w·√f (VINS-Mono/Fusion's `integration_base.h` adds
    /// `acc_n²` to each midpoint step scaled by dt and `acc_w²` scaled by dt²).
    DiscretePerSample,
}

/// Factors ≥ 1 multiplying the identified noise, and where each comes from.
#[derive(Debug, Clone, PartialEq)]
pub struct Inflation {
    /// Gyro white noise.
    pub gyro_noise: f64,
    /// Accelerometer white noise.
    pub accel_noise: f64,
    /// Gyro bias random walk.
    pub gyro_walk: f64,
    /// Accelerometer bias random walk.
    pub accel_walk: f64,
    /// One sentence per factor (or why there is none).
    pub reasons: Vec<String>,
}

impl Inflation {
    /// No inflation, with the reason.
    pub fn none(reason: &str) -> Inflation {
        Inflation { gyro_noise: 1.0, accel_noise: 1.0, gyro_walk: 1.0, accel_walk: 1.0, reasons: vec![reason.into()] }
    }

    /// From the audit of the same recording. White noise: each residual
    /// group's χ² per residual says how much larger the errors in motion are
    /// than the white noise the audit measured at rest on the same recording;
    /// the figure is multiplied by √(χ²/n) when that exceeds 1 (`rotation` →
    /// gyro, `accel_norm` → accelerometer). Random walks: the bias-walk groups
    /// were whitened with the walk the audit assumed (`random_walk_raw`, over
    /// the mean scale `k` of [`crate::model::calibration::Triad::mean_scale`]); the walk they imply, assumed·√(χ²/n), multiplies
    /// `noise`'s walk when it is the larger. Never deflated.
    pub fn from_audit(audit: &AuditSummary, noise: &ImuNoise, mean_k: (f64, f64)) -> Inflation {
        let mut inf = Inflation::none("");
        inf.reasons.clear();
        let ratio =
            |group: &str| audit.groups.get(group).filter(|g| g.residuals > 0).map(|g| g.chi2 / g.residuals as f64);
        for (group, slot, what) in [
            ("rotation", &mut inf.gyro_noise, "gyro white noise"),
            ("accel_norm", &mut inf.accel_noise, "accelerometer white noise"),
        ] {
            inf.reasons.push(match ratio(group) {
                Some(r) => {
                    *slot = r.max(1.0).sqrt();
                    format!("{what} x{:.2}: the audit's {group} residuals have chi2/n = {r:.2}", *slot)
                }
                None => format!("{what} x1: the audit has no {group} residuals"),
            });
        }
        let raw = audit.random_walk_raw.as_ref();
        for (group, slot, what, assumed, own) in [
            (
                "gyro_bias_walk",
                &mut inf.gyro_walk,
                "gyro random walk",
                raw.map(|w| w.gyro / mean_k.0),
                noise.gyroscope_random_walk,
            ),
            (
                "accel_bias_walk",
                &mut inf.accel_walk,
                "accelerometer random walk",
                raw.map(|w| w.accel / mean_k.1),
                noise.accelerometer_random_walk,
            ),
        ] {
            inf.reasons.push(match (ratio(group), assumed) {
                (Some(r), Some(w)) if w.is_finite() && w > 0.0 => {
                    let implied = w * r.sqrt();
                    *slot = (implied / own).max(1.0);
                    format!(
                        "{what} x{:.2}: the audit's {group} residuals (chi2/n = {r:.2} with {w:.3e}) imply {implied:.3e}; imu.yaml has {own:.3e}",
                        *slot
                    )
                }
                _ => format!("{what} x1: the audit records no {group} residuals or the walk it assumed"),
            });
        }
        inf
    }
}

/// The part of `audit.json` the inflation reads.
#[derive(Debug, Clone, Default, serde::Deserialize)]
pub struct AuditSummary {
    /// χ² and residual count per residual group of the final model.
    #[serde(rename = "final_groups")]
    pub groups: std::collections::BTreeMap<String, AuditGroup>,
    /// The bias random walks the audit assumed, in raw units per √Hz (physical × mean scale).
    #[serde(default)]
    pub random_walk_raw: Option<AuditWalks>,
}

/// The audit's assumed random walks (`random_walk_raw` in `audit.json`).
#[derive(Debug, Clone, Copy, Default, serde::Deserialize)]
pub struct AuditWalks {
    /// Gyro \[raw/s/√Hz\].
    pub gyro: f64,
    /// Accelerometer \[raw/s/√Hz\].
    pub accel: f64,
}

/// One residual group of the audit.
#[derive(Debug, Clone, Copy, Default, serde::Deserialize)]
pub struct AuditGroup {
    /// Sum of squared whitened residuals.
    pub chi2: f64,
    /// Number of residuals.
    pub residuals: usize,
}

/// Everything an export writes from.
#[derive(Debug, Clone)]
pub struct ExportInputs {
    /// Continuous-time noise (`imu.yaml`).
    pub noise: ImuNoise,
    /// IMU update rate \[Hz\].
    pub rate_hz: f64,
    /// The IMU topic.
    pub imu_topic: String,
    /// The calibration, if any.
    pub calibration: Option<ImuCalibration>,
    /// Noise inflation and its reasons.
    pub inflation: Inflation,
    /// Cameras (none without an ASL folder).
    pub cameras: Vec<RigCamera>,
    /// The camera–IMU time offset of a `tumble calibrate-rig` output given as
    /// the ASL folder (`rig.json`'s `timeshift_cam_imu_s`) \[s\]; it wins over
    /// the calibration's audited one.
    pub rig_time_offset_s: Option<f64>,
    /// Where each input came from (for the files' headers).
    pub sources: Vec<String>,
}

/// Where to look for the inputs (explicit files win over the results folder).
#[derive(Debug, Clone, Default)]
pub struct ExportSources {
    /// A results folder of `tumble run` (calibrate/, allan/, audit/) or of one command.
    pub results: Option<PathBuf>,
    /// `calibration.json` / `.yaml`.
    pub calibration: Option<PathBuf>,
    /// Kalibr `imu.yaml`.
    pub noise: Option<PathBuf>,
    /// `audit.json` of the same recording.
    pub audit: Option<PathBuf>,
    /// An ASL folder whose `camN/sensor.yaml` and `imu0/sensor.yaml` give the
    /// cameras and extrinsics, or the output folder of `tumble calibrate-rig`.
    pub asl: Option<PathBuf>,
}

fn first_file(results: Option<&Path>, rels: &[&str]) -> Option<PathBuf> {
    let r = results?;
    rels.iter().map(|p| r.join(p)).find(|p| p.is_file())
}

/// The figures of `imu.yaml` beyond [`ImuNoise`].
#[derive(serde::Deserialize)]
struct KalibrExtra {
    update_rate: Option<f64>,
    rostopic: Option<String>,
}

impl ExportInputs {
    /// Gather the inputs: explicit files, else the results folder's
    /// (`audit/calibration.json` before `calibrate/calibration.json` before
    /// `calibration.json`; `allan/imu.yaml` or `imu.yaml`; `audit/audit.json`
    /// or `audit.json`). The noise is required.
    pub fn gather(src: &ExportSources) -> Result<ExportInputs, InputError> {
        let res = src.results.as_deref();
        if let Some(r) = res {
            if !r.is_dir() {
                return Err(InputError::file(r, "is not a results folder"));
            }
        }
        let noise_path =
            src.noise.clone().or_else(|| first_file(res, &["allan/imu.yaml", "imu.yaml"])).ok_or_else(|| {
                InputError::file(res.unwrap_or(Path::new(".")), "no imu.yaml here (allan/imu.yaml or imu.yaml)")
                    .with_hint("give --noise IMU.yaml (from `tumble allan`, or `tumble noise` from a datasheet)")
            })?;
        let noise = ImuNoise::read(&noise_path)?;
        let extra: KalibrExtra = crate::io::yaml::read_yaml(&noise_path)?;
        let rate_hz = extra.update_rate.filter(|r| r.is_finite() && *r > 0.0).ok_or_else(|| {
            InputError::file(&noise_path, "needs update_rate (the IMU rate in Hz) for the discrete-time conversions")
        })?;
        let mut sources = vec![format!("noise: {}", noise_path.display())];
        let cal_path = src
            .calibration
            .clone()
            .or_else(|| first_file(res, &["audit/calibration.json", "calibrate/calibration.json", "calibration.json"]));
        let calibration = cal_path.as_deref().map(ImuCalibration::read).transpose()?;
        if let Some(p) = &cal_path {
            sources.push(format!("calibration: {}", p.display()));
        }
        let audit_path = src.audit.clone().or_else(|| first_file(res, &["audit/audit.json", "audit.json"]));
        let inflation = match &audit_path {
            Some(p) => {
                let text = std::fs::read_to_string(p).map_err(|e| InputError::file(p, e.to_string()))?;
                let a: AuditSummary =
                    serde_json::from_str(&text).map_err(|e| InputError::at(p, e.line(), e.to_string()))?;
                sources.push(format!("audit: {}", p.display()));
                let k = calibration.as_ref().map(|c| (c.gyro.mean_scale(), c.accel.mean_scale())).unwrap_or((1.0, 1.0));
                Inflation::from_audit(&a, &noise, k)
            }
            None => Inflation::none(
                "no audit of this recording: the noise is as identified at rest, not inflated (run `tumble audit` \
                 with this imu.yaml for factors measured in motion)",
            ),
        };
        let cameras = match &src.asl {
            Some(dir) => {
                sources.push(format!("cameras: {}", dir.display()));
                rig_cameras(dir)?
            }
            None => Vec::new(),
        };
        // A rig calibration measured the time offset on a target: it is the one to use.
        let rig_time_offset_s = match &src.asl {
            Some(dir) if is_rig_output(dir) => {
                let t = crate::io::target::RigCalibration::read(dir)?.time_offset_s;
                sources.push(format!("camera–IMU time offset: {} ({:.3} ms)", dir.join("rig.json").display(), t * 1e3));
                Some(t)
            }
            _ => None,
        };
        Ok(ExportInputs {
            noise,
            rate_hz,
            imu_topic: extra.rostopic.unwrap_or_else(|| "/imu0".into()),
            calibration,
            inflation,
            cameras,
            rig_time_offset_s,
            sources,
        })
    }

    /// Continuous-time figures per axis `[x, y, z]`, inflated:
    /// (gyro noise, accel noise, gyro walk, accel walk).
    pub fn axes(&self) -> [[f64; 3]; 4] {
        let a = self.noise.per_axis();
        let i = &self.inflation;
        let (gn, an, gw, aw) = (
            a.gyroscope_noise_density,
            a.accelerometer_noise_density,
            a.gyroscope_random_walk,
            a.accelerometer_random_walk,
        );
        [
            gn.map(|v| v * i.gyro_noise),
            an.map(|v| v * i.accel_noise),
            gw.map(|v| v * i.gyro_walk),
            aw.map(|v| v * i.accel_walk),
        ]
    }

    /// One figure per sensor in `convention` (Kalibr's scalars: the worst axis), inflated:
    /// (gyro noise, accel noise, gyro walk, accel walk).
    pub fn scalars(&self, convention: NoiseConvention) -> [f64; 4] {
        let n = &self.noise;
        let i = &self.inflation;
        let c = [
            n.gyroscope_noise_density * i.gyro_noise,
            n.accelerometer_noise_density * i.accel_noise,
            n.gyroscope_random_walk * i.gyro_walk,
            n.accelerometer_random_walk * i.accel_walk,
        ];
        match convention {
            NoiseConvention::Continuous => c,
            NoiseConvention::DiscretePerSample => c.map(|v| v * self.rate_hz.sqrt()),
        }
    }

    /// The calibration's effects outside `modelled` (they need `tumble apply`).
    fn unmodelled_effects(&self, modelled: &[&str]) -> Vec<String> {
        self.calibration
            .as_ref()
            .map(|c| c.effect_ids())
            .unwrap_or_default()
            .into_iter()
            .filter(|e| !modelled.contains(&e.as_str()))
            .collect()
    }

    /// The camera–IMU time offset \[s\] (frame stamped t taken at IMU time t +
    /// offset): the rig calibration's, else the calibration's audited one, else 0.
    fn camera_time_offset(&self) -> f64 {
        self.rig_time_offset_s
            .or_else(|| self.calibration.as_ref().and_then(|c| c.time_offsets).map(|t| t.camera_imu_s))
            .unwrap_or(0.0)
    }
}

/// Whether `dir` is the output folder of `tumble calibrate-rig` (`rig.json` beside `cam0/sensor.yaml`).
fn is_rig_output(dir: &Path) -> bool {
    dir.join("rig.json").is_file() && dir.join("cam0").join("sensor.yaml").is_file()
}

/// The cameras of an ASL folder (or of `tumble calibrate-rig`'s output, whose
/// `camN/sensor.yaml` sit beside `rig.json`): intrinsics, resolution, rate and
/// IMU ← camera from the `T_BS` of both sensors.
fn rig_cameras(dir: &Path) -> Result<Vec<RigCamera>, InputError> {
    let root = if is_rig_output(dir) { dir.to_path_buf() } else { crate::io::asl::resolve_mav0(dir)? };
    let imu_yaml = root.join("imu0").join("sensor.yaml");
    let body_imu = if imu_yaml.is_file() {
        crate::io::asl::read_imu_sensor(&imu_yaml)?.t_bs
    } else {
        nalgebra::Isometry3::identity()
    };
    let mut cams = Vec::new();
    for k in 0..8 {
        let yaml = root.join(format!("cam{k}")).join("sensor.yaml");
        if !yaml.is_file() {
            continue;
        }
        let (model, t_bs, res, rate) = crate::io::asl::read_camera_sensor(&yaml)?;
        let t_bs =
            t_bs.ok_or_else(|| InputError::file(&yaml, "has no T_BS: the camera's pose on the body is unknown"))?;
        let resolution = res.ok_or_else(|| InputError::file(&yaml, "has no resolution"))?;
        cams.push(RigCamera {
            model,
            resolution,
            rate_hz: rate.unwrap_or(20.0),
            t_imu_cam: body_imu.inverse() * t_bs,
            topic: format!("/cam{k}/image_raw"),
        });
    }
    if cams.is_empty() {
        return Err(InputError::file(&root, "has no camN/sensor.yaml"));
    }
    Ok(cams)
}

/// What an export wrote and what the user must know.
#[derive(Debug, Clone, Default)]
pub struct ExportReport {
    /// Files written.
    pub files: Vec<PathBuf>,
    /// Conversions made and what the estimator does not model.
    pub notes: Vec<String>,
}

/// Write `target`'s configuration from `inputs` into `out` (all files or none).
pub fn export(target: Target, inputs: &ExportInputs, out: &Path) -> Result<ExportReport, OutputError> {
    let (files, notes) = targets::render(target, inputs)?;
    let written = crate::io::staging::write_staged(out, |stage| -> Result<Vec<PathBuf>, OutputError> {
        let mut paths = Vec::new();
        for (name, text) in &files {
            let p = stage.join(name);
            std::fs::write(&p, text).map_err(|e| format!("{}: {e}", p.display()))?;
            paths.push(p);
        }
        Ok(paths)
    })?;
    Ok(ExportReport { files: written, notes })
}

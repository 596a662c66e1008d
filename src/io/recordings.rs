//! A YAML file describing each recording of a run with its own reading
//! options (`tumble run --inputs recordings.yaml`), so that a static log in
//! one CSV layout, a tumble in another and a bag go through one run:
//!
//! ```yaml
//! tumble:
//!   path: tumble_2024-05-01.csv      # relative to this file
//!   columns: t,ax,ay,az,gx,gy,gz
//!   time_unit: ms
//!   gyro_unit: deg/s
//!   accel_unit: g
//! static:
//!   path: overnight.db3
//!   topic: /imu/data
//! ```
//!
//! `tumble calibrate --inputs` pools several tumbles of one sensor: give
//! them as a list under `tumbles:` (with or without `tumble:`, which then
//! comes first):
//!
//! ```yaml
//! tumbles:
//!   - path: monday.csv
//!     columns: t,ax,ay,az,gx,gy,gz
//!   - path: tuesday.csv
//!     columns: t,ax,ay,az,gx,gy,gz
//! ```
//!
//! Keys per recording: `path` (required), `columns`, `time_unit`,
//! `gyro_unit`, `accel_unit`, `rate` \[Hz\], `gyro_file` (imu_tk's second
//! file), `topic`, `accel_topic`, `gyro_topic`, `temperature_topic`,
//! `strict_timestamps`, `unit_check` — the same meanings as the command
//! line's flags. Unknown keys are refused.

use super::recording::{Declared, RecordingSource, SourceError};
use super::ros::ImuTopics;
use super::validate::Duplicates;
use super::{AccelUnit, GyroUnit, ImuColumns, RecordingOptions, TimeUnit};
use crate::error::{InputError, OptionError};
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// One recording as the file describes it.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RecordingSpec {
    /// The recording (relative paths are relative to the description file).
    pub path: PathBuf,
    /// Text files: column names in file order (`t,gx,gy,gz,ax,ay,az`).
    pub columns: Option<String>,
    /// Text files: `s`, `ms`, `us` or `ns`.
    pub time_unit: Option<String>,
    /// Text files: `rad/s`, `deg/s`, `counts`, `counts:SCALE[:OFFSET]`.
    pub gyro_unit: Option<String>,
    /// Text files: `m/s2`, `g`, `counts`, `counts:SCALE[:OFFSET]`.
    pub accel_unit: Option<String>,
    /// Nominal sample rate \[Hz\].
    pub rate: Option<f64>,
    /// imu_tk layout: the gyro file (then `path` is the accelerometer file).
    pub gyro_file: Option<PathBuf>,
    /// ROS: the IMU topic.
    pub topic: Option<String>,
    /// ROS split streams: the accelerometer topic.
    pub accel_topic: Option<String>,
    /// ROS split streams: the gyro topic.
    pub gyro_topic: Option<String>,
    /// ROS: a temperature topic.
    pub temperature_topic: Option<String>,
    /// Refuse duplicated timestamps instead of re-stamping.
    #[serde(default)]
    pub strict_timestamps: bool,
    /// Check that values at rest look like rad/s and m/s² (default true).
    pub unit_check: Option<bool>,
}

/// The recordings of one run.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunRecordings {
    /// The hand-tumbled calibration recording.
    pub tumble: Option<RecordingSpec>,
    /// The static recording for the Allan stage.
    #[serde(rename = "static")]
    pub still: Option<RecordingSpec>,
    /// More hand-tumbled recordings of the same sensor (`tumble calibrate --inputs` pools them).
    #[serde(default)]
    pub tumbles: Vec<RecordingSpec>,
}

impl RunRecordings {
    /// Read and check a description file; paths become relative to its folder.
    pub fn read(path: &Path) -> Result<RunRecordings, InputError> {
        let mut r: RunRecordings = super::yaml::read_yaml(path)?;
        if r.tumble.is_none() && r.still.is_none() && r.tumbles.is_empty() {
            return Err(InputError::file(path, "describes no recording (give `tumble:`, `tumbles:` and/or `static:`)"));
        }
        let base = path.parent().unwrap_or(Path::new("."));
        let listed = r.tumbles.iter_mut().enumerate().map(|(i, s)| (Some(s), format!("tumbles[{i}]")));
        let single = [(r.tumble.as_mut(), "tumble".to_string()), (r.still.as_mut(), "static".to_string())];
        for (spec, key) in single.into_iter().chain(listed) {
            if let Some(s) = spec {
                if s.path.is_relative() {
                    s.path = base.join(&s.path);
                }
                if let Some(g) = &mut s.gyro_file {
                    if g.is_relative() {
                        *g = base.join(&*g);
                    }
                }
                s.source().map_err(|e| InputError::file(path, format!("{key}: {e}")))?;
            }
        }
        Ok(r)
    }

    /// Every tumble described, `tumble:` first, then `tumbles:` in order.
    pub fn all_tumbles(&self) -> Vec<&RecordingSpec> {
        self.tumble.iter().chain(&self.tumbles).collect()
    }

    /// The one tumble of a run (`tumble run` calibrates from one recording):
    /// an error when `tumbles:` lists more.
    pub fn single_tumble(&self) -> Result<Option<&RecordingSpec>, OptionError> {
        match self.all_tumbles()[..] {
            [] => Ok(None),
            [one] => Ok(Some(one)),
            ref several => Err(OptionError::new(
                "tumbles:",
                format!(
                    "{} tumbles described: `tumble run` calibrates from one; pool several with                      `tumble calibrate --inputs`, then give its calibration.json to `tumble run --calibration`",
                    several.len()
                ),
            )),
        }
    }
}

impl RecordingSpec {
    /// A short name: the recording's file or folder name.
    pub fn name(&self) -> String {
        self.path.file_name().map_or_else(|| self.path.display().to_string(), |n| n.to_string_lossy().into_owned())
    }

    /// The reading options this entry gives (the readers' defaults elsewhere).
    pub fn options(&self) -> Result<RecordingOptions, OptionError> {
        fn key(k: &'static str) -> impl Fn(OptionError) -> OptionError {
            move |e| OptionError::new(format!("{k}:"), e.to_string())
        }
        let mut o = RecordingOptions::default();
        if let Some(c) = &self.columns {
            o.format.columns = ImuColumns::parse(c).map_err(key("columns"))?;
        }
        if let Some(t) = &self.time_unit {
            o.format.time_unit = TimeUnit::parse(t)
                .ok_or_else(|| OptionError::new("time_unit:", format!("'{t}': use s, ms, us or ns")))?;
        }
        if let Some(u) = &self.gyro_unit {
            o.format.gyro_unit = GyroUnit::parse(u).map_err(key("gyro_unit"))?;
        }
        if let Some(u) = &self.accel_unit {
            o.format.accel_unit = AccelUnit::parse(u).map_err(key("accel_unit"))?;
        }
        o.format.validate.nominal_rate = self.rate;
        o.format.validate.check_units = self.unit_check.unwrap_or(true);
        if self.strict_timestamps {
            o.format.validate.duplicates = Duplicates::Error;
        }
        o.format.validate.check()?;
        o.gyro_file = self.gyro_file.clone();
        o.topics = ImuTopics {
            imu: self.topic.clone(),
            accel: self.accel_topic.clone(),
            gyro: self.gyro_topic.clone(),
            temperature: self.temperature_topic.clone(),
        };
        o.topics.check()?;
        Ok(o)
    }

    /// The recording source (imu_tk pairs resolved as on the command line).
    pub fn source(&self) -> Result<RecordingSource, SourceError> {
        let declared = Declared {
            time_unit: self.time_unit.is_some(),
            units: self.gyro_unit.is_some() || self.accel_unit.is_some(),
        };
        RecordingSource::new(Some(self.path.clone()), None, self.gyro_file.is_some(), self.options()?, declared)
    }

    /// One line saying which options were used.
    pub fn describe(&self) -> String {
        let mut parts = vec![self.path.display().to_string()];
        for (k, v) in [
            ("columns", &self.columns),
            ("time", &self.time_unit),
            ("gyro", &self.gyro_unit),
            ("accel", &self.accel_unit),
            ("topic", &self.topic),
            ("accel topic", &self.accel_topic),
            ("gyro topic", &self.gyro_topic),
            ("temperature topic", &self.temperature_topic),
        ] {
            if let Some(v) = v {
                parts.push(format!("{k} {v}"));
            }
        }
        if let Some(r) = self.rate {
            parts.push(format!("rate {r} Hz"));
        }
        if let Some(g) = &self.gyro_file {
            parts.push(format!("gyro file {}", g.display()));
        }
        parts.join(", ")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_recording_carries_its_options_and_bad_ones_are_named() {
        let dir = std::env::temp_dir().join(format!("tumble-recordings-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("recordings.yaml");
        std::fs::write(
            &p,
            "tumble:\n  path: t.csv\n  columns: t,ax,ay,az,gx,gy,gz\n  gyro_unit: deg/s\n  accel_unit: g\n  time_unit: ms\nstatic:\n  path: s.db3\n  topic: /imu\n",
        )
        .unwrap();
        let r = RunRecordings::read(&p).unwrap();
        let t = r.tumble.unwrap();
        assert_eq!(t.path, dir.join("t.csv"));
        let o = t.options().unwrap();
        assert_eq!((o.format.time_unit, o.format.gyro_unit), (TimeUnit::Ms, GyroUnit::DegPerS));
        assert!(t.describe().contains("gyro deg/s"));
        assert_eq!(r.still.unwrap().options().unwrap().topics.imu.as_deref(), Some("/imu"));
        std::fs::write(&p, "tumble:\n  path: t.csv\n  gyro_unit: furlongs\n").unwrap();
        let e = RunRecordings::read(&p).unwrap_err().to_string();
        assert!(e.contains("recordings.yaml") && e.contains("tumble: gyro_unit"), "{e}");
        std::fs::write(&p, "tumbles:\n  - path: a.csv\n  - path: b.csv\n    gyro_unit: deg/s\n").unwrap();
        let r = RunRecordings::read(&p).unwrap();
        assert_eq!(r.all_tumbles().iter().map(|s| s.name()).collect::<Vec<_>>(), ["a.csv", "b.csv"]);
        assert!(r.single_tumble().unwrap_err().to_string().contains("calibrate --inputs"));
        std::fs::write(&p, "tumbles:\n  - path: a.csv\n  - path: b.csv\n    gyro_unit: parsecs\n").unwrap();
        let e = RunRecordings::read(&p).unwrap_err().to_string();
        assert!(e.contains("tumbles[1]: gyro_unit"), "{e}");
        std::fs::write(&p, "tumble:\n  path: t.csv\n  colums: t,gx\n").unwrap();
        let e = RunRecordings::read(&p).unwrap_err().to_string();
        assert!(e.contains("recordings.yaml:3") && e.contains("colums"), "{e}");
    }
}

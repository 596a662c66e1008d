//! ROS recordings: ROS 1 bags, MCAP files, rosbag2 SQLite files and rosbag2
//! folders ([`container`]), their messages decoded by hand ([`msgs`]; ROS 1
//! serialization and CDR are fixed layouts for the messages read), into an
//! [`ImuRecording`].
//!
//! Times are the messages' `header.stamp` (the recorder's receive time for
//! messages a driver left unstamped, with a warning). The IMU is one `sensor_msgs/Imu`
//! topic, or an accelerometer topic and a gyro topic merged onto the gyro's
//! stamps ([`crate::io::split`]); a `sensor_msgs/Temperature` topic is joined
//! by time. Topics are chosen by name, or automatically when the choice is
//! unambiguous (one IMU topic; exactly two whose names contain `accel` and
//! `gyro`; one temperature topic).

pub mod container;
pub mod msgs;
mod ros1;

pub use container::{normalize_type, RawMessage, Storage, TopicInfo};

use super::imu::{ImuRecording, Stored};
use super::split::{join_temperature, merge_onto_gyro, Stream};
use super::table::LineMap;
use super::validate::{validate, ValidateOptions};
use crate::error::InputError;
use std::collections::BTreeMap;
use std::path::Path;

/// Which topics make the IMU recording (all optional: see the module doc).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ImuTopics {
    /// One `sensor_msgs/Imu` topic holding both sensors.
    pub imu: Option<String>,
    /// Split streams: the topic whose `linear_acceleration` is read.
    pub accel: Option<String>,
    /// Split streams: the topic whose `angular_velocity` is read.
    pub gyro: Option<String>,
    /// A `sensor_msgs/Temperature` topic joined by time.
    pub temperature: Option<String>,
}

impl ImuTopics {
    /// Check that the topics asked for fit together (the library's one check of these options).
    pub fn check(&self) -> Result<(), crate::OptionError> {
        match (&self.imu, &self.accel, &self.gyro) {
            (Some(_), Some(_), _) | (Some(_), _, Some(_)) => {
                Err(crate::OptionError::new("--topic", "cannot be combined with --accel-topic/--gyro-topic"))
            }
            (None, Some(_), None) | (None, None, Some(_)) => {
                Err(crate::OptionError::new("--accel-topic", "and --gyro-topic go together (split streams need both)"))
            }
            _ => Ok(()),
        }
    }
}

/// One decoded `sensor_msgs/Imu`: stamp \[ns\], angular rate \[rad/s\], specific force \[m/s²\].
type ImuMessage = (i64, [f64; 3], [f64; 3]);

/// The chosen topics, resolved against what the file holds.
enum Choice {
    One(String),
    Split { accel: String, gyro: String },
}

fn list(topics: &[&TopicInfo]) -> String {
    topics.iter().map(|t| t.name.as_str()).collect::<Vec<_>>().join(", ")
}

fn choose(path: &Path, all: &[TopicInfo], want: &ImuTopics) -> Result<(Choice, Option<String>), InputError> {
    let of_type = |t: &str| all.iter().filter(|i| i.msg_type == t).collect::<Vec<_>>();
    let imus = of_type("sensor_msgs/Imu");
    let temps = of_type("sensor_msgs/Temperature");
    let known = |name: &str, list_of: &[&TopicInfo], what: &str| -> Result<String, InputError> {
        if list_of.iter().any(|t| t.name == name) {
            return Ok(name.to_string());
        }
        let e = InputError::file(path, format!("no {what} topic '{name}'"));
        Err(if list_of.is_empty() {
            e.with_hint(format!("the file holds no {what} topic"))
        } else {
            e.with_hint(format!("{what} topics here: {}", list(list_of)))
        })
    };
    let imu = match (&want.imu, &want.accel, &want.gyro) {
        (Some(t), _, _) => Choice::One(known(t, &imus, "sensor_msgs/Imu")?),
        (None, Some(a), Some(g)) => {
            Choice::Split { accel: known(a, &imus, "sensor_msgs/Imu")?, gyro: known(g, &imus, "sensor_msgs/Imu")? }
        }
        _ => match imus.as_slice() {
            [] => {
                let hint = if all.is_empty() {
                    "the file holds no topics".to_string()
                } else {
                    format!(
                        "topics here: {}",
                        all.iter().map(|t| format!("{} ({})", t.name, t.msg_type)).collect::<Vec<_>>().join(", ")
                    )
                };
                return Err(InputError::file(path, "holds no sensor_msgs/Imu topic").with_hint(hint));
            }
            [one] => Choice::One(one.name.clone()),
            [a, b] if a.name.contains("accel") && b.name.contains("gyro") => {
                Choice::Split { accel: a.name.clone(), gyro: b.name.clone() }
            }
            [a, b] if a.name.contains("gyro") && b.name.contains("accel") => {
                Choice::Split { accel: b.name.clone(), gyro: a.name.clone() }
            }
            _ => {
                return Err(InputError::file(path, "holds several sensor_msgs/Imu topics").with_hint(format!(
                    "choose one with --topic, or split streams with --accel-topic and --gyro-topic: {}",
                    list(&imus)
                )))
            }
        },
    };
    let temperature = match &want.temperature {
        Some(t) => Some(known(t, &temps, "sensor_msgs/Temperature")?),
        None if temps.len() == 1 => Some(temps[0].name.clone()),
        None => None,
    };
    Ok((imu, temperature))
}

/// Read an IMU recording from a ROS storage (see the module doc for how
/// topics are chosen). The recording's `topic` says which were read.
pub fn read_ros_imu(storage: &Storage, want: &ImuTopics, checks: &ValidateOptions) -> Result<ImuRecording, InputError> {
    let path = storage.path().to_path_buf();
    want.check().map_err(|e| InputError::file(&path, e))?;
    let all = storage.topic_types()?;
    let (choice, temp_topic) = choose(&path, &all, want)?;
    let mut topics: Vec<&str> = match &choice {
        Choice::One(t) => vec![t.as_str()],
        Choice::Split { accel, gyro } => vec![accel.as_str(), gyro.as_str()],
    };
    topics.extend(temp_topic.as_deref());
    // One (stamp, ω, a) per message: 56 bytes, the recording's own size.
    let mut by_topic: BTreeMap<String, Vec<ImuMessage>> = BTreeMap::new();
    let mut temps: Vec<(i64, f64)> = Vec::new();
    // Drivers that leave header.stamp at zero: the recorder's receive time is the only clock.
    let mut unstamped = 0usize;
    storage.for_each(&topics, &mut |m| {
        let bad = |what: &str| InputError::file(&path, format!("a message on {} is not a {what} (too short)", m.topic));
        if Some(m.topic) == temp_topic.as_deref() {
            temps.push(msgs::temperature(m.encoding, m.data).ok_or_else(|| bad("sensor_msgs/Temperature"))?);
        } else {
            let mut msg = msgs::imu(m.encoding, m.data).ok_or_else(|| bad("sensor_msgs/Imu"))?;
            if msg.0 == 0 {
                unstamped += 1;
                msg.0 = m.log_time_ns;
            }
            match by_topic.get_mut(m.topic) {
                Some(v) => v.push(msg),
                None => {
                    by_topic.insert(m.topic.to_string(), vec![msg]);
                }
            }
        }
        Ok(())
    })?;
    let mut take = |t: &str| by_topic.remove(t).unwrap_or_default();
    let mut notes = Vec::new();
    if unstamped > 0 {
        notes.push(format!(
            "{unstamped} IMU messages have header.stamp = 0: stamped with the recorder's receive time instead \
             (transport jitter included; the checks below judge it)"
        ));
    }
    let (t_ns, gyro, accel, topic) = match &choice {
        Choice::One(t) => {
            let mut m = take(t);
            if m.is_empty() {
                return Err(InputError::file(&path, format!("the IMU topic {t} has no messages")));
            }
            // Bags store messages in arrival order; the validation then judges the stamps.
            m.sort_by_key(|x| x.0);
            (
                m.iter().map(|x| x.0).collect::<Vec<_>>(),
                m.iter().map(|x| x.1).collect(),
                m.iter().map(|x| x.2).collect(),
                t.clone(),
            )
        }
        Choice::Split { accel, gyro } => {
            let g = take(gyro);
            let a = take(accel);
            let g = Stream { t_ns: g.iter().map(|x| x.0).collect(), v: g.iter().map(|x| x.1).collect() };
            let a = Stream { t_ns: a.iter().map(|x| x.0).collect(), v: a.iter().map(|x| x.2).collect() };
            let m = merge_onto_gyro(g, a).map_err(|e| InputError::file(&path, format!("{accel} + {gyro}: {e}")))?;
            notes.push(format!("{accel} + {gyro}: {}", m.note));
            notes.extend(m.warnings.iter().map(|w| format!("{accel}: {w}")));
            (m.t_ns, m.gyro, m.accel, format!("{accel} + {gyro}"))
        }
    };
    if gyro.iter().chain(&accel).flatten().any(|v| !v.is_finite()) {
        return Err(InputError::file(&path, format!("an IMU message on {topic} holds a non-finite value")));
    }
    let temperature = match &temp_topic {
        Some(tt) if !temps.is_empty() => {
            let (v, outside) = join_temperature(&t_ns, &temps);
            notes.push(format!("temperature from {tt} ({} messages) joined by time", temps.len()));
            if outside > 0 {
                notes.push(format!("{outside} IMU samples lie outside {tt}'s span: its first/last value held there"));
            }
            Some(v)
        }
        Some(tt) => {
            notes.push(format!("{tt} has no messages: no temperature"));
            None
        }
        None => None,
    };
    let t0 = t_ns[0];
    let mut rec = ImuRecording {
        sources: vec![path.clone()],
        topic: Some(topic),
        t0_ns: t0,
        t: t_ns.iter().map(|&t| (t - t0) as f64 * 1e-9).collect(),
        gyro,
        accel,
        temperature,
        gyro_units: Stored::Si,
        accel_units: Stored::Si,
        lines: LineMap::default(),
        warnings: notes,
    };
    validate(&mut rec, checks)?;
    Ok(rec)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn info(name: &str, t: &str) -> TopicInfo {
        TopicInfo { name: name.into(), msg_type: t.into(), count: None }
    }

    #[test]
    fn topics_are_chosen_only_when_unambiguous() {
        let p = Path::new("x.db3");
        let rs = [
            info("/camera/accel/sample", "sensor_msgs/Imu"),
            info("/camera/gyro/sample", "sensor_msgs/Imu"),
            info("/imu_temp", "sensor_msgs/Temperature"),
        ];
        let (c, t) = choose(p, &rs, &ImuTopics::default()).unwrap();
        assert!(matches!(c, Choice::Split { ref accel, ref gyro } if accel.contains("accel") && gyro.contains("gyro")));
        assert_eq!(t.as_deref(), Some("/imu_temp"));
        let three = [info("/a", "sensor_msgs/Imu"), info("/b", "sensor_msgs/Imu"), info("/c", "sensor_msgs/Imu")];
        let e = choose(p, &three, &ImuTopics::default()).err().unwrap().to_string();
        assert!(e.contains("several") && e.contains("/a, /b, /c"), "{e}");
        let want = ImuTopics { imu: Some("/d".into()), ..Default::default() };
        assert!(choose(p, &three, &want).err().unwrap().to_string().contains("no sensor_msgs/Imu topic '/d'"));
        let bad = ImuTopics { accel: Some("/a".into()), ..Default::default() };
        assert!(bad.check().unwrap_err().to_string().contains("--accel-topic and --gyro-topic go together"));
        let e = choose(p, &[info("/img", "sensor_msgs/Image")], &ImuTopics::default()).err().unwrap().to_string();
        assert!(e.contains("no sensor_msgs/Imu") && e.contains("/img (sensor_msgs/Image)"), "{e}");
    }
}

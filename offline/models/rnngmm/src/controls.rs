//! Control scripts for online speed and direction control (RNN-GMM control, paper sec. 5.3):
//! target speed and facing over time, read from JSON, replayed frame by frame, and the
//! benchmark's measure of how well a generated motion follows them.
//!
//! JSON: `{"units": "m" | "cm", "duration": 32, "keys": [{"time": 0, "speed": 1.2, "heading":
//! 0}, {"time": 4, "heading": 90}, ...]}`. Times in seconds from the start (the first key at 0,
//! strictly increasing); speed in units per second (metres by default); heading in degrees
//! about the up axis (+y): 0 faces +z, 90 faces +x. A key holds until the next one (steps); a
//! key without `speed` or `heading` keeps the previous value. `duration` (seconds, after the
//! last key) is where the script ends.
//!
//! Every value is range-checked like the command line's options: `duration` in (last key,
//! [`MAX_DURATION`] = 3600] seconds, at most [`MAX_KEYS`] keys, speeds from 0 to 10 m/s,
//! headings within +-[`MAX_HEADING_DEG`] degrees. A script is replayed in memory (`zoo control`
//! keeps the whole motion and writes it as one BVH), so its length is bounded like the other
//! in-memory outputs: one hour is 108,000 frames at 30 fps, about `zoo transition`'s 100,000.
//!
//! Internally speeds are in centimetres per second and headings in radians.

use std::path::Path;
use thiserror::Error;

/// Speeds above this (cm/s, 10 m/s) are refused: no locomotion data goes there.
pub const MAX_SPEED: f64 = 1000.0;

/// The longest script, seconds (one hour; the longest synthetic clip is as long).
pub const MAX_DURATION: f64 = 3600.0;

/// The most keys of a script (one every 36 ms over an hour).
pub const MAX_KEYS: usize = 100_000;

/// The largest heading, degrees either way (about 2,800 turns: headings may wind up).
pub const MAX_HEADING_DEG: f64 = 1e6;

/// A script that cannot be used, with what to do about it.
#[derive(Debug, Error)]
pub enum ControlError {
    /// The file could not be read.
    #[error("cannot read the control script {path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The cause.
        source: std::io::Error,
    },
    /// The script is malformed or out of range.
    #[error("{0}")]
    Invalid(String),
}

fn invalid(message: impl Into<String>) -> ControlError {
    ControlError::Invalid(message.into())
}

/// The controls from one time on.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ControlKey {
    /// Seconds from the start.
    pub time: f64,
    /// Target speed of the root on the ground (cm/s).
    pub speed: f64,
    /// Target facing: yaw about +y (radians; 0 faces +z, pi/2 faces +x).
    pub heading: f64,
}

/// Speed and heading over time.
#[derive(Clone, Debug, PartialEq)]
pub struct ControlScript {
    keys: Vec<ControlKey>,
    duration: f64,
}

/// `a - b` wrapped to [-pi, pi].
pub fn angle_difference(a: f64, b: f64) -> f64 {
    let tau = std::f64::consts::TAU;
    let d = (a - b).rem_euclid(tau);
    if d > std::f64::consts::PI { d - tau } else { d }
}

impl ControlScript {
    /// A script of `keys` (cm/s, radians) ending at `duration` seconds; checked as the JSON
    /// reader checks it.
    pub fn new(keys: Vec<ControlKey>, duration: f64) -> Result<Self, ControlError> {
        let Some(first) = keys.first() else {
            return Err(invalid(
                "a control script needs at least one key: give {\"time\": 0, \"speed\": ..., \"heading\": ...}",
            ));
        };
        if keys.len() > MAX_KEYS {
            return Err(invalid(format!(
                "the control script has {} keys, more than the {MAX_KEYS} zoo reads: give at most one key per change",
                keys.len()
            )));
        }
        if first.time != 0.0 {
            return Err(invalid(format!("the first control key must be at time 0, found {}", first.time)));
        }
        for (i, k) in keys.iter().enumerate() {
            if !k.time.is_finite() || (i > 0 && k.time <= keys[i - 1].time) {
                return Err(invalid(format!(
                    "control key {i} is at time {}: times must be finite and strictly increasing",
                    k.time
                )));
            }
            if k.time >= MAX_DURATION {
                return Err(invalid(format!(
                    "control key {i} is at time {:?} s: key times are in [0, {MAX_DURATION}) seconds (a script lasts \
                     at most one hour)",
                    k.time
                )));
            }
            if !(k.speed.is_finite() && (0.0..=MAX_SPEED).contains(&k.speed)) {
                return Err(invalid(format!(
                    "control key {i} has speed {} cm/s: a speed is a finite number from 0 to {} m/s",
                    k.speed,
                    MAX_SPEED / 100.0
                )));
            }
            if !(k.heading.is_finite() && k.heading.to_degrees().abs() <= MAX_HEADING_DEG) {
                return Err(invalid(format!(
                    "control key {i} has heading {:?} degrees: give a finite angle in [-{MAX_HEADING_DEG}, \
                     {MAX_HEADING_DEG}] degrees",
                    k.heading.to_degrees()
                )));
            }
        }
        let last = keys[keys.len() - 1].time;
        if !(duration.is_finite() && duration > last && duration <= MAX_DURATION) {
            return Err(invalid(format!(
                "`duration` is {duration:?} s: a script ends after its last key ({last} s) and lasts at most \
                 {MAX_DURATION} s (one hour), valid range ({last}, {MAX_DURATION}]"
            )));
        }
        Ok(ControlScript { keys, duration })
    }

    /// The script of a JSON description (see the module docs).
    pub fn from_json(text: &str) -> Result<Self, ControlError> {
        let v: serde_json::Value =
            serde_json::from_str(text).map_err(|e| invalid(format!("the control script does not parse: {e}")))?;
        let scale = match v.get("units").map(|u| u.as_str()) {
            None | Some(Some("m")) => 100.0,
            Some(Some("cm")) => 1.0,
            Some(other) => {
                return Err(invalid(format!("unknown control units {other:?}: use \"m\" or \"cm\" (per second)")));
            }
        };
        let keys = v.get("keys").and_then(|k| k.as_array()).ok_or_else(|| {
            invalid(
                "the control script needs `keys`: a list of {\"time\": s, \"speed\": units/s, \"heading\": degrees}",
            )
        })?;
        let number = |k: &serde_json::Value, i: usize, name: &str| -> Result<Option<f64>, ControlError> {
            match k.get(name) {
                None => Ok(None),
                Some(x) => x.as_f64().map(Some).ok_or_else(|| {
                    invalid(format!("control key {i}: `{name}` must be a number, found {x} (NaN is not a number)"))
                }),
            }
        };
        if keys.len() > MAX_KEYS {
            return Err(invalid(format!(
                "the control script has {} keys, more than the {MAX_KEYS} zoo reads: give at most one key per change",
                keys.len()
            )));
        }
        let mut out: Vec<ControlKey> = Vec::with_capacity(keys.len());
        for (i, k) in keys.iter().enumerate() {
            if !k.is_object() {
                return Err(invalid(format!("control key {i} is not an object: {k}")));
            }
            let time = number(k, i, "time")?.ok_or_else(|| invalid(format!("control key {i} has no `time`")))?;
            let prev = out.last().copied();
            let speed = match (number(k, i, "speed")?, prev) {
                (Some(s), _) => s * scale,
                (None, Some(p)) => p.speed,
                (None, None) => return Err(invalid("the first control key needs a `speed`")),
            };
            let heading = match (number(k, i, "heading")?, prev) {
                (Some(h), _) => h.to_radians(),
                (None, Some(p)) => p.heading,
                (None, None) => return Err(invalid("the first control key needs a `heading` (degrees)")),
            };
            out.push(ControlKey { time, speed, heading });
        }
        let duration = number(&v, 0, "duration")?.ok_or_else(|| {
            invalid("the control script needs `duration`: where it ends, in seconds after its last key")
        })?;
        Self::new(out, duration)
    }

    /// Reads a `.json` script.
    pub fn load(path: &Path) -> Result<Self, ControlError> {
        let text = std::fs::read_to_string(path)
            .map_err(|source| ControlError::Io { path: path.display().to_string(), source })?;
        Self::from_json(&text)
    }

    /// The keys.
    pub fn keys(&self) -> &[ControlKey] {
        &self.keys
    }

    /// Seconds.
    pub fn duration(&self) -> f64 {
        self.duration
    }

    /// The controls in force at `time` seconds (the last key at or before it).
    pub fn at(&self, time: f64) -> ControlKey {
        let i = self.keys.partition_point(|k| k.time <= time).saturating_sub(1);
        self.keys[i]
    }

    /// The benchmark's script (fixed before any result): 32 s of walking at 1.2 m/s, turning
    /// to 90 degrees, a 180-degree turn to -90, running at 3.5 m/s, a running 180-degree turn
    /// back to 90, walking, a stop, and walking off towards 0; 4 s per key.
    pub fn benchmark() -> Self {
        let (walk, run) = (120.0, 350.0);
        let r = f64::to_radians;
        let keys = [
            (walk, 0.0),
            (walk, 90.0),
            (walk, -90.0),
            (run, -90.0),
            (run, 90.0),
            (walk, 90.0),
            (0.0, 90.0),
            (walk, 0.0),
        ]
        .iter()
        .enumerate()
        .map(|(i, &(speed, h))| ControlKey { time: 4.0 * i as f64, speed, heading: r(h) })
        .collect();
        Self::new(keys, 32.0).expect("the benchmark script is valid")
    }
}

/// How one key's stretch of a motion follows it (see [`score`]).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct SegmentScore {
    /// The key's time (s).
    pub time: f64,
    /// Its target speed (cm/s) and heading (degrees).
    pub target_speed: f64,
    /// See `target_speed`.
    pub target_heading_deg: f64,
    /// Mean root speed over the half second from `settle` after the key (cm/s).
    pub speed_at_settle: f64,
    /// Mean root speed from `settle` after the key to the next key (cm/s).
    pub speed_after: f64,
    /// `|speed_after - target|` over the target; for a stop, over the speed of the key before.
    pub speed_error: f64,
    /// Facing error `settle` after the key (degrees, absolute).
    pub heading_at_settle_deg: f64,
    /// Mean and largest absolute facing error from `settle` after the key to the next key.
    pub heading_mean_deg: f64,
    /// See `heading_mean_deg`.
    pub heading_max_deg: f64,
    /// Speed error <= 10%, facing error at `settle` and its mean after <= 10 degrees.
    pub pass: bool,
}

/// Scores a motion against `script`: `speed` (cm/s) and `yaw` (radians) of each frame at `fps`
/// (frame `f` at time `f / fps`), each key's stretch measured from `settle` seconds after it
/// (the issue's 1 s). Keys whose stretch has no frame after `settle` are left out.
pub fn score(script: &ControlScript, fps: f64, speed: &[f64], yaw: &[f64], settle: f64) -> Vec<SegmentScore> {
    let keys = script.keys();
    let n = speed.len().min(yaw.len());
    let frame = |t: f64| ((t * fps).round().max(0.0) as usize).min(n);
    let mean = |v: &[f64]| if v.is_empty() { f64::NAN } else { v.iter().sum::<f64>() / v.len() as f64 };
    let mut out = Vec::new();
    for (i, k) in keys.iter().enumerate() {
        let end = keys.get(i + 1).map_or(script.duration(), |k| k.time);
        let (a, b) = (frame(k.time + settle), frame(end));
        if a >= b {
            continue;
        }
        let half = frame(k.time + settle + 0.5).clamp(a + 1, b);
        let speed_after = mean(&speed[a..b]);
        let reference = if k.speed > 0.0 {
            k.speed
        } else {
            keys[..i].iter().rev().map(|k| k.speed).find(|s| *s > 0.0).unwrap_or(100.0)
        };
        let speed_error = (speed_after - k.speed).abs() / reference;
        let err: Vec<f64> = yaw[a..b].iter().map(|y| angle_difference(*y, k.heading).abs().to_degrees()).collect();
        let heading_mean = mean(&err);
        let heading_max = err.iter().copied().fold(0.0, f64::max);
        out.push(SegmentScore {
            time: k.time,
            target_speed: k.speed,
            target_heading_deg: k.heading.to_degrees(),
            speed_at_settle: mean(&speed[a..half]),
            speed_after,
            speed_error,
            heading_at_settle_deg: err[0],
            heading_mean_deg: heading_mean,
            heading_max_deg: heading_max,
            pass: speed_error <= 0.1 && err[0] <= 10.0 && heading_mean <= 10.0,
        });
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_script_reads_steps_and_keeps_missing_values() {
        let s = ControlScript::from_json(
            r#"{"units": "m", "duration": 10, "keys": [{"time": 0, "speed": 1.2, "heading": 0},
                {"time": 4, "heading": 90}, {"time": 6, "speed": 0}]}"#,
        )
        .unwrap();
        assert_eq!(s.keys().len(), 3);
        let k = s.at(5.0);
        assert_eq!((k.speed, k.heading), (120.0, 90f64.to_radians()));
        let k = s.at(7.0);
        assert_eq!((k.speed, k.heading), (0.0, 90f64.to_radians()));
        assert_eq!(s.at(0.0).heading, 0.0);
        assert_eq!(s.at(3.99).speed, 120.0);
    }

    #[test]
    fn bad_scripts_are_refused_with_the_fix() {
        for (text, want) in [
            (r#"{"duration": 5, "keys": [{"time": 0, "speed": -1, "heading": 0}]}"#, "from 0 to"),
            (r#"{"duration": 5, "keys": [{"time": 0, "speed": NaN, "heading": 0}]}"#, "does not parse"),
            (r#"{"duration": 5, "keys": [{"time": 0, "speed": "fast", "heading": 0}]}"#, "must be a number"),
            (r#"{"duration": 5, "keys": [{"time": 0, "speed": 50, "heading": 0}]}"#, "from 0 to 10 m/s"),
            (r#"{"duration": 5, "keys": [{"time": 1, "speed": 1, "heading": 0}]}"#, "at time 0"),
            (
                r#"{"duration": 5, "keys": [{"time": 0, "speed": 1, "heading": 0}, {"time": 0, "speed": 2}]}"#,
                "increasing",
            ),
            (r#"{"duration": 5, "keys": []}"#, "at least one key"),
            (r#"{"keys": [{"time": 0, "speed": 1, "heading": 0}]}"#, "duration"),
            (r#"{"duration": 5, "keys": [{"time": 0, "speed": 1}]}"#, "heading"),
            (
                r#"{"duration": 5, "units": "ft", "keys": [{"time": 0, "speed": 1, "heading": 0}]}"#,
                "unknown control units",
            ),
        ] {
            let e = ControlScript::from_json(text).unwrap_err().to_string();
            assert!(e.contains(want), "{text}: {e}");
        }
        let e = ControlScript::new(vec![ControlKey { time: 0.0, speed: 1.0, heading: f64::NAN }], 2.0).unwrap_err();
        assert!(e.to_string().contains("finite angle"), "{e}");
    }

    #[test]
    fn durations_key_times_headings_and_key_counts_past_their_bounds_are_refused_with_the_range() {
        let key = |t: f64| format!(r#"{{"time": {t}, "speed": 1, "heading": 0}}"#);
        let script = |duration: &str, keys: &str| format!(r#"{{"duration": {duration}, "keys": [{keys}]}}"#);
        // At the bounds: loads.
        let s = ControlScript::from_json(&script("3600", &format!("{}, {}", key(0.0), key(3599.5)))).unwrap();
        assert_eq!(s.duration(), MAX_DURATION);
        let s = ControlScript::from_json(r#"{"duration": 5, "keys": [{"time": 0, "speed": 1, "heading": 1e6}]}"#);
        assert!(s.is_ok(), "{s:?}");
        for (text, want) in [
            (script("3600.5", &key(0.0)), "`duration` is 3600.5 s"),
            (script("1e300", &key(0.0)), "valid range (0, 3600]"),
            (script("1e9", &format!("{}, {}", key(0.0), key(5000.0))), "control key 1 is at time 5000.0 s"),
            (script("5", &format!("{}, {}", key(0.0), key(1e300))), "[0, 3600) seconds"),
            (
                r#"{"duration": 5, "keys": [{"time": 0, "speed": 1, "heading": 1.5e6}]}"#.to_string(),
                "heading 1500000.0 degrees",
            ),
        ] {
            let e = ControlScript::from_json(&text).unwrap_err().to_string();
            assert!(e.contains(want), "{text}: {e}");
        }
        let many: Vec<String> = (0..=MAX_KEYS).map(|i| key(i as f64 * 0.01)).collect();
        let e = ControlScript::from_json(&script("3599", &many.join(","))).unwrap_err().to_string();
        assert!(e.contains("100001 keys, more than the 100000"), "{e}");
        let keys: Vec<ControlKey> =
            (0..=MAX_KEYS).map(|i| ControlKey { time: i as f64 * 0.01, speed: 1.0, heading: 0.0 }).collect();
        assert!(ControlScript::new(keys, 3599.0).unwrap_err().to_string().contains("more than the 100000"));
    }

    #[test]
    fn scores_measure_after_the_settling_time() {
        let s = ControlScript::new(
            vec![
                ControlKey { time: 0.0, speed: 100.0, heading: 0.0 },
                ControlKey { time: 2.0, speed: 0.0, heading: std::f64::consts::PI },
            ],
            4.0,
        )
        .unwrap();
        // 30 fps: on target from 1 s after each key, off before.
        let (mut speed, mut yaw) = (Vec::new(), Vec::new());
        for f in 0..120 {
            let t = f as f64 / 30.0;
            let settled = t.rem_euclid(2.0) >= 1.0;
            let k = s.at(t);
            speed.push(if settled { k.speed } else { 50.0 });
            // Facing -179 degrees is 1 degree from 180.
            yaw.push(if settled { k.heading - 2.0 * std::f64::consts::PI } else { 1.0 });
        }
        yaw[100] = (-179f64).to_radians();
        let r = score(&s, 30.0, &speed, &yaw, 1.0);
        assert_eq!(r.len(), 2);
        assert!(r.iter().all(|r| r.pass), "{r:?}");
        assert!(r[1].heading_max_deg > 0.9 && r[1].heading_max_deg < 1.1, "{r:?}");
        // Measured from 0.5 s after the key instead: the unsettled frames count and fail it.
        let r = score(&s, 30.0, &speed, &yaw, 0.5);
        assert!(r.iter().all(|r| !r.pass), "{r:?}");
        // 15 frames at 50 cm/s and 30 at 0: 16.7 cm/s over the speed before the stop.
        assert!((r[1].speed_error - 50.0 / 3.0 / 100.0).abs() < 0.01, "stop error over the speed before: {r:?}");
    }

    #[test]
    fn the_benchmark_script_has_walk_run_stop_and_180_degree_turns() {
        let s = ControlScript::benchmark();
        // The example in docs/controls is the same script.
        let doc = ControlScript::from_json(include_str!("../../../../docs/controls/benchmark.json")).unwrap();
        assert_eq!(doc.duration(), s.duration());
        for (a, b) in doc.keys().iter().zip(s.keys()) {
            assert!((a.time - b.time).abs() < 1e-12 && (a.speed - b.speed).abs() < 1e-9, "{a:?} vs {b:?}");
            assert!((a.heading - b.heading).abs() < 1e-12, "{a:?} vs {b:?}");
        }
        assert_eq!(doc.keys().len(), s.keys().len());
        let k = s.keys();
        assert!(k.iter().any(|k| k.speed == 0.0) && k.iter().any(|k| k.speed > 300.0));
        let turns: Vec<f64> =
            k.windows(2).map(|w| angle_difference(w[1].heading, w[0].heading).abs().to_degrees()).collect();
        assert!(turns.iter().filter(|t| (**t - 180.0).abs() < 1e-9).count() >= 2, "{turns:?}");
    }
}

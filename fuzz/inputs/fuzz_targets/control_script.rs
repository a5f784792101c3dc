//! Control scripts (`zoo control --script`, `zoo bench control`): `ControlScript::from_json`
//! must parse or fail with an error, never panic; a parsed script must be within the bounds
//! (at most `MAX_KEYS` keys from time 0, strictly increasing, a duration after the last key of
//! at most `MAX_DURATION` s, speeds in [0, `MAX_SPEED`], headings within
//! `MAX_HEADING_DEG`), and replaying it frame by frame and scoring a motion against it must
//! work.
#![no_main]

use libfuzzer_sys::fuzz_target;
use zoo_rnngmm::controls::{ControlScript, MAX_DURATION, MAX_HEADING_DEG, MAX_KEYS, MAX_SPEED, score};

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    let Ok(s) = ControlScript::from_json(text) else { return };
    let keys = s.keys();
    assert!(!keys.is_empty() && keys.len() <= MAX_KEYS, "{} keys", keys.len());
    assert_eq!(keys[0].time, 0.0);
    assert!(keys.windows(2).all(|w| w[0].time < w[1].time));
    let d = s.duration();
    assert!(d.is_finite() && d > keys[keys.len() - 1].time && d <= MAX_DURATION, "duration {d}");
    for k in keys {
        assert!((0.0..=MAX_SPEED).contains(&k.speed), "speed {}", k.speed);
        assert!(k.heading.is_finite() && k.heading.to_degrees().abs() <= MAX_HEADING_DEG, "heading {}", k.heading);
    }
    // A motion of a few frames per second over the whole script (at most 14,400 frames).
    let fps = 4.0;
    let frames = (d * fps).ceil() as usize;
    let (speed, yaw): (Vec<f64>, Vec<f64>) = (0..frames)
        .map(|f| {
            let k = s.at(f as f64 / fps);
            (k.speed, k.heading + 0.1)
        })
        .unzip();
    for r in score(&s, fps, &speed, &yaw, 1.0) {
        assert!(r.speed_error.is_finite() && r.heading_mean_deg.is_finite(), "{r:?}");
    }
});

//! Value parsers for the numeric options: each refuses a value outside its range when the
//! arguments are parsed, so clap's error names the option (`invalid value '0' for
//! '--frames <FRAMES>': ...`) and the message states the valid range. No command then sees a
//! zero, negative, NaN or infinite value where it cannot use one.

/// The largest transition or keyframe interval `zoo transition` / `zoo decompress` accept, in
/// frames (about 55 minutes at 30 fps; inference memory does not grow with it, the output does).
pub const MAX_FRAMES: usize = 100_000;

fn whole(s: &str) -> Result<usize, String> {
    s.trim().parse::<usize>().map_err(|_| format!("`{s}` is not a whole number"))
}

fn real(s: &str) -> Result<f64, String> {
    let v = s.trim().parse::<f64>().map_err(|_| format!("`{s}` is not a number"))?;
    if v.is_finite() { Ok(v) } else { Err(format!("{v} is not a finite number")) }
}

/// The most frames `zoo data synth` and `zoo train rtn` (without `--data`) generate in memory
/// (about 18.5 hours at 30 fps, a few GB).
pub const MAX_SYNTH_FRAMES: f64 = 2_000_000.0;

/// Checks the size of synthetic data: `minutes` at `fps` in clips of `clip_seconds`, naming
/// the options as the command spells them.
pub fn check_synth_size(minutes: (&str, f64), clip_seconds: f64, fps: f64) -> Result<(), String> {
    let (option, minutes) = minutes;
    if !(1.0..=1000.0).contains(&fps) {
        return Err(format!("--fps {fps} is outside the valid range 1..=1000"));
    }
    let frames = minutes * 60.0 * fps;
    if frames > MAX_SYNTH_FRAMES {
        return Err(format!(
            "{option} {minutes} at {fps} fps is {frames:.0} frames, more than the {MAX_SYNTH_FRAMES} this command generates \
             in memory (at most {:.0} minutes at this frame rate)",
            MAX_SYNTH_FRAMES / 60.0 / fps
        ));
    }
    if clip_seconds * fps < 2.0 {
        return Err(format!(
            "--clip-seconds {clip_seconds} at {fps} fps is less than 2 frames per clip (at least {} s)",
            2.0 / fps
        ));
    }
    Ok(())
}

/// A whole number >= 1.
pub fn at_least_one(s: &str) -> Result<usize, String> {
    match whole(s)? {
        0 => Err("must be a whole number >= 1".into()),
        n => Ok(n),
    }
}

/// A frame count in `1..=MAX_FRAMES`.
pub fn frame_count(s: &str) -> Result<usize, String> {
    match whole(s)? {
        n @ 1..=MAX_FRAMES => Ok(n),
        n => Err(format!("{n} frames is outside the valid range 1..={MAX_FRAMES}")),
    }
}

/// A finite number > 0.
pub fn positive(s: &str) -> Result<f64, String> {
    match real(s)? {
        v if v > 0.0 => Ok(v),
        v => Err(format!("{v} is not a positive number (must be finite and > 0)")),
    }
}

/// A finite number > 0, as f32 (and finite as f32).
pub fn positive_f32(s: &str) -> Result<f32, String> {
    let v = positive(s)?;
    let f = v as f32;
    if f.is_finite() && f > 0.0 { Ok(f) } else { Err(format!("{v} is outside the range of a 32-bit float")) }
}

/// A finite number >= 0.
pub fn non_negative(s: &str) -> Result<f64, String> {
    match real(s)? {
        v if v >= 0.0 => Ok(v),
        v => Err(format!("{v} is negative (must be finite and >= 0)")),
    }
}

/// A decay in `[0, 1)`.
pub fn decay(s: &str) -> Result<f64, String> {
    match real(s)? {
        v if (0.0..1.0).contains(&v) => Ok(v),
        v => Err(format!("{v} is not a decay in [0, 1) (0.999 averages over about 1000 steps; 0 turns it off)")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_parser_refuses_zero_negative_nan_and_infinity() {
        assert_eq!(at_least_one("3"), Ok(3));
        assert!(at_least_one("0").unwrap_err().contains(">= 1"));
        assert!(at_least_one("-2").unwrap_err().contains("not a whole number"));
        assert_eq!(frame_count("20000"), Ok(20000));
        assert!(frame_count("0").unwrap_err().contains("1..=100000"));
        assert!(frame_count("100001").unwrap_err().contains("1..=100000"));
        assert_eq!(positive("2.5"), Ok(2.5));
        for bad in ["0", "-1", "NaN", "inf", "x"] {
            assert!(positive(bad).is_err(), "{bad}");
            assert!(decay(bad).is_err() || bad == "0", "{bad}");
        }
        assert!(positive_f32("1e300").unwrap_err().contains("32-bit"));
        assert_eq!(non_negative("0"), Ok(0.0));
        assert!(non_negative("-0.5").unwrap_err().contains("negative"));
        assert_eq!(decay("0"), Ok(0.0));
        assert!(decay("1").unwrap_err().contains("[0, 1)"));
        assert!(check_synth_size(("--minutes", 10.0), 10.0, 30.0).is_ok());
        let e = check_synth_size(("--minutes", 2000.0), 10.0, 30.0).unwrap_err();
        assert!(e.contains("--minutes 2000 at 30 fps is 3600000 frames") && e.contains("at most 1111 minutes"), "{e}");
        assert!(check_synth_size(("--minutes", 1.0), 1e-9, 30.0).unwrap_err().contains("less than 2 frames"));
        assert!(check_synth_size(("--minutes", 1.0), 10.0, 1e9).unwrap_err().contains("1..=1000"));
    }
}

//! Value parsers for the numeric options: each refuses a value outside its range when the
//! arguments are parsed, so clap's error names the option (`invalid value '0' for
//! '--frames <FRAMES>': ...`) and the message states the valid range. No command then sees a
//! zero, negative, NaN, infinite or absurdly large value.
//!
//! The ranges are wide enough that a real use never meets them and narrow enough that no value
//! overflows, allocates more than the machine holds or runs for years (`docs/option-ranges.md`
//! lists them). Use the parser named after what the option counts (`epochs`, `batch_size`,
//! `learning_rate`, `fps`, `seed`, ...) in `#[arg(value_parser = zoo_nn::args::NAME)]`, with
//! `allow_hyphen_values = true` so that a negative value reaches the parser (and gets its
//! message) instead of being taken for an option.

use std::ops::RangeInclusive;

/// The largest transition or keyframe interval `zoo transition` / `zoo decompress` accept, in
/// frames (about 55 minutes at 30 fps; inference memory does not grow with it, the output does).
pub const MAX_FRAMES: usize = 100_000;

/// The largest frame index (`zoo render --from/--to`): about 92 hours at 30 fps.
pub const MAX_FRAME_INDEX: usize = 10_000_000;

/// The most epochs a training run may ask for.
pub const MAX_EPOCHS: usize = 100_000;

/// The largest training mini-batch.
pub const MAX_BATCH_SIZE: usize = 65_536;

/// The largest learning rate: far beyond any useful one (Adam-family rates are below 1, and
/// diverge long before this), but a diverging run is allowed on purpose (the divergence check
/// stops it); the bound keeps the rate finite in f32 arithmetic.
pub const MAX_LEARNING_RATE: f64 = 1e9;

/// The longest `--time-limit`, minutes (30 days).
pub const MAX_TIME_LIMIT_MINUTES: f64 = 43_200.0;

/// The longest synthetic clip, seconds (one hour).
pub const MAX_CLIP_SECONDS: f64 = 3_600.0;

/// The frame rates accepted, frames per second.
pub const FPS_RANGE: RangeInclusive<f64> = 1.0..=1_000.0;

/// The largest relative tolerance of `zoo bench --reference` (100 = 10,000 %).
pub const MAX_TOLERANCE: f64 = 100.0;

/// The largest distance between clips drawn side by side, clip units (10 km in cm).
pub const MAX_SPACING: f64 = 1e6;

/// The most test windows `zoo bench --save-bvh` writes.
pub const MAX_SAVE_COUNT: usize = 10_000;

/// The largest batch of `zoo bench runtime` (characters stepped together).
pub const MAX_RUNTIME_BATCH: usize = 16_384;

/// The most rounds of `zoo bench runtime`.
pub const MAX_ROUNDS: usize = 10_000;
/// Largest weight of a loss term.
pub const MAX_LOSS_WEIGHT: f64 = 1e6;

/// The most character-steps per backend and round of `zoo bench runtime`.
pub const MAX_CHARACTER_STEPS: usize = 10_000_000;

/// The most sequences `zoo data luxo` generates (the paper uses 300).
pub const MAX_SEQUENCES: usize = 100_000;

/// The most simulated-annealing iterations per run of `zoo data luxo` (the paper's K_max).
pub const MAX_ANNEAL_ITERATIONS: usize = 1_000_000;

/// The most annealing runs per sequence of `zoo data luxo`.
pub const MAX_ATTEMPTS: usize = 1_000;

/// The most frames `zoo data synth` and `zoo train rtn` (without `--data`) generate in memory
/// (about 18.5 hours at 30 fps, a few GB).
pub const MAX_SYNTH_FRAMES: f64 = 2_000_000.0;

/// The frames of run-up `zoo_data::synth` generates around each clip (twice its `ROLL`).
const SYNTH_RUN_UP_FRAMES: f64 = 90.0;

/// The shortest span (clip plus run-up) the motion generator is asked to plan, seconds.
const MIN_SYNTH_SPAN_SECONDS: f64 = 1.0;

/// A whole number in `range`; `unit` names what it counts in the message (`frames`, `epochs`).
pub fn whole_in(s: &str, range: RangeInclusive<usize>, unit: &str) -> Result<usize, String> {
    let (lo, hi) = (*range.start(), *range.end());
    let n = s.trim().parse::<usize>().map_err(|_| format!("`{s}` is not a whole number (valid range {lo}..={hi})"))?;
    if range.contains(&n) {
        return Ok(n);
    }
    let unit = if unit.is_empty() { String::new() } else { format!(" {unit}") };
    let bound = if n < lo { format!("must be >= {lo}") } else { format!("must be <= {hi}") };
    Err(format!("{n}{unit} is outside the valid range {lo}..={hi} ({bound})"))
}

/// An interval of real numbers; an open end excludes its bound.
#[derive(Clone, Copy, Debug)]
pub struct Interval {
    /// Lower bound.
    pub lo: f64,
    /// Whether `lo` itself is excluded.
    pub lo_open: bool,
    /// Upper bound.
    pub hi: f64,
    /// Whether `hi` itself is excluded.
    pub hi_open: bool,
}

impl Interval {
    /// `(lo, hi]`.
    pub const fn above(lo: f64, hi: f64) -> Interval {
        Interval { lo, lo_open: true, hi, hi_open: false }
    }

    /// `[lo, hi]`.
    pub const fn closed(lo: f64, hi: f64) -> Interval {
        Interval { lo, lo_open: false, hi, hi_open: false }
    }

    /// Whether `v` lies in the interval.
    pub fn contains(&self, v: f64) -> bool {
        let above = if self.lo_open { v > self.lo } else { v >= self.lo };
        let below = if self.hi_open { v < self.hi } else { v <= self.hi };
        above && below
    }
}

impl std::fmt::Display for Interval {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let open = if self.lo_open { '(' } else { '[' };
        let close = if self.hi_open { ')' } else { ']' };
        if self.hi.is_infinite() {
            write!(f, "{open}{}, inf)", self.lo)
        } else {
            write!(f, "{open}{}, {}{close}", self.lo, self.hi)
        }
    }
}

/// A finite number in `range`; `unit` names its unit in the message (`minutes`, `fps`).
pub fn real_in(s: &str, range: Interval, unit: &str) -> Result<f64, String> {
    let v = s.trim().parse::<f64>().map_err(|_| format!("`{s}` is not a number (valid range {range})"))?;
    if !v.is_finite() {
        return Err(format!("{v} is not a finite number (valid range {range})"));
    }
    if range.contains(v) {
        return Ok(v);
    }
    let positive_only = range.lo > 0.0 || (range.lo == 0.0 && range.lo_open);
    if v <= 0.0 && positive_only {
        return Err(format!("{v} is not a positive number (valid range {range})"));
    }
    if v < 0.0 && range.lo >= 0.0 {
        return Err(format!("{v} is negative (valid range {range})"));
    }
    let unit = if unit.is_empty() { String::new() } else { format!(" {unit}") };
    Err(format!("{v}{unit} is outside the valid range {range}"))
}

/// Checks the size of synthetic data: `minutes` at `fps` in clips of `clip_seconds` (every clip
/// is generated whole, the last one too), naming the options as the command spells them.
pub fn check_synth_size(minutes: (&str, f64), clip_seconds: f64, fps: f64) -> Result<(), String> {
    let (option, minutes) = minutes;
    if !FPS_RANGE.contains(&fps) {
        return Err(format!("--fps {fps} is outside the valid range {}..={}", FPS_RANGE.start(), FPS_RANGE.end()));
    }
    if !(clip_seconds > 0.0 && clip_seconds <= MAX_CLIP_SECONDS) {
        return Err(format!("--clip-seconds {clip_seconds} is outside the valid range (0, {MAX_CLIP_SECONDS}]"));
    }
    if clip_seconds * fps < 2.0 {
        return Err(format!(
            "--clip-seconds {clip_seconds} at {fps} fps is less than 2 frames per clip (at least {} s)",
            2.0 / fps
        ));
    }
    // The generator plans each clip with 45 frames of run-up on either side; a planned span
    // shorter than about half a second may hold no foot plant, which its feet planner cannot
    // handle (`synth/feet.rs`): ask for a second, twice the longest failing span measured.
    let min_seconds = MIN_SYNTH_SPAN_SECONDS - SYNTH_RUN_UP_FRAMES / fps;
    if clip_seconds < min_seconds {
        return Err(format!(
            "--clip-seconds {clip_seconds} at {fps} fps is too short for the motion generator (at least {:.3} s at this \
             frame rate)",
            (min_seconds * 1000.0).ceil() / 1000.0
        ));
    }
    // `SynthConfig::clip_count` clips of `clip_seconds * fps` frames each.
    let clips = (minutes * 60.0 / clip_seconds).ceil().max(1.0);
    let frames = clips * (clip_seconds * fps).round();
    if minutes.is_nan() || minutes <= 0.0 || !frames.is_finite() || frames > MAX_SYNTH_FRAMES {
        let most = MAX_SYNTH_FRAMES / 60.0 / fps;
        return Err(format!(
            "{option} {minutes} at {fps} fps is {frames:.0} frames (in clips of {clip_seconds} s), more than the \
             {MAX_SYNTH_FRAMES} this command generates in memory (valid range (0, {most:.0}] minutes at this frame rate)"
        ));
    }
    Ok(())
}

/// Refuses synthetic training data whose frames ([`check_synth_size`]'s count) would need more
/// than the memory bound (`zoo_data::limits::memory_bound`) once the training holds them
/// (`bytes_per_frame` each, the trainer's measure): checked before the motion is generated,
/// naming the size, the bound, the longest length within it and how to raise it.
pub fn check_synth_memory(
    minutes: (&str, f64),
    clip_seconds: f64,
    fps: f64,
    bytes_per_frame: f64,
) -> Result<(), String> {
    let (option, minutes) = minutes;
    let clips = (minutes * 60.0 / clip_seconds).ceil().max(1.0);
    let frames = clips * (clip_seconds * fps).round();
    let need = frames * bytes_per_frame;
    let bound = zoo_data::limits::memory_bound() as f64;
    if need > bound {
        let most = (bound / bytes_per_frame / fps / 60.0).floor();
        return Err(format!(
            "{option} {minutes} at {fps} fps is {frames:.0} frames, which this command holds in about {:.1} GB, \
             past the memory bound of {:.2} GB: give at most {most:.0} minutes, or raise the bound with the \
             environment variable ZOO_MEMORY_GB=N",
            need / 1e9,
            bound / 1e9
        ));
    }
    Ok(())
}

/// A frame count or interval in `1..=MAX_FRAMES` (`--frames`, `--interval`, `--lengths`,
/// `--every`).
pub fn frame_count(s: &str) -> Result<usize, String> {
    whole_in(s, 1..=MAX_FRAMES, "frames")
}

/// A frame index in `0..=MAX_FRAME_INDEX` (a first frame).
pub fn frame_index(s: &str) -> Result<usize, String> {
    whole_in(s, 0..=MAX_FRAME_INDEX, "")
}

/// One past a last frame, in `1..=MAX_FRAME_INDEX`.
pub fn frame_end(s: &str) -> Result<usize, String> {
    whole_in(s, 1..=MAX_FRAME_INDEX, "")
}

/// A clip and frame, `CLIP.bvh:FRAME`, with FRAME in `0..=MAX_FRAME_INDEX` (whether the clip
/// has that frame is checked once it is read); the text is kept as given.
pub fn clip_frame(s: &str) -> Result<String, String> {
    let Some((path, frame)) = s.rsplit_once(':') else {
        return Err(format!("expected CLIP.bvh:FRAME, e.g. walk.bvh:120 (FRAME in 0..={MAX_FRAME_INDEX})"));
    };
    if path.is_empty() {
        return Err(format!("the clip before `:{frame}` is empty: expected CLIP.bvh:FRAME"));
    }
    whole_in(frame, 0..=MAX_FRAME_INDEX, "").map_err(|e| format!("frame {e}"))?;
    Ok(s.to_string())
}

/// A random seed: any 64-bit unsigned whole number.
pub fn seed(s: &str) -> Result<u64, String> {
    s.trim().parse::<u64>().map_err(|_| format!("`{s}` is not a seed: a whole number in 0..={}", u64::MAX))
}

/// Training epochs, `1..=MAX_EPOCHS`.
pub fn epochs(s: &str) -> Result<usize, String> {
    whole_in(s, 1..=MAX_EPOCHS, "epochs")
}

/// A training mini-batch size, `1..=MAX_BATCH_SIZE`.
pub fn batch_size(s: &str) -> Result<usize, String> {
    whole_in(s, 1..=MAX_BATCH_SIZE, "")
}

/// The most units a layer of a model may have (`--hidden`).
pub const MAX_LAYER_WIDTH: usize = 65_536;

/// The most test cases a benchmark may be asked to make.
pub const MAX_CASES: usize = 100_000;

/// A layer width (units of a recurrent or dense layer), `1..=MAX_LAYER_WIDTH`.
pub fn layer_width(s: &str) -> Result<usize, String> {
    whole_in(s, 1..=MAX_LAYER_WIDTH, "units")
}

/// A frame count that may be zero (`0` turns the feature off), `0..=MAX_FRAMES`.
pub fn frames_or_zero(s: &str) -> Result<usize, String> {
    whole_in(s, 0..=MAX_FRAMES, "frames")
}

/// A number of benchmark cases, `0..=MAX_CASES`.
pub fn case_count(s: &str) -> Result<usize, String> {
    whole_in(s, 0..=MAX_CASES, "cases")
}

/// The longest synthesis, seconds (100 hours).
pub const MAX_SYNTHESIS_SECONDS: f64 = 360_000.0;

/// The largest sampling temperature.
pub const MAX_TEMPERATURE: f64 = 100.0;

/// A frame count of a streamed output (synthesis of any length), `1..=MAX_FRAME_INDEX`.
pub fn long_frame_count(s: &str) -> Result<usize, String> {
    whole_in(s, 1..=MAX_FRAME_INDEX, "frames")
}

/// A duration of generated motion in seconds, `(0, MAX_SYNTHESIS_SECONDS]`.
pub fn duration_seconds(s: &str) -> Result<f64, String> {
    real_in(s, Interval::above(0.0, MAX_SYNTHESIS_SECONDS), "seconds")
}

/// A range of transition lengths `SHORTEST-LONGEST` (`zoo train rtn --lengths 5-45`), each in
/// `1..=MAX_TRANSITION_FRAMES`, the shortest first.
pub fn length_range(s: &str) -> Result<[usize; 2], String> {
    let (a, b) = s.split_once('-').ok_or_else(|| format!("`{s}` is not a range SHORTEST-LONGEST, e.g. 5-45"))?;
    let lo = whole_in(a, 1..=MAX_TRANSITION_FRAMES, "frames")?;
    let hi = whole_in(b, 1..=MAX_TRANSITION_FRAMES, "frames")?;
    if lo > hi {
        return Err(format!("{s}: the shortest length comes first, e.g. {hi}-{lo}"));
    }
    Ok([lo, hi])
}

/// A range of speed factors `SLOWEST-FASTEST` (`zoo train rtn --speed-range 0.7-2.0`), each in
/// `(0, 4]`, the slowest first.
pub fn speed_range(s: &str) -> Result<(f32, f32), String> {
    let (a, b) = s.split_once('-').ok_or_else(|| format!("`{s}` is not a range SLOWEST-FASTEST, e.g. 0.7-2.0"))?;
    let lo = real_in(a, Interval { lo: 0.0, lo_open: true, hi: 4.0, hi_open: false }, "")?;
    let hi = real_in(b, Interval { lo: 0.0, lo_open: true, hi: 4.0, hi_open: false }, "")?;
    if lo > hi {
        return Err(format!("{s}: the slowest factor comes first, e.g. {b}-{a}"));
    }
    Ok((lo as f32, hi as f32))
}

/// The longest transition a training range may ask for (frames).
pub const MAX_TRANSITION_FRAMES: usize = 1000;

/// The longest sequence `zoo bench synthesis` measures, seconds (1 hour): unlike `zoo generate`
/// it holds each sequence whole while measuring it (about 9 KB per frame of a 22-joint skeleton,
/// so about 1 GB per worker thread at this limit).
pub const MAX_BENCH_SYNTHESIS_SECONDS: f64 = 3600.0;

/// The length of one benchmarked sequence in seconds, `(0, MAX_BENCH_SYNTHESIS_SECONDS]`.
pub fn bench_sequence_seconds(s: &str) -> Result<f64, String> {
    real_in(s, Interval::above(0.0, MAX_BENCH_SYNTHESIS_SECONDS), "seconds").map_err(|e| {
        format!("{e}: the benchmark holds each sequence whole while it measures it; measure more sequences instead")
    })
}

/// A sampling temperature, `[0, MAX_TEMPERATURE]` (0: the most likely component's mean).
pub fn temperature(s: &str) -> Result<f64, String> {
    real_in(s, Interval::closed(0.0, MAX_TEMPERATURE), "")
}

/// A fraction strictly between 0 and 1 (`--test-fraction`).
pub fn unit_fraction(s: &str) -> Result<f64, String> {
    real_in(s, Interval { lo: 0.0, lo_open: true, hi: 1.0, hi_open: true }, "")
}

/// A margin as a fraction of a range, `[0, 10]`.
pub fn margin_fraction(s: &str) -> Result<f64, String> {
    real_in(s, Interval::closed(0.0, 10.0), "")
}

/// A learning rate in `(0, MAX_LEARNING_RATE]`.
pub fn learning_rate(s: &str) -> Result<f64, String> {
    real_in(s, Interval::above(0.0, MAX_LEARNING_RATE), "")
}

/// A time limit in minutes, `(0, MAX_TIME_LIMIT_MINUTES]`.
pub fn time_limit_minutes(s: &str) -> Result<f64, String> {
    real_in(s, Interval::above(0.0, MAX_TIME_LIMIT_MINUTES), "minutes")
}

/// Minutes of synthetic motion, > 0; the upper bound depends on the frame rate and is checked
/// by [`check_synth_size`] (at most `MAX_SYNTH_FRAMES` frames).
pub fn synth_minutes(s: &str) -> Result<f64, String> {
    real_in(s, Interval::above(0.0, f64::INFINITY), "minutes")
}

/// Seconds per synthetic clip, `(0, MAX_CLIP_SECONDS]`.
pub fn clip_seconds(s: &str) -> Result<f64, String> {
    real_in(s, Interval::above(0.0, MAX_CLIP_SECONDS), "seconds")
}

/// A frame rate in `FPS_RANGE`.
pub fn fps(s: &str) -> Result<f64, String> {
    real_in(s, Interval::closed(*FPS_RANGE.start(), *FPS_RANGE.end()), "fps")
}

/// A frame rate in `FPS_RANGE`, as f32.
pub fn fps_f32(s: &str) -> Result<f32, String> {
    fps(s).map(|v| v as f32)
}

/// A relative tolerance in `[0, MAX_TOLERANCE]`.
pub fn relative_tolerance(s: &str) -> Result<f64, String> {
    real_in(s, Interval::closed(0.0, MAX_TOLERANCE), "")
}

/// A distance between drawn clips in `(0, MAX_SPACING]` clip units.
pub fn spacing(s: &str) -> Result<f64, String> {
    real_in(s, Interval::above(0.0, MAX_SPACING), "")
}

/// How many test windows to save, `1..=MAX_SAVE_COUNT`.
pub fn save_count(s: &str) -> Result<usize, String> {
    whole_in(s, 1..=MAX_SAVE_COUNT, "windows")
}

/// Characters stepped together by `zoo bench runtime`, `1..=MAX_RUNTIME_BATCH`.
pub fn runtime_batch(s: &str) -> Result<usize, String> {
    whole_in(s, 1..=MAX_RUNTIME_BATCH, "characters")
}

/// Measuring rounds, `1..=MAX_ROUNDS`.
pub fn rounds(s: &str) -> Result<usize, String> {
    whole_in(s, 1..=MAX_ROUNDS, "rounds")
}

/// Character-steps per backend and round, `1..=MAX_CHARACTER_STEPS`.
pub fn character_steps(s: &str) -> Result<usize, String> {
    whole_in(s, 1..=MAX_CHARACTER_STEPS, "steps")
}

/// Generated sequences, `1..=MAX_SEQUENCES`.
pub fn sequences(s: &str) -> Result<usize, String> {
    whole_in(s, 1..=MAX_SEQUENCES, "sequences")
}

/// Simulated-annealing iterations, `1..=MAX_ANNEAL_ITERATIONS`.
pub fn anneal_iterations(s: &str) -> Result<usize, String> {
    whole_in(s, 1..=MAX_ANNEAL_ITERATIONS, "iterations")
}

/// Tries before giving up, `1..=MAX_ATTEMPTS`.
pub fn attempts(s: &str) -> Result<usize, String> {
    whole_in(s, 1..=MAX_ATTEMPTS, "attempts")
}

/// A finite number > 0, without an upper bound: prefer a parser with a range.
#[allow(dead_code)] // for subcommands without a ranged parser yet
pub fn positive(s: &str) -> Result<f64, String> {
    real_in(s, Interval::above(0.0, f64::INFINITY), "")
}

/// A weight of a loss term in `[0, MAX_LOSS_WEIGHT]` (0 turns the term off).
pub fn loss_weight(s: &str) -> Result<f64, String> {
    real_in(s, Interval::closed(0.0, MAX_LOSS_WEIGHT), "")
}

/// A percentile below the median, `[0, 50)`.
pub fn range_percentile(s: &str) -> Result<f64, String> {
    real_in(s, Interval { lo: 0.0, lo_open: false, hi: 50.0, hi_open: true }, "")
}

/// A filter width in frames, `[0, 50]` (`0` turns the smoothing off).
pub fn smoothing_frames(s: &str) -> Result<f64, String> {
    real_in(s, Interval::closed(0.0, 50.0), "frames")
}

/// A count that may be zero (`0` turns the feature off), `0..=MAX_CASES`.
pub fn count_or_zero(s: &str) -> Result<usize, String> {
    whole_in(s, 0..=MAX_CASES, "")
}

/// A decay in `[0, 1)`.
pub fn decay(s: &str) -> Result<f64, String> {
    let range = Interval { lo: 0.0, lo_open: false, hi: 1.0, hi_open: true };
    match real_in(s, range, "") {
        Ok(v) => Ok(v),
        Err(e) if e.contains("not a finite") || e.contains("not a number") => Err(e),
        Err(_) => {
            Err(format!("{} is not a decay in [0, 1) (0.999 averages over about 1000 steps; 0 turns it off)", s.trim()))
        }
    }
}

/// A training thread count in `1..=MAX_THREADS`.
pub fn training_threads(s: &str) -> Result<usize, String> {
    let max = crate::parallel::MAX_THREADS;
    match s.trim().parse::<usize>() {
        Ok(n @ 1..) if n <= max => Ok(n),
        _ => Err(format!("`{s}` is not a thread count: valid range 1..={max}")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn whole_numbers_outside_their_range_say_the_range() {
        let at_least_one = |s| whole_in(s, 1..=usize::MAX, "");
        assert_eq!(at_least_one("3"), Ok(3));
        assert!(at_least_one("0").unwrap_err().contains(">= 1"));
        assert!(at_least_one("-2").unwrap_err().contains("not a whole number"));
        assert_eq!(frame_count("20000"), Ok(20000));
        assert_eq!(frame_count("0").unwrap_err(), "0 frames is outside the valid range 1..=100000 (must be >= 1)");
        assert_eq!(
            frame_count("100001").unwrap_err(),
            "100001 frames is outside the valid range 1..=100000 (must be <= 100000)"
        );
        assert_eq!(frame_count("1.5").unwrap_err(), "`1.5` is not a whole number (valid range 1..=100000)");
        assert_eq!(frame_index("0"), Ok(0));
        assert!(frame_end("0").unwrap_err().contains("1..=10000000"));
        assert!(epochs("100001").unwrap_err().contains("1..=100000"));
        assert!(batch_size("65537").unwrap_err().contains("1..=65536"));
        // Larger than any usize: not a whole number of the range, not a wrap-around.
        assert!(epochs("99999999999999999999999").unwrap_err().contains("not a whole number (valid range 1..=100000)"));
        assert_eq!(seed("18446744073709551615"), Ok(u64::MAX));
        assert!(seed("-1").unwrap_err().contains("0..=18446744073709551615"));
        assert!(seed("18446744073709551616").unwrap_err().contains("not a seed"));
        assert_eq!(clip_frame("a:b.bvh:12"), Ok("a:b.bvh:12".to_string()));
        assert!(clip_frame("walk.bvh").unwrap_err().contains("expected CLIP.bvh:FRAME"));
        assert!(clip_frame(":3").unwrap_err().contains("is empty"));
        assert_eq!(
            clip_frame("b.bvh:18446744073709551615").unwrap_err(),
            "frame 18446744073709551615 is outside the valid range 0..=10000000 (must be <= 10000000)"
        );
    }

    #[test]
    fn length_ranges_are_two_lengths_shortest_first() {
        assert_eq!(length_range("5-45"), Ok([5, 45]));
        assert_eq!(length_range("30-30"), Ok([30, 30]));
        assert!(length_range("45-5").unwrap_err().contains("shortest length comes first"));
        assert!(length_range("0-45").unwrap_err().contains("1..=1000"));
        assert!(length_range("5-1001").unwrap_err().contains("1..=1000"));
        assert!(length_range("30").unwrap_err().contains("SHORTEST-LONGEST"));
    }

    #[test]
    fn speed_ranges_are_two_positive_factors_slowest_first() {
        assert_eq!(speed_range("0.7-2.0"), Ok((0.7, 2.0)));
        assert_eq!(speed_range("1-1"), Ok((1.0, 1.0)));
        assert!(speed_range("2-0.7").unwrap_err().contains("slowest factor comes first"));
        assert!(speed_range("0-2").unwrap_err().contains("not a positive number"));
        assert!(speed_range("0.7-5").unwrap_err().contains("(0, 4]"), "{:?}", speed_range("0.7-5"));
        assert!(speed_range("1.5").unwrap_err().contains("SLOWEST-FASTEST"));
    }

    #[test]
    fn a_benchmarked_sequence_is_at_most_an_hour_and_says_why() {
        assert_eq!(bench_sequence_seconds("3600"), Ok(3600.0));
        let e = bench_sequence_seconds("3601").unwrap_err();
        assert!(
            e.contains("3601 seconds is outside the valid range (0, 3600]") && e.contains("holds each sequence whole"),
            "{e}"
        );
        assert_eq!(duration_seconds("3601"), Ok(3601.0));
    }

    #[test]
    fn real_numbers_refuse_zero_negative_nan_infinity_and_too_large() {
        assert_eq!(positive("2.5"), Ok(2.5));
        for bad in ["0", "-1", "NaN", "inf", "x"] {
            assert!(positive(bad).is_err(), "{bad}");
            assert!(learning_rate(bad).unwrap_err().contains("(valid range (0, 1000000000])"), "{bad}");
            assert!(decay(bad).is_err() || bad == "0", "{bad}");
        }
        assert_eq!(learning_rate("1e8"), Ok(1e8));
        assert_eq!(learning_rate("2e9").unwrap_err(), "2000000000 is outside the valid range (0, 1000000000]");
        assert_eq!(learning_rate("-0.1").unwrap_err(), "-0.1 is not a positive number (valid range (0, 1000000000])");
        assert_eq!(fps("0.5").unwrap_err(), "0.5 fps is outside the valid range [1, 1000]");
        assert_eq!(fps("0").unwrap_err(), "0 is not a positive number (valid range [1, 1000])");
        assert_eq!(fps_f32("1000"), Ok(1000.0));
        let non_negative = |s| real_in(s, Interval::closed(0.0, f64::INFINITY), "");
        assert_eq!(non_negative("0"), Ok(0.0));
        assert!(non_negative("-0.5").unwrap_err().contains("negative"));
        assert!(
            real_in("1e300", Interval::above(0.0, f32::MAX as f64), "")
                .unwrap_err()
                .contains("outside the valid range")
        );
        assert_eq!(relative_tolerance("-1").unwrap_err(), "-1 is negative (valid range [0, 100])");
        assert_eq!(time_limit_minutes("1e9").unwrap_err(), "1000000000 minutes is outside the valid range (0, 43200]");
        assert_eq!(decay("0"), Ok(0.0));
        assert!(decay("1").unwrap_err().contains("[0, 1)"));
        assert!(decay("NaN").unwrap_err().contains("not a finite"));
    }

    #[test]
    fn synthetic_data_larger_than_memory_is_refused_with_the_range() {
        assert!(check_synth_size(("--minutes", 10.0), 10.0, 30.0).is_ok());
        let e = check_synth_size(("--minutes", 2000.0), 10.0, 30.0).unwrap_err();
        assert!(e.contains("--minutes 2000 at 30 fps is 3600000 frames (in clips of 10 s)"), "{e}");
        assert!(e.contains("valid range (0, 1111] minutes"), "{e}");
        assert!(check_synth_size(("--minutes", 1.0), 1e-9, 30.0).unwrap_err().contains("less than 2 frames"));
        assert!(check_synth_size(("--minutes", 1.0), 10.0, 1e9).unwrap_err().contains("1..=1000"));
        // One clip is generated whole: a short total in one very long clip is refused too.
        let e = check_synth_size(("--minutes", 0.01), 3600.0, 1000.0).unwrap_err();
        assert!(e.contains("3600000 frames"), "{e}");
        assert!(check_synth_size(("--minutes", 1.0), 1e9, 30.0).unwrap_err().contains("(0, 3600]"));
        // At 1000 fps the 90 frames of run-up are 0.09 s: a clip needs 0.91 s more.
        let e = check_synth_size(("--minutes", 1.0), 0.5, 1000.0).unwrap_err();
        assert!(e.contains("too short for the motion generator (at least 0.910 s at this frame rate)"), "{e}");
        assert!(check_synth_size(("--minutes", 1.0), 0.91, 1000.0).is_ok());
        assert!(check_synth_size(("--minutes", 1.0), 0.1, 30.0).is_ok());
        // Within the frame cap, past the memory bound (2 GB by default): refused before the work.
        assert!(check_synth_size(("--synth-minutes", 1111.0), 10.0, 30.0).is_ok());
        let e = check_synth_memory(("--synth-minutes", 1111.0), 10.0, 30.0, 6_500.0).unwrap_err();
        assert!(e.contains("1999800 frames") && e.contains("13.0 GB") && e.contains("ZOO_MEMORY_GB"), "{e}");
        assert!(e.contains("at most 170 minutes"), "{e}");
        assert!(check_synth_memory(("--synth-minutes", 30.0), 10.0, 30.0, 6_500.0).is_ok());
    }
}

/// The most L-BFGS iterations of `zoo denoise`.
const MAX_DENOISE_ITERATIONS: usize = 100_000;

/// L-BFGS iterations of the denoiser, `1..=MAX_DENOISE_ITERATIONS`.
pub fn denoise_iterations(s: &str) -> Result<usize, String> {
    whole_in(s, 1..=MAX_DENOISE_ITERATIONS, "iterations")
}

/// A noise level in degrees, `(0, 90]`.
pub fn noise_degrees(s: &str) -> Result<f64, String> {
    real_in(s, Interval::above(0.0, 90.0), "degrees")
}

/// A noise level in clip units, `(0, 1000]`.
pub fn noise_units(s: &str) -> Result<f64, String> {
    real_in(s, Interval::above(0.0, 1000.0), "clip units")
}

/// A fraction in `[0, 1)` (0 turns it off).
pub fn fraction_or_zero(s: &str) -> Result<f64, String> {
    real_in(s, Interval { lo: 0.0, lo_open: false, hi: 1.0, hi_open: true }, "")
}

/// A path-following or control weight's standard deviation in clip units, `(0, 10000]`.
pub fn sigma_units(s: &str) -> Result<f64, String> {
    real_in(s, Interval::above(0.0, 10_000.0), "clip units")
}

/// A walking or running speed in clip units per second, `(0, 10000]` (100 m/s in cm).
pub fn speed_units(s: &str) -> Result<f64, String> {
    real_in(s, Interval::above(0.0, 10_000.0), "clip units per second")
}

/// Frames per batch of online control, `1..=120`.
pub fn control_batch(s: &str) -> Result<usize, String> {
    whole_in(s, 1..=120, "frames")
}

/// Gradient steps per batch of online control, `0..=100`.
pub fn gradient_steps(s: &str) -> Result<usize, String> {
    whole_in(s, 0..=100, "steps")
}

/// A standard deviation in radians, `(0, 10]`.
pub fn sigma_radians(s: &str) -> Result<f64, String> {
    real_in(s, Interval::above(0.0, 10.0), "rad")
}

/// A proposal offset in normalised units, `[-10, 10]`.
pub fn proposal_offset(s: &str) -> Result<f64, String> {
    real_in(s, Interval::closed(-10.0, 10.0), "standard deviations")
}

/// Centimetres per SVG user unit, `(0, 10000]`.
pub fn svg_scale(s: &str) -> Result<f64, String> {
    real_in(s, Interval::above(0.0, 10_000.0), "cm per unit")
}

/// Particles of a swarm, `2..=1024`.
pub fn particles(s: &str) -> Result<usize, String> {
    whole_in(s, 2..=1024, "particles")
}

/// Iterations of an optimiser per window, `0..=10000`.
pub fn optimiser_iterations(s: &str) -> Result<u64, String> {
    whole_in(s, 0..=10_000, "iterations").map(|n| n as u64)
}

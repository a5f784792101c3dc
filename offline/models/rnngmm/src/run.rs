//! What the commands of a trained RNN-GMM share (`zoo generate`, `follow`, `control`,
//! `denoise` and their benchmarks): loading a run folder, the start clip, the written motion
//! with its contact labels, the plots, and the controllers with their progress.

use crate::checkpoint::{LoadedGenerator, START_FILE};
use crate::controls::{ControlScript, angle_difference};
use crate::error::RnnGmmResult;
use crate::path::GroundPath;
use crate::refiner::{REFINER_FILE, RefinerNets};
use crate::{Controlled, FollowOptions, Followed, OnlineOptions};
use std::path::{Path, PathBuf};
use zoo_data::{Context, Progress, bail};
use zoo_motion::Clip;

/// The model of a run folder: the generator, and the refiner unless `no_refiner`. A folder of
/// another kind, a refiner without its generator and a generator stage without a refiner (when
/// one is wanted) are refused with what to do.
pub fn load_run(dir: &Path, no_refiner: bool) -> RnnGmmResult<(LoadedGenerator, Option<RefinerNets>)> {
    let kind = zoo_nn::checkpoint::model_kind(dir).map_err(|e| zoo_data::Message::new(e))?;
    if kind != "rnn-gmm" {
        bail!(
            "{} holds a `{kind}` model, not an `rnn-gmm` one: `zoo generate`, `zoo denoise`, `zoo follow` and `zoo \
             control` run a run folder of `zoo train rnn-gmm`",
            dir.display()
        );
    }
    let weights = dir.join(crate::checkpoint::WEIGHTS_FILE);
    if !weights.is_file() {
        let refiner = if dir.join(REFINER_FILE).is_file() {
            " (it has a refiner, but a refiner only runs on the generator it was trained with)"
        } else {
            ""
        };
        bail!(
            "{} has no generator weights ({} is missing){refiner}: copy the whole run folder",
            dir.display(),
            weights.display()
        );
    }
    let device = candle_core::Device::Cpu;
    if no_refiner {
        let g = crate::checkpoint::load(dir, &device)
            .with_context(|| format!("loading the generator in {}", dir.display()))?;
        return Ok((g, None));
    }
    if !dir.join(REFINER_FILE).is_file() {
        bail!(
            "{} holds no refiner ({REFINER_FILE}): train it with `zoo train rnn-gmm --stage refiner --out {}`, or \
             generate with --no-refiner",
            dir.display(),
            dir.display()
        );
    }
    let m = crate::refiner::load(dir, &device)
        .with_context(|| format!("loading the generator and refiner in {}", dir.display()))?;
    Ok((m.generator, Some(m.nets)))
}

/// The start clip and frame: `from` (a clip and a frame), or the run folder's start clip at
/// frame 29; with its label `CLIP:FRAME`.
pub fn start_clip(
    dir: &Path,
    from: Option<(&Path, usize)>,
    g: &LoadedGenerator,
) -> RnnGmmResult<(Clip, usize, String)> {
    let (path, frame) = match from {
        Some((p, f)) => (p.to_path_buf(), f),
        None => {
            let p = dir.join(START_FILE);
            if !p.is_file() {
                bail!("{} has no {START_FILE}: give a start clip with --from CLIP.bvh:FRAME", dir.display());
            }
            (p, usize::MAX)
        }
    };
    let mut clip = zoo_data::clip_io::read_model_clip(&path).map_err(zoo_data::Message::new)?;
    if let Some(zoo_data::clip_io::Conformed::Folded(how)) = zoo_data::clip_io::conform_to(&mut clip, &g.spec.skeleton)
    {
        eprintln!("{}: {how}", path.display());
    }
    if let Some(d) = g.spec.skeleton.topology_difference(&clip.skeleton) {
        bail!(
            "{} is on another skeleton than the model's ({d}); start from a clip of the training skeleton",
            path.display()
        );
    }
    // A clip at another frame rate than the model's is resampled to it, its start frame with it.
    let mut frame = frame;
    if let Some((note, ratio)) =
        zoo_data::clip_io::to_frame_rate(&mut clip, g.spec.fps, &path).map_err(zoo_data::Message)?
    {
        eprintln!("{note}");
        if frame != usize::MAX {
            frame = (frame as f64 * ratio).round() as usize;
        }
    }
    let frame = if frame == usize::MAX { clip.frames().saturating_sub(1).min(29) } else { frame };
    if frame >= clip.frames() {
        bail!("{}: frame {frame} is past the clip's last frame {}", path.display(), clip.frames().saturating_sub(1));
    }
    Ok((clip, frame, format!("{}:{frame}", path.display())))
}

/// `NAME.contacts.json` beside the clip `out`.
pub fn contacts_path(out: &Path) -> PathBuf {
    let stem = out.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    out.with_file_name(format!("{stem}.contacts.json"))
}

/// Writes the contact labels as JSON to `path` (atomically).
pub fn write_contacts(path: &Path, fps: f64, contacts: &[[bool; 2]]) -> RnnGmmResult<()> {
    if !fps.is_finite() {
        bail!("the contact labels' frame rate is {fps}: nothing was written to {}", path.display());
    }
    let rows: Vec<[u8; 2]> = contacts.iter().map(|c| [u8::from(c[0]), u8::from(c[1])]).collect();
    let json = serde_json::json!({ "fps": fps, "frames": contacts.len(), "feet": ["left", "right"], "contacts": rows });
    let text = serde_json::to_string(&json).context("contact labels")?;
    zoo_format::atomic::write(path, text).with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}

/// Writes a generated motion to `out` on the start clip's skeleton `skeleton` (its names and
/// offsets), and its contact labels beside it; returns the labels' path.
pub fn write_motion(
    out: &Path,
    motion: &crate::DecodedMotion,
    skeleton: &zoo_motion::Skeleton,
    fps: f64,
) -> RnnGmmResult<PathBuf> {
    let mut clip = motion.clip.clone();
    clip.skeleton = skeleton.clone();
    zoo_data::clip_io::write(&clip, out).map_err(zoo_data::Message::new)?;
    let json = contacts_path(out);
    write_contacts(&json, fps, &motion.contacts)?;
    Ok(json)
}

/// Follows `path` from `frame` of `clip`, its progress over the path's length (cm).
pub fn follow_with_progress(
    g: &LoadedGenerator,
    clip: &Clip,
    frame: usize,
    path: &GroundPath,
    opts: &FollowOptions,
    label: &str,
    p: &dyn Progress,
) -> RnnGmmResult<Followed> {
    p.start(path.length().ceil() as u64, label);
    let mut done = 0;
    let mut tick = |s: f64| {
        let at = s.clamp(0.0, path.length()) as u64;
        p.advance(at.saturating_sub(done));
        done = done.max(at);
    };
    let f = crate::follow(g, clip, frame, path, opts, &mut tick)?;
    p.finish();
    Ok(f)
}

/// Runs the candle controller over `script`, its progress in frames.
pub fn control_with_progress(
    g: &LoadedGenerator,
    clip: &Clip,
    frame: usize,
    script: &ControlScript,
    opts: &OnlineOptions,
    label: &str,
    p: &dyn Progress,
) -> RnnGmmResult<Controlled> {
    p.start((script.duration() * g.spec.fps).round() as u64, label);
    let mut done = 0;
    let mut tick = |f: usize| {
        p.advance((f as u64).saturating_sub(done));
        done = done.max(f as u64);
    };
    let c = crate::online::control(g, clip, frame, script, opts, &mut tick)?;
    p.finish();
    Ok(c)
}

/// The generated root trajectory (x, z) of a followed motion.
pub fn root_track(f: &Followed) -> Vec<[f64; 2]> {
    let c = &f.motion.clip;
    let (_, gp) = c.global();
    (0..c.frames()).map(|i| [gp[i * c.joints()].x, gp[i * c.joints()].z]).collect()
}

/// Writes the top view of `path` (grey) and `track` (red) to `png`.
pub fn plot_path(png: &Path, path: &GroundPath, track: &[[f64; 2]]) -> RnnGmmResult<()> {
    let grid = if path.length() > 3000.0 { 500.0 } else { 100.0 };
    zoo_nn::plot::top_view(png, &[(path.points(), (150, 150, 150), 5.0), (track, (200, 30, 30), 1.5)], grid, 600)
        .with_context(|| format!("writing {}", png.display()))?;
    Ok(())
}

/// Plots speed (top, 0 to the largest) and heading (bottom, degrees, unwrapped near the
/// controls) of a motion against the script's controls.
pub fn plot_controls(png: &Path, script: &ControlScript, fps: f64, speed: &[f64], yaw: &[f64]) -> RnnGmmResult<()> {
    let n = speed.len();
    let at = |f: usize| script.at(f as f64 / fps);
    let target_speed: Vec<f64> = (0..n).map(|f| at(f).speed).collect();
    let target_heading: Vec<f64> = (0..n).map(|f| at(f).heading.to_degrees()).collect();
    // Each frame's facing shown within 180 degrees of its control, so that a wrap is not a jump.
    let heading: Vec<f64> =
        (0..n).map(|f| target_heading[f] + angle_difference(yaw[f], at(f).heading).to_degrees()).collect();
    let top = speed.iter().chain(&target_speed).copied().fold(1.0, f64::max) * 1.1;
    let (lo, hi) = heading
        .iter()
        .chain(&target_heading)
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| (a.min(*v), b.max(*v)));
    let grey = (150, 150, 150);
    let red = (200, 30, 30);
    zoo_nn::plot::line_panels(
        png,
        &[
            (vec![(&target_speed, grey), (speed, red)], 0.0, top, 50.0),
            (vec![(&target_heading, grey), (&heading, red)], lo - 10.0, hi + 10.0, 45.0),
        ],
    )
    .with_context(|| format!("writing {}", png.display()))?;
    Ok(())
}

/// Frames generated per chunk by [`generate_files`] (memory holds one chunk).
pub const CHUNK: usize = 300;

/// Writes a clip stream as BVH: the hierarchy and the frame count first, then chunk after chunk.
struct BvhStream<W: std::io::Write> {
    w: W,
    header: Option<String>,
}

impl<W: std::io::Write> BvhStream<W> {
    /// Appends `clip`'s frames (`total`: the frame count of the whole file, written with the
    /// first chunk).
    fn write(&mut self, clip: &Clip, total: usize) -> RnnGmmResult<()> {
        zoo_motion::finite::check_clip("the generated motion", clip).map_err(zoo_data::Message::new)?;
        let text = zoo_data::bvh::to_string(clip);
        let (hierarchy, motion) = text.split_once("MOTION\n").context("BVH text without MOTION")?;
        // "Frames: N\nFrame Time: T\n" then one line per frame.
        let mut lines = motion.splitn(3, '\n');
        let (_, time, rows) = (lines.next(), lines.next().unwrap_or_default(), lines.next().unwrap_or_default());
        let io = |e: std::io::Error| zoo_data::Message::new(e);
        match &self.header {
            None => {
                write!(self.w, "{hierarchy}MOTION\nFrames: {total}\n{time}\n").map_err(io)?;
                self.header = Some(hierarchy.to_string());
            }
            Some(h) if h != hierarchy => bail!("the hierarchy changed between chunks (a joint gained channels)"),
            Some(_) => {}
        }
        self.w.write_all(rows.as_bytes()).map_err(io)?;
        Ok(())
    }
}

use std::io::Write as _;

/// Frames of a generated motion, chunk by chunk: the engine runtime's synthesis (`zoo
/// generate`, `zoo_tasks::generate`) or the candle model's [`crate::SynthesisStream`].
pub trait MotionChunks {
    /// The next `frames` frames (at least 1), placed where the previous chunk ended.
    fn next_motion(&mut self, frames: usize) -> RnnGmmResult<crate::features::DecodedMotion>;
}

impl MotionChunks for crate::SynthesisStream<'_> {
    fn next_motion(&mut self, frames: usize) -> RnnGmmResult<crate::features::DecodedMotion> {
        Ok(self.next_chunk(frames)?.motion)
    }
}

/// Generates one sequence continuing `frame` of `clip` with the candle model into the BVH file
/// `bvh` and its contact labels `json` ([`write_generated`]).
pub fn generate_files(
    g: &LoadedGenerator,
    refiner: Option<&RefinerNets>,
    (clip, frame): (&Clip, usize),
    opts: &crate::SynthesisOptions,
    (bvh, json): (&Path, &Path),
    positions: bool,
    p: &dyn Progress,
) -> RnnGmmResult<Vec<Vec<[f32; 3]>>> {
    let mut stream = crate::SynthesisStream::new(g, refiner, clip, frame, opts)?;
    write_generated(&mut stream, g.spec.fps, opts.frames, (bvh, json), positions, p)
}

/// Writes `frames` frames of `stream` (at `fps`) into the BVH file `bvh` and its contact labels
/// `json`, chunk by chunk (each file written atomically); returns the global joint positions of
/// every frame when `positions` asks for them.
pub fn write_generated(
    stream: &mut dyn MotionChunks,
    fps: f64,
    frames: usize,
    (bvh, json): (&Path, &Path),
    positions: bool,
    p: &dyn Progress,
) -> RnnGmmResult<Vec<Vec<[f32; 3]>>> {
    let mut frames_xyz = Vec::new();
    let mut failure = None;
    let written = zoo_format::atomic::write_with(bvh, |bvh_file| {
        zoo_format::atomic::write_with(json, |json_file| {
            // The root always carries position channels, so every chunk has the same hierarchy.
            let mut out = BvhStream { w: std::io::BufWriter::new(&mut *bvh_file), header: None };
            let mut cj = std::io::BufWriter::new(json_file);
            if !fps.is_finite() {
                failure = Some(zoo_data::Message(format!("the model's frame rate is {}: re-export it", fps)).into());
                return Err(std::io::Error::other("generation failed"));
            }
            write!(
                cj,
                "{{\n\"fps\": {},\n\"frames\": {},\n\"feet\": [\"left\", \"right\"],\n\"contacts\": [",
                fps, frames
            )?;
            let mut done = 0;
            while done < frames {
                let n = CHUNK.min(frames - done);
                let chunk = stream.next_motion(n).and_then(|mut chunk| {
                    chunk.clip.skeleton.channels[0].position = true;
                    out.write(&chunk.clip, frames)?;
                    Ok(chunk)
                });
                let chunk = match chunk {
                    Ok(c) => c,
                    Err(e) => {
                        failure = Some(e);
                        return Err(std::io::Error::other("generation failed"));
                    }
                };
                if positions {
                    frames_xyz.extend(zoo_data::positions::clip_positions(&chunk.clip));
                }
                for (i, c) in chunk.contacts.iter().enumerate() {
                    let sep = if done + i == 0 { "\n" } else { ",\n" };
                    write!(cj, "{sep}[{}, {}]", c[0] as u8, c[1] as u8)?;
                }
                done += n;
                p.advance(n as u64);
            }
            writeln!(cj, "\n]\n}}")?;
            cj.flush()?;
            out.w.flush()
        })
    });
    match (failure, written) {
        (Some(e), _) => Err(e),
        (None, Err(e)) => Err(zoo_data::Message(format!("writing {}: {e}", bvh.display())).into()),
        (None, Ok(())) => Ok(frames_xyz),
    }
}

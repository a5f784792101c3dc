//! `zoo complete`: an animator's keys completed into a whole motion by a trained keyframe
//! network, run by the engine runtime ([`zoo_tasks::complete`]; keys file format in docs/arnn.md,
//! "Keys file").

use anyhow::bail;
use clap::Args;
use std::path::PathBuf;

/// Arguments of `zoo complete`.
#[derive(Args)]
pub struct CompleteArgs {
    /// Run folder of `zoo train arnn`, or its exported file (`zoo export --onnx`).
    #[arg(long)]
    pub model: PathBuf,
    /// Keys file: frames and poses (format in docs/arnn.md, example in docs/arnn-keys-example.json).
    #[arg(long, required_unless_present = "poses", conflicts_with = "poses")]
    pub keys: Option<PathBuf>,
    /// Humanoid models: a clip (BVH, glTF, FBX) holding only the key poses, one per frame, in
    /// order (exported from Blender, say); their frames come from `--key-frames` or `--every`,
    /// or, for a glTF file given without them, from its own key times (at `--fps`, default 30).
    #[arg(long, value_name = "CLIP")]
    pub poses: Option<PathBuf>,
    /// With `--poses`: the output frame of each key pose (comma-separated, increasing).
    #[arg(long, value_delimiter = ',', requires = "poses", conflicts_with = "every")]
    pub key_frames: Option<Vec<usize>>,
    /// With `--poses`: a key every K frames.
    #[arg(long, requires = "poses", value_parser = clap::value_parser!(u64).range(1..=100_000))]
    pub every: Option<u64>,
    /// With `--poses`: the clip is a whole motion; the keys are its poses at `--key-frames` (or
    /// every `--every` frames), the frames between completed anew.
    #[arg(long, requires = "poses")]
    pub sample: bool,
    /// Output BVH of the lamp (Blender opens it).
    #[arg(long)]
    pub out: PathBuf,
    /// Also write every completed pose (and the key misses) to this JSON file.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Also plot each degree of freedom over the frames (blue) with the keys (circles) into this
    /// PNG, like the paper's Figure 8.
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Write the network's output as is, without lifting a base that sinks below the ground
    /// onto it (docs/arnn.md, "The ground").
    #[arg(long)]
    pub no_ground: bool,
    /// Humanoid keys: write the network's motion as is, without the foot lock between the keys
    /// (planted feet held, legs refitted; key frames unchanged; docs/keys-only.md).
    #[arg(long)]
    pub no_foot_lock: bool,
    /// In-betweening models: write the network's completion without the fallback towards
    /// Blender's curves where its correction is larger than on motion like its training data's
    /// (calibrated by `zoo train arnn --design inbetween`; docs/keys-only.md).
    #[arg(long)]
    pub no_fallback: bool,
    /// Frames per second of the output [default: the keys file's `fps`, else 50].
    #[arg(long, allow_hyphen_values = true, value_parser = crate::args::fps)]
    pub fps: Option<f64>,
    /// Also write the global joint positions of every completed frame (forward kinematics of
    /// the written BVH's skeleton, its units) to this JSON file (docs/runtime-protocol.md,
    /// "Positions files").
    #[arg(long, value_name = "FILE.json")]
    pub positions: Option<PathBuf>,
}

/// Runs `zoo complete`.
pub fn run(a: CompleteArgs) -> anyhow::Result<()> {
    crate::cmd::check_output_file("--out", &a.out)?;
    for (option, path) in [("--json", &a.json), ("--plot", &a.plot), ("--positions", &a.positions)] {
        if let Some(p) = path {
            crate::cmd::check_output_file(option, p)?;
        }
    }
    let key_times = a.key_frames.is_none() && a.every.is_none();
    if let Some(p) = a.poses.as_ref().filter(|_| key_times)
        && zoo_data::clip_io::ClipFormat::of(p) != Some(zoo_data::clip_io::ClipFormat::Gltf)
    {
        bail!(
            "--poses {}: give the key frames (--key-frames 0,15,40, one per pose, or --every K); only a glTF file \
             stores its keys' times",
            p.display()
        );
    }
    if key_times && a.sample {
        bail!("--sample takes the key poses out of a whole motion at --key-frames or --every: give one of them");
    }
    let poses = a.poses.map(|clip| zoo_arnn::completion::PoseKeys {
        clip,
        frames: a.key_frames,
        every: a.every.map(|k| k as usize),
        sample: a.sample,
    });
    let o = zoo_arnn::completion::CompleteOptions {
        model: a.model,
        keys: a.keys.unwrap_or_default(),
        poses,
        out: a.out,
        json: a.json,
        plot: a.plot,
        no_ground: a.no_ground,
        no_foot_lock: a.no_foot_lock,
        no_fallback: a.no_fallback,
        fps: a.fps,
        positions: a.positions,
    };
    println!("{}", zoo_tasks::complete::complete(&o)?);
    Ok(())
}

//! `zoo transition`: generate a transition between two clips with a trained RTN, run by the
//! engine runtime ([`zoo_tasks::transition`]).

use clap::Args;
use std::path::PathBuf;

/// Arguments of `zoo transition`.
#[derive(Args)]
pub struct TransitionArgs {
    /// Run folder of `zoo train rtn`, or its exported file (`zoo export --onnx`).
    #[arg(long)]
    pub model: PathBuf,
    /// Source clip and frame, `A.bvh:FRAME`: the transition starts after the 10 frames before FRAME.
    #[arg(long, allow_hyphen_values = true, value_parser = crate::args::clip_frame)]
    pub from: String,
    /// Target clip and frame, `B.bvh:FRAME`: the transition ends in this pose.
    #[arg(long, allow_hyphen_values = true, value_parser = crate::args::clip_frame)]
    pub to: String,
    /// Transition length in frames.
    #[arg(long, default_value_t = 30, allow_hyphen_values = true, value_parser = crate::args::frame_count)]
    pub frames: usize,
    /// Output clip (`.bvh`, `.bvh.gz`, `.glb` or `.gltf`): A up to FRAME, the transition, then B
    /// from its FRAME on, aligned in space (with --heightmap: B where it is, both clips in the
    /// heightmap's world frame).
    #[arg(long)]
    pub out: PathBuf,
    /// The FBX take (animation stack) or glTF animation of the --from and --to clips (default:
    /// the first).
    #[arg(long)]
    pub take: Option<String>,
    /// Clips of another rig of the same kind: a joint-name map (JSON, docs/formats.md) from the
    /// clips' joints to the model's (same names under a `mixamorig:`-style prefix need `{}`);
    /// the clips are mapped onto the run folder's skeleton.json, and the output is written back
    /// on the --from clip's rig.
    #[arg(long)]
    pub rig_map: Option<PathBuf>,
    /// Foot-lock the transition (`zoo_protocol::footlock`: planted feet slide less, dragged feet
    /// are lifted); legs are found by joints named `foot`.
    #[arg(long)]
    pub foot_lock: bool,
    /// Keep the network's transition even when its own miss at the target is large. By
    /// default a run whose config.json holds calibrated fallback thresholds (written by `zoo
    /// train rtn`) blends towards interpolation on a large miss (docs/ood.md); an in-betweening
    /// run (`zoo train arnn --design inbetween`) blends towards the curves through the context
    /// and the target where its correction is larger than on motion like its training data's.
    #[arg(long)]
    pub no_fallback: bool,
    /// The ground for a terrain-aware model (`zoo train rtn --terrain`): a heightmap header
    /// (`NAME.terrain.json`, as `zoo data synth --terrain` writes beside each clip) in the
    /// --from clip's units and world frame, which the --to clip shares (it is not moved).
    /// Required by a terrain-aware model, refused by one without terrain input.
    #[arg(long)]
    pub heightmap: Option<PathBuf>,
    /// Also write the network's global joint positions to this JSON file (docs/runtime-protocol.md,
    /// "Positions files"): the inputs it was given (context, target, next), its raw frames before
    /// the target blend and the blended frames (with the fallback) that the output's rotations
    /// are fitted to, in the model's units, on the model's skeleton.
    #[arg(long, value_name = "FILE.json")]
    pub positions: Option<PathBuf>,
    /// Leave the --to clip where it is: both clips share one world frame (by default the --to
    /// clip is moved and turned to follow on from the --from clip's last position and heading).
    #[arg(long)]
    pub in_place: bool,
}

/// Runs `zoo transition`.
pub fn run(a: TransitionArgs) -> anyhow::Result<()> {
    crate::cmd::check_output_file("--out", &a.out)?;
    if let Some(p) = &a.positions {
        crate::cmd::check_output_file("--positions", p)?;
    }
    let o = zoo_tasks::transition::TransitionOptions {
        from: crate::args::clip_and_frame(&a.from)?,
        to: crate::args::clip_and_frame(&a.to)?,
        from_label: a.from,
        to_label: a.to,
        model: a.model,
        frames: a.frames,
        out: a.out,
        take: a.take,
        rig_map: a.rig_map,
        foot_lock: a.foot_lock,
        no_fallback: a.no_fallback,
        heightmap: a.heightmap,
        positions: a.positions,
        in_place: a.in_place,
    };
    println!("{}", zoo_tasks::transition::run(&o, &crate::cmd::Stderr)?);
    Ok(())
}

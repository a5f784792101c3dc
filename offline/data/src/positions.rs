//! Positions files (`--positions FILE.json` of `zoo transition`, `complete`, `stitch` and
//! `generate`; docs/runtime-protocol.md, "Positions files"): a clip's global joint positions per
//! frame, beside what each command adds, for checking an engine's runtime against zoo.

use std::path::Path;
use zoo_motion::Clip;

/// `format` of a positions file.
pub const POSITIONS_FORMAT: &str = "zoo-positions";

/// Global joint positions of every frame of `clip` (forward kinematics), `[x, y, z]` per
/// joint: the `frames` of a positions file of the commands whose networks give rotations.
pub fn clip_positions(clip: &Clip) -> Vec<Vec<[f32; 3]>> {
    let (_, positions) = clip.global();
    positions
        .chunks_exact(clip.joints().max(1))
        .map(|frame| frame.iter().map(|p| [p.x as f32, p.y as f32, p.z as f32]).collect())
        .collect()
}

/// The positions file of a clip `command` wrote: its joints, frame rate and every frame's
/// global joint positions (`extra` fields added). A clip holding NaN or infinity is refused
/// here, since JSON would write those values as `null`.
pub fn clip_positions_json(
    command: &str,
    clip: &Clip,
    extra: serde_json::Value,
) -> Result<serde_json::Value, zoo_motion::finite::NonFinite> {
    zoo_motion::finite::check_clip(&format!("the clip of `zoo {command}`"), clip)?;
    let mut v = serde_json::json!({
        "format": POSITIONS_FORMAT,
        "version": 1,
        "command": command,
        "joints": clip.skeleton.names,
        "fps": clip.fps(),
        "frames": clip_positions(clip),
    });
    if let (Some(v), serde_json::Value::Object(extra)) = (v.as_object_mut(), extra) {
        v.extend(extra);
    }
    Ok(v)
}

/// Writes a positions file (compact JSON, atomically).
pub fn write(path: &Path, value: &serde_json::Value) -> std::io::Result<()> {
    zoo_format::atomic::write(path, serde_json::to_string(value)?)
}

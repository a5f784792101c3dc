//! `zoo complete` on the runtime's keyframes task (`zoo_runtime::KeyframeModel`): the keys read
//! (a keys file, a clip of key poses, or a whole clip sampled), the exported network run by the
//! runtime (either design: the ARNN's step graph or the in-betweening design's whole-shot
//! graph), then the keys hit, the feet locked between them and the outputs written by
//! [`zoo_arnn::completion::complete_command`].

use crate::{ModelSource, TaskResult};
use std::cell::RefCell;
use zoo_arnn::completion::{CompleteOptions, KeyNet};
use zoo_arnn::config::HumanoidSkeleton;
use zoo_arnn::{ArnnConfig, ArnnResult};
use zoo_data::{Message, bail};
use zoo_format::MotionTaskKind;
use zoo_runtime::{KeyframeRunner, MotionKeys};

/// An exported keyframe network in the runtime, as `zoo complete` runs it.
pub struct RuntimeKeyNet {
    pub(crate) runner: RefCell<KeyframeRunner>,
    dofs: usize,
    groups: usize,
    humanoid: Option<HumanoidSkeleton>,
    lamp: Option<ArnnConfig>,
}

impl RuntimeKeyNet {
    /// The keyframe network of `source`: a humanoid one (its file's skeleton and frame rate) or
    /// the lamp's (its training configuration, which the file carries, for the lamp's geometry).
    pub fn new(source: &ModelSource) -> TaskResult<RuntimeKeyNet> {
        let model = source.load()?.into_keyframes()?;
        let (dofs, groups) = (model.dofs(), model.groups());
        let m = &source.metadata;
        let (humanoid, lamp) = if groups > 0 && !m.skeleton.names.is_empty() {
            let s = &m.skeleton;
            let skeleton = HumanoidSkeleton {
                names: s.names.clone(),
                parents: s.parents.clone(),
                offsets: s.offsets.clone(),
                fps: f64::from(m.fps),
            };
            (Some(skeleton), None)
        } else {
            let config: ArnnConfig = serde_json::from_str(&m.config_json).map_err(|e| {
                Message(format!(
                    "{}: the lamp's training configuration in the file does not read ({e}): re-export it with `zoo \
                     export --onnx RUN_DIR`",
                    source.path.display()
                ))
            })?;
            (None, Some(config))
        };
        let mut runner = model.runner(1)?;
        runner.set_hit_keys(false);
        runner.set_foot_lock(false);
        Ok(RuntimeKeyNet { runner: RefCell::new(runner), dofs, groups, humanoid, lamp })
    }
}

impl KeyNet for RuntimeKeyNet {
    fn humanoid(&self) -> Option<&HumanoidSkeleton> {
        self.humanoid.as_ref()
    }

    fn lamp(&self) -> Option<&ArnnConfig> {
        self.lamp.as_ref()
    }

    fn complete(&self, frames: &[usize], poses: &[Vec<f64>], fixed: &[Vec<bool>]) -> ArnnResult<Vec<Vec<f64>>> {
        let d = self.dofs;
        let flat: Vec<f32> = poses.iter().flatten().map(|v| *v as f32).collect();
        let flags: Vec<f32> = fixed.iter().flatten().map(|f| if *f { 1.0 } else { 0.0 }).collect();
        if !fixed.is_empty() && flags.len() != frames.len() * self.groups {
            bail!("{} key group flags for {} keys of {} groups", flags.len(), frames.len(), self.groups);
        }
        let keys = MotionKeys { frames, poses: &flat, fixed: &flags };
        let mut out = vec![0.0f32; keys.len() * d];
        self.runner.borrow_mut().complete(keys, &mut out).map_err(|e| Message(e.to_string()))?;
        Ok(out.chunks_exact(d).map(|p| p.iter().map(|v| f64::from(*v)).collect()).collect())
    }

    fn kept(&self) -> Vec<f64> {
        self.runner.borrow().fallback_kept(0).to_vec()
    }
}

/// `zoo complete`: completes the keys of `o` with the keyframe model of `o.model` (a run folder
/// of `zoo train arnn`, exported in memory, or its exported file) through the runtime; returns
/// the summary the command prints.
pub fn complete(o: &CompleteOptions) -> TaskResult<String> {
    let source = ModelSource::open(&o.model, MotionTaskKind::Keyframes, "complete")?;
    let net = RuntimeKeyNet::new(&source)?;
    if o.no_fallback {
        net.runner.borrow_mut().set_fallback(None)?;
    }
    Ok(zoo_arnn::completion::complete_command(o, &net).map_err(|e| Message(e.to_string()))?)
}

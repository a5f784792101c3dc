//! A cache of planned pairs ([`PairPlan`]): the searches are the expensive part of making
//! pairs, so a run folder keeps their result as JSON and reuses it while the clips and the
//! configuration are the same.

use super::StitchError;
use super::generate::{PairConfig, PairSpec};
use super::segments::MotionSet;
use std::path::Path;

/// Version of the cache file format.
pub const PLAN_VERSION: u32 = 1;

/// What identifies a set of clips: counts, and a hash of names, frame counts, frame rate,
/// layout and the ground roots of every clip's first and last frames.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct SetFingerprint {
    /// Number of clips.
    pub clips: usize,
    /// Total frames.
    pub frames: usize,
    /// FNV-1a hash (hex).
    pub hash: String,
}

impl SetFingerprint {
    /// The fingerprint of `set`.
    pub fn of(set: &MotionSet) -> SetFingerprint {
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        let mut eat = |bytes: &[u8]| {
            for b in bytes {
                h ^= *b as u64;
                h = h.wrapping_mul(0x0100_0000_01b3);
            }
        };
        eat(&set.fps.to_le_bytes());
        eat(serde_json::to_string(&set.layout).unwrap_or_default().as_bytes());
        for (c, roots) in set.roots.iter().enumerate() {
            eat(set.names[c].as_bytes());
            eat(&(roots.len() as u64).to_le_bytes());
            for r in [roots.first(), roots.last()].into_iter().flatten() {
                for v in [r.pos.x, r.pos.z, r.yaw] {
                    eat(&((v * 1e3).round() as i64).to_le_bytes());
                }
            }
        }
        SetFingerprint { clips: set.clips.len(), frames: set.total_frames(), hash: format!("{h:016x}") }
    }
}

/// Planned pairs with what they were planned from.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PairPlan {
    /// [`PLAN_VERSION`].
    pub version: u32,
    /// The configuration.
    pub config: PairConfig,
    /// The ground-truth clips.
    pub ground_truth: SetFingerprint,
    /// The database clips.
    pub database: SetFingerprint,
    /// The plans.
    pub specs: Vec<PairSpec>,
}

impl PairPlan {
    /// A plan record.
    pub fn new(config: &PairConfig, gt: &MotionSet, db_set: &MotionSet, specs: Vec<PairSpec>) -> PairPlan {
        PairPlan {
            version: PLAN_VERSION,
            config: config.clone(),
            ground_truth: SetFingerprint::of(gt),
            database: SetFingerprint::of(db_set),
            specs,
        }
    }

    /// Whether this plan was made from these clips with this configuration.
    pub fn matches(&self, config: &PairConfig, gt: &MotionSet, db_set: &MotionSet) -> bool {
        self.version == PLAN_VERSION
            && &self.config == config
            && self.ground_truth == SetFingerprint::of(gt)
            && self.database == SetFingerprint::of(db_set)
    }

    /// Writes the plan as JSON (to a temporary file, then renamed).
    pub fn save(&self, path: &Path) -> Result<(), StitchError> {
        let io = |e: &dyn std::fmt::Display| StitchError::Io { path: path.to_path_buf(), message: e.to_string() };
        zoo_motion::finite::check_serialize("the stitch pair plan", self).map_err(|e| io(&e))?;
        let text = serde_json::to_string(self).map_err(|e| io(&e))?;
        zoo_format::atomic::write(path, text).map_err(|e| io(&e))
    }

    /// Reads a plan written by [`PairPlan::save`].
    pub fn load(path: &Path) -> Result<PairPlan, StitchError> {
        let io = |m: String| StitchError::Io { path: path.to_path_buf(), message: m };
        let text = std::fs::read_to_string(path).map_err(|e| io(e.to_string()))?;
        serde_json::from_str(&text).map_err(|e| io(format!("not a pair plan ({e}); delete it to plan again")))
    }

    /// The cached specs at `path` when they match; otherwise runs `plan`, saves its result
    /// there and returns it. Returns the specs and whether they came from the cache.
    pub fn load_or_plan(
        path: &Path,
        config: &PairConfig,
        gt: &MotionSet,
        db_set: &MotionSet,
        plan: impl FnOnce() -> Result<Vec<PairSpec>, StitchError>,
    ) -> Result<(Vec<PairSpec>, bool), StitchError> {
        if path.is_file()
            && let Ok(cached) = PairPlan::load(path)
            && cached.matches(config, gt, db_set)
        {
            return Ok((cached.specs, true));
        }
        let specs = plan()?;
        PairPlan::new(config, gt, db_set, specs.clone()).save(path)?;
        Ok((specs, false))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pairs::{StitchDatabases, StitchLayout, plan_pairs};
    use zoo_data::synth::{SynthConfig, generate};

    #[test]
    fn plans_are_reused_only_for_the_same_clips_and_configuration() {
        let cfg = SynthConfig { minutes: 0.5, seed: 2, clip_seconds: 6.0, ..SynthConfig::default() };
        let clips: Vec<_> = generate(&cfg).into_iter().map(|c| c.clip).collect();
        let layout = StitchLayout::bandai2(&clips[0].skeleton).unwrap();
        let set = MotionSet::new(clips.clone(), vec![], layout.clone()).unwrap();
        let pc = PairConfig { database_stride: 3, ..PairConfig::default() };
        let dbs = StitchDatabases::build(&set, &pc.segment_lengths(), pc.database_stride).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("pairs.json");
        let mut calls = 0;
        let mut run = |pc: &PairConfig, set: &MotionSet| {
            PairPlan::load_or_plan(&path, pc, set, set, || {
                calls += 1;
                plan_pairs(set, set, &dbs, pc)
            })
            .unwrap()
        };
        let (a, cached) = run(&pc, &set);
        assert!(!cached);
        let (b, cached) = run(&pc, &set);
        assert!(cached);
        assert_eq!(a, b);
        let other = PairConfig { seed: 5, ..pc.clone() };
        assert!(!run(&other, &set).1, "another seed plans again");
        let fewer = MotionSet::new(clips[1..].to_vec(), vec![], layout).unwrap();
        assert_ne!(SetFingerprint::of(&fewer), SetFingerprint::of(&set));
        std::fs::write(&path, "{").unwrap();
        assert!(PairPlan::load(&path).unwrap_err().to_string().contains("delete it"));
        assert!(!run(&pc, &set).1, "an unreadable cache is replaced");
        assert_eq!(calls, 3);
    }
}

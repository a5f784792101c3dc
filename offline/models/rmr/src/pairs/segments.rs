//! Motion segments and their per-length databases (RMR sec. 4).
//!
//! The feature of a segment of `L` frames starting at frame `s` is
//! `m = {w_1 j_1, w_L j_L, w_u u}` (RMR sec. 4): `j_1` and `j_L` are the global positions of
//! every joint at the first and last frame expressed in the ground root of the first frame,
//! `u` is the root trajectory (ground position x, z and forward direction x, z of every frame,
//! in the same frame), with `w_1 = 0.1`, `w_L = 1`, `w_u = 1`. The weights are applied when the
//! feature is stored, so the distance is the plain Euclidean one. Values are stored in the
//! order `[w_L j_L (3J), w_u u (4L), w_1 j_1 (3J)]`; a database stores its rows permuted by
//! decreasing variance so that the search can stop summing a candidate early (the distance does
//! not depend on the order).

use super::layout::{GroundRoot, StitchLayout};
use super::{StitchError, knn};
use glam::DVec3;
use rayon::prelude::*;
use zoo_motion::Clip;

/// Weight of the first pose in the segment feature (RMR sec. 4).
pub const W_FIRST: f64 = 0.1;
/// Weight of the last pose.
pub const W_LAST: f64 = 1.0;
/// Weight of the root trajectory.
pub const W_TRAJECTORY: f64 = 1.0;

/// Clips on one rig and frame rate, with what stitching reads of them precomputed: global
/// joint positions and the ground root of every frame.
#[derive(Clone, Debug)]
pub struct MotionSet {
    /// The clips (joint 0 is the hips).
    pub clips: Vec<Clip>,
    /// A name per clip (file name), for messages.
    pub names: Vec<String>,
    /// Global joint positions per clip, frame-major.
    pub global_positions: Vec<Vec<DVec3>>,
    /// Ground root of every frame, per clip.
    pub roots: Vec<Vec<GroundRoot>>,
    /// The joints read.
    pub layout: StitchLayout,
    /// Frames per second of every clip.
    pub fps: f64,
}

impl MotionSet {
    /// Checks that the clips share one rig and frame rate and that `layout` fits the rig, then
    /// runs forward kinematics (in parallel). `names` may be empty (clips are then named by index).
    pub fn new(clips: Vec<Clip>, names: Vec<String>, layout: StitchLayout) -> Result<MotionSet, StitchError> {
        let first = clips.first().ok_or(StitchError::NoClips { needed: 1 })?;
        layout.validate(&first.skeleton)?;
        let fps = first.fps();
        let label = |i: usize| names.get(i).map(|n| format!(" ({n})")).unwrap_or_default();
        for (i, c) in clips.iter().enumerate().skip(1) {
            if let Some(why) = first.skeleton.topology_difference(&c.skeleton) {
                return Err(StitchError::Skeleton { index: i, name: label(i), why });
            }
            if !c.plays_at(fps) {
                return Err(StitchError::FrameRate { index: i, name: label(i), expected: fps, found: c.fps() });
            }
        }
        let (global_positions, roots): (Vec<_>, Vec<_>) = clips
            .par_iter()
            .map(|c| {
                let (_, gp) = c.global();
                (gp, super::layout::ground_roots(c, &layout))
            })
            .unzip();
        let names =
            if names.len() == clips.len() { names } else { (0..clips.len()).map(|i| format!("clip {i}")).collect() };
        Ok(MotionSet { clips, names, global_positions, roots, layout, fps })
    }

    /// [`MotionSet::new`] on named clips of a dataset.
    pub fn from_named(
        clips: Vec<zoo_data::dataset::NamedClip>,
        layout: StitchLayout,
    ) -> Result<MotionSet, StitchError> {
        let names = clips.iter().map(|c| c.name.clone()).collect();
        MotionSet::new(clips.into_iter().map(|c| c.clip).collect(), names, layout)
    }

    /// Joints per frame.
    pub fn joints(&self) -> usize {
        self.clips[0].joints()
    }

    /// Frames of clip `c`.
    pub fn frames(&self, c: usize) -> usize {
        self.roots[c].len()
    }

    /// Total frames over all clips.
    pub fn total_frames(&self) -> usize {
        self.roots.iter().map(Vec::len).sum()
    }

    /// Frames of the longest clip.
    pub fn longest(&self) -> usize {
        self.roots.iter().map(Vec::len).max().unwrap_or(0)
    }

    /// Errors unless `other` has the same rig and frame rate.
    pub fn check_compatible(&self, other: &MotionSet) -> Result<(), StitchError> {
        if let Some(why) = self.clips[0].skeleton.topology_difference(&other.clips[0].skeleton) {
            return Err(StitchError::Mismatch(format!("skeletons differ ({why})")));
        }
        if !zoo_motion::clip::same_frame_rate(other.fps, self.fps) {
            return Err(StitchError::Mismatch(format!("{} fps vs {} fps", self.fps, other.fps)));
        }
        Ok(())
    }

    /// Number of values of the feature of a segment of `length` frames.
    pub fn feature_dim(&self, length: usize) -> usize {
        6 * self.joints() + 4 * length
    }

    /// Writes the weighted feature of frames `start..start + length` of clip `clip` into `out`
    /// (`feature_dim(length)` values; layout in the module docs).
    pub fn segment_feature(&self, clip: usize, start: usize, length: usize, out: &mut [f32]) {
        let j = self.joints();
        debug_assert_eq!(out.len(), self.feature_dim(length));
        let roots = &self.roots[clip][start..start + length];
        let gp = &self.global_positions[clip];
        let origin = roots[0];
        let (last, rest) = out.split_at_mut(3 * j);
        let (traj, first) = rest.split_at_mut(4 * length);
        let pose = |frame: usize, w: f64, o: &mut [f32]| {
            for (k, p) in gp[frame * j..(frame + 1) * j].iter().enumerate() {
                let l = origin.to_local(*p) * w;
                o[3 * k..3 * k + 3].copy_from_slice(&[l.x as f32, l.y as f32, l.z as f32]);
            }
        };
        pose(start + length - 1, W_LAST, last);
        pose(start, W_FIRST, first);
        for (t, r) in roots.iter().enumerate() {
            let p = origin.to_local(r.pos) * W_TRAJECTORY;
            let f = DVec3::new((r.yaw - origin.yaw).sin(), 0.0, (r.yaw - origin.yaw).cos()) * W_TRAJECTORY;
            traj[4 * t..4 * t + 4].copy_from_slice(&[p.x as f32, p.z as f32, f.x as f32, f.z as f32]);
        }
    }
}

/// Where a database segment comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct SegmentRef {
    /// Clip index in the database's [`MotionSet`].
    pub clip: u32,
    /// First frame.
    pub start: u32,
}

/// Every segment of one length (starts every `stride` frames of every clip) and its feature.
///
/// Rows are stored with their values permuted by decreasing variance over the database
/// ([`SegmentDatabase::order`]), so that the early-terminating search sums the most telling
/// values first; a query goes through [`SegmentDatabase::permute`] (done by
/// [`SegmentDatabase::nearest`]). Distances do not depend on the order.
#[derive(Clone, Debug)]
pub struct SegmentDatabase {
    /// Frames per segment.
    pub length: usize,
    /// Values per feature.
    pub dim: usize,
    /// Features, one row of `dim` values per segment, permuted by `order`.
    pub features: Vec<f32>,
    /// Stored value `i` of a row is value `order[i]` of [`MotionSet::segment_feature`].
    pub order: Vec<usize>,
    /// Source of each row.
    pub segments: Vec<SegmentRef>,
}

impl SegmentDatabase {
    /// Builds the database of segments of `length` frames starting every `stride` frames.
    pub fn build(set: &MotionSet, length: usize, stride: usize) -> SegmentDatabase {
        let dim = set.feature_dim(length);
        let segments: Vec<SegmentRef> = (0..set.clips.len())
            .flat_map(|c| {
                let n = set.frames(c);
                (0..n.saturating_sub(length - 1))
                    .step_by(stride)
                    .map(move |s| SegmentRef { clip: c as u32, start: s as u32 })
            })
            .collect();
        let mut features = vec![0.0f32; segments.len() * dim];
        features.par_chunks_mut(dim).zip(segments.par_iter()).for_each(|(row, s)| {
            set.segment_feature(s.clip as usize, s.start as usize, length, row);
        });
        let n = segments.len().max(1) as f64;
        let (mut sum, mut sq) = (vec![0.0f64; dim], vec![0.0f64; dim]);
        for row in features.chunks_exact(dim) {
            for (i, &v) in row.iter().enumerate() {
                sum[i] += v as f64;
                sq[i] += (v as f64) * (v as f64);
            }
        }
        let var: Vec<f64> = sum.iter().zip(&sq).map(|(s, q)| q / n - (s / n) * (s / n)).collect();
        let mut order: Vec<usize> = (0..dim).collect();
        order.sort_by(|&a, &b| var[b].total_cmp(&var[a]).then(a.cmp(&b)));
        features.par_chunks_mut(dim).for_each(|row| {
            let orig = row.to_vec();
            for (dst, &src) in row.iter_mut().zip(&order) {
                *dst = orig[src];
            }
        });
        SegmentDatabase { length, dim, features, order, segments }
    }

    /// A feature of [`MotionSet::segment_feature`]'s layout in the stored order.
    pub fn permute(&self, feature: &[f32]) -> Vec<f32> {
        self.order.iter().map(|&i| feature[i]).collect()
    }

    /// Number of segments.
    pub fn len(&self) -> usize {
        self.segments.len()
    }

    /// True when the database holds no segment.
    pub fn is_empty(&self) -> bool {
        self.segments.is_empty()
    }

    /// Feature row `i` (in the stored order).
    pub fn feature(&self, i: usize) -> &[f32] {
        &self.features[i * self.dim..(i + 1) * self.dim]
    }

    /// The `k` nearest segments to `query` (a feature in [`MotionSet::segment_feature`]'s
    /// layout; exact; ascending distance, ties by index), skipping segments of clip `exclude_clip`.
    pub fn nearest(&self, query: &[f32], k: usize, exclude_clip: Option<usize>) -> Vec<knn::Neighbour> {
        let skip = |i: usize| exclude_clip.is_some_and(|c| self.segments[i].clip as usize == c);
        knn::k_nearest(&self.features, self.dim, &self.permute(query), k, skip)
    }
}

/// One [`SegmentDatabase`] per segment length.
#[derive(Clone, Debug)]
pub struct StitchDatabases {
    /// Start step of the segments, frames.
    pub stride: usize,
    /// Databases in increasing length.
    pub databases: Vec<SegmentDatabase>,
}

impl StitchDatabases {
    /// Builds a database for each of `lengths` over `set` (segments start every `stride` frames).
    pub fn build(set: &MotionSet, lengths: &[usize], stride: usize) -> Result<StitchDatabases, StitchError> {
        if stride == 0 {
            return Err(StitchError::Config("the database stride must be at least 1 frame".into()));
        }
        let mut lengths = lengths.to_vec();
        lengths.sort_unstable();
        lengths.dedup();
        if lengths.first() == Some(&0) {
            return Err(StitchError::Config("segment lengths must be at least 1 frame".into()));
        }
        if let Some(&max) = lengths.last()
            && max > set.longest()
        {
            return Err(StitchError::TooShort { needed: max, longest: set.longest() });
        }
        let databases = lengths.iter().map(|&l| SegmentDatabase::build(set, l, stride)).collect();
        Ok(StitchDatabases { stride, databases })
    }

    /// The database of segments of `length` frames.
    pub fn get(&self, length: usize) -> Result<&SegmentDatabase, StitchError> {
        self.databases
            .iter()
            .find(|d| d.length == length)
            .ok_or_else(|| StitchError::NoDatabase { length, built: self.databases.iter().map(|d| d.length).collect() })
    }

    /// Segments over all databases.
    pub fn total_segments(&self) -> usize {
        self.databases.iter().map(SegmentDatabase::len).sum()
    }

    /// Bytes of stored features.
    pub fn feature_bytes(&self) -> usize {
        self.databases.iter().map(|d| d.features.len() * 4).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DQuat;
    use zoo_motion::{JointChannels, Skeleton};

    /// Two joints: hips and a foot 10 below and 5 ahead in the hips' local frame. The hips
    /// walk along +X while facing +X (yaw pi/2), one unit per frame.
    fn straight_walk(frames: usize) -> (Clip, StitchLayout) {
        let skeleton = Skeleton {
            names: vec!["Hips".into(), "Foot".into()],
            parents: vec![None, Some(0)],
            offsets: vec![DVec3::ZERO, DVec3::new(0.0, -10.0, 5.0)],
            end_sites: vec![None, Some(DVec3::ZERO)],
            channels: vec![JointChannels::default(); 2],
        };
        let yaw = DQuat::from_rotation_y(std::f64::consts::FRAC_PI_2);
        let mut clip = Clip { skeleton, frame_time: 1.0 / 30.0, local_rotations: vec![], local_positions: vec![] };
        for f in 0..frames {
            clip.local_rotations.extend([yaw, DQuat::IDENTITY]);
            clip.local_positions.extend([DVec3::new(f as f64, 20.0, 3.0), DVec3::new(0.0, -10.0, 5.0)]);
        }
        let layout = StitchLayout {
            lower_body: vec![0, 1],
            contacts: [1, 1, 1, 1],
            contact_thresholds: [2.5, 1.6, 2.5, 1.6],
            planted: [0.0; 4],
            forward_axis: DVec3::Z,
        };
        (clip, layout)
    }

    #[test]
    fn feature_by_hand() {
        let (clip, layout) = straight_walk(6);
        let set = MotionSet::new(vec![clip], vec![], layout).unwrap();
        assert!((set.roots[0][2].yaw - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        let mut m = vec![0.0f32; set.feature_dim(3)];
        set.segment_feature(0, 2, 3, &mut m);
        // In the first root's frame the character faces +Z and walks along +Z; the foot is 10
        // below the hips (hips at height 20) and 5 ahead.
        let want: Vec<f32> = [
            vec![0.0, 20.0, 2.0, 0.0, 10.0, 7.0],                             // last pose
            vec![0.0, 0.0, 0.0, 1.0, 0.0, 1.0, 0.0, 1.0, 0.0, 2.0, 0.0, 1.0], // trajectory
            vec![0.0, 2.0, 0.0, 0.0, 1.0, 0.5],                               // 0.1 * first pose
        ]
        .concat();
        for (a, b) in m.iter().zip(&want) {
            assert!((a - b).abs() < 1e-5, "{m:?} vs {want:?}");
        }
    }

    #[test]
    fn databases_hold_every_start_and_refuse_bad_input() {
        let (clip, layout) = straight_walk(25);
        let set = MotionSet::new(vec![clip.clone(), clip.slice(0, 12)], vec![], layout.clone()).unwrap();
        let dbs = StitchDatabases::build(&set, &[10, 20], 2).unwrap();
        // length 10: starts 0,2,..,14 (8) in the first clip, 0,2 in the second
        assert_eq!(dbs.get(10).unwrap().len(), 10);
        assert_eq!(dbs.get(20).unwrap().len(), 3);
        assert!(dbs.get(30).unwrap_err().to_string().contains("[10, 20]"));
        let db = dbs.get(10).unwrap();
        let mut m = vec![0.0f32; set.feature_dim(10)];
        set.segment_feature(0, 4, 10, &mut m);
        assert_eq!(db.feature(2), db.permute(&m).as_slice(), "row 2 is clip 0 from frame 4, permuted");
        let mut sorted = db.order.clone();
        sorted.sort_unstable();
        assert_eq!(sorted, (0..db.dim).collect::<Vec<_>>());
        assert!(StitchDatabases::build(&set, &[30], 1).unwrap_err().to_string().contains("longest has 25"));
        let mut other = clip.clone();
        other.frame_time = 1.0 / 60.0;
        let err =
            MotionSet::new(vec![clip.clone(), other], vec!["a".into(), "b.bvh".into()], layout.clone()).unwrap_err();
        assert!(err.to_string().contains("b.bvh") && err.to_string().contains("60 fps"), "{err}");
        let mut other = clip;
        other.skeleton.names[1] = "Toe".into();
        let err =
            MotionSet::new(vec![other.clone(), other.slice(0, 3), straight_walk(3).0], vec![], layout).unwrap_err();
        assert!(err.to_string().contains("clip 2"), "{err}");
    }
}

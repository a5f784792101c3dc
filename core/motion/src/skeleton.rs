//! Skeleton: joint names, parents, rest offsets and the channel layout they were read with.

use crate::euler::EulerOrder;
use glam::DVec3;
use serde::{Deserialize, Serialize};

/// Which animation channels a joint carries (kept so a BVH re-export has the same layout).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct JointChannels {
    /// The joint has `Xposition Yposition Zposition` channels.
    pub position: bool,
    /// Order of the three rotation channels.
    pub order: EulerOrder,
}

impl Default for JointChannels {
    fn default() -> Self {
        JointChannels { position: false, order: EulerOrder::Zxy }
    }
}

/// A joint hierarchy. Joint 0 is the root; every parent index is smaller than its child's.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Skeleton {
    /// Joint names, unique.
    pub names: Vec<String>,
    /// Parent of each joint (`None` for the root only).
    pub parents: Vec<Option<usize>>,
    /// Rest offset of each joint from its parent, in the parent's frame (clip units).
    pub offsets: Vec<DVec3>,
    /// Offset of the `End Site` below a joint, if it has one.
    pub end_sites: Vec<Option<DVec3>>,
    /// Channel layout of each joint.
    pub channels: Vec<JointChannels>,
}

/// Why a skeleton is not well formed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SkeletonError(pub String);

impl std::fmt::Display for SkeletonError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}
impl std::error::Error for SkeletonError {}

impl Skeleton {
    /// The deepest joint hierarchy a file may define (levels below the root). Real skeletons
    /// have under 100; readers refuse a deeper one at parse time, so no walk over a hierarchy
    /// (printing, writing, fitting) meets an unbounded depth.
    pub const MAX_DEPTH: usize = 1000;

    /// The most joints a file may define. Real skeletons have under 1000; some walks over a
    /// skeleton (children of every joint) take time growing with the square of the count, so
    /// readers refuse more at parse time.
    pub const MAX_JOINTS: usize = 10_000;

    /// The number of levels below the root (0 for a lone root); parents come before children,
    /// so one pass suffices.
    pub fn depth(&self) -> usize {
        let mut depth = vec![0usize; self.len()];
        for j in 0..self.len() {
            if let Some(p) = self.parents[j].filter(|&p| p < j) {
                depth[j] = depth[p] + 1;
            }
        }
        depth.into_iter().max().unwrap_or(0)
    }

    /// Number of joints.
    pub fn len(&self) -> usize {
        self.names.len()
    }

    /// True when the skeleton has no joints.
    pub fn is_empty(&self) -> bool {
        self.names.is_empty()
    }

    /// Index of the joint called `name`.
    pub fn index_of(&self, name: &str) -> Option<usize> {
        self.names.iter().position(|n| n == name)
    }

    /// Children of joint `j`, in index order.
    pub fn children(&self, j: usize) -> Vec<usize> {
        (0..self.len()).filter(|&c| self.parents[c] == Some(j)).collect()
    }

    /// Parents as `i32` with -1 for the root (the layout of exported metadata).
    pub fn parents_i32(&self) -> Vec<i32> {
        self.parents.iter().map(|p| p.map_or(-1, |p| p as i32)).collect()
    }

    /// Checks array lengths, unique names, a single root at 0 and parents before children.
    pub fn validate(&self) -> Result<(), SkeletonError> {
        let n = self.names.len();
        if n == 0 {
            return Err(SkeletonError("skeleton has no joints".into()));
        }
        for (what, len) in [
            ("parents", self.parents.len()),
            ("offsets", self.offsets.len()),
            ("end_sites", self.end_sites.len()),
            ("channels", self.channels.len()),
        ] {
            if len != n {
                return Err(SkeletonError(format!("skeleton has {n} joint names but {len} {what}")));
            }
        }
        if self.parents[0].is_some() {
            return Err(SkeletonError(format!("joint 0 `{}` must be the root", self.names[0])));
        }
        for j in 1..n {
            match self.parents[j] {
                Some(p) if p < j => {}
                Some(p) => {
                    return Err(SkeletonError(format!(
                        "joint {j} `{}` has parent {p}, which does not come before it",
                        self.names[j]
                    )));
                }
                None => {
                    return Err(SkeletonError(format!("joint {j} `{}` is a second root", self.names[j])));
                }
            }
        }
        let mut seen = std::collections::HashSet::new();
        for name in &self.names {
            if !seen.insert(name.as_str()) {
                return Err(SkeletonError(format!("joint name `{name}` appears twice")));
            }
        }
        Ok(())
    }

    /// Same names and parents (offsets may differ: other actors, same rig).
    pub fn same_topology(&self, other: &Skeleton) -> bool {
        self.names == other.names && self.parents == other.parents
    }

    /// Explains how `other` differs from `self` (for "wrong skeleton" errors), or `None`.
    pub fn topology_difference(&self, other: &Skeleton) -> Option<String> {
        if self.len() != other.len() {
            return Some(format!("expected {} joints, found {}", self.len(), other.len()));
        }
        for j in 0..self.len() {
            if self.names[j] != other.names[j] {
                return Some(format!("joint {j}: expected `{}`, found `{}`", self.names[j], other.names[j]));
            }
            if self.parents[j] != other.parents[j] {
                return Some(format!("joint `{}`: parent differs", self.names[j]));
            }
        }
        None
    }

    /// Length of each bone (|offset|; 0 for the root).
    pub fn bone_lengths(&self) -> Vec<f64> {
        (0..self.len()).map(|j| if self.parents[j].is_some() { self.offsets[j].length() } else { 0.0 }).collect()
    }
}

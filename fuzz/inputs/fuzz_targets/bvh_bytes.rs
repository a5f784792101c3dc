//! BVH bytes (`zoo_data::bvh::parse_bytes`, the reader of every BVH file zoo opens) must parse
//! or fail with an error, never panic. A parsed clip must hold what the reader promises (a
//! frame time in range, finite values, one rotation and position per joint and frame, parents
//! before children) and survive a write and re-read.
#![no_main]

use libfuzzer_sys::fuzz_target;
use std::path::Path;
use zoo_data::bvh::{ReadOptions, parse, parse_bytes, to_string};
use zoo_motion::Clip;

fuzz_target!(|data: &[u8]| {
    for drop_dummy_root in [false, true] {
        let opts = ReadOptions { drop_dummy_root };
        let Ok(clip) = parse_bytes(data, Path::new("fuzz.bvh"), &opts) else { continue };
        let (lo, hi) = Clip::FRAME_TIME_RANGE;
        assert!((lo..=hi).contains(&clip.frame_time), "frame time {}", clip.frame_time);
        let joints = clip.joints();
        assert!(joints >= 1);
        assert_eq!(clip.local_rotations.len(), clip.frames() * joints);
        assert_eq!(clip.local_positions.len(), clip.frames() * joints);
        assert!(clip.local_rotations.iter().all(|q| q.is_finite()), "a rotation is not finite");
        assert!(clip.local_positions.iter().all(|p| p.is_finite()), "a position is not finite");
        for (j, p) in clip.skeleton.parents.iter().enumerate() {
            assert!(p.is_none_or(|p| p < j), "joint {j}'s parent {p:?} is not before it");
        }
        let again = to_string(&clip);
        let back =
            parse(&again, Path::new("fuzz-rewritten.bvh"), &ReadOptions::default()).expect("a written clip re-reads");
        assert_eq!(back.frames(), clip.frames());
        assert_eq!(back.joints(), clip.joints());
    }
});

//! Keys files (`zoo complete`): the same bytes through the lamp's parser
//! (`zoo_arnn::completion::parse_keys`) and the humanoid one (`parse_humanoid_keys`). Each must
//! parse or fail with an error, never panic; what parses must be within the documented ranges
//! (frames from 0, strictly increasing, within the longest completion; the first key's frame
//! and every source frame within the frame-number range; pose values finite and within
//! `MAX_KEY_VALUE`; fps in [1, 1000]).
#![no_main]

use libfuzzer_sys::fuzz_target;
use zoo_arnn::completion::{MAX_FRAMES, MAX_KEY_FRAME, MAX_KEY_VALUE, parse_humanoid_keys, parse_keys};
use zoo_arnn::luxo::DOF_NAMES;

fn check_frames(frames: &[usize], offset: usize, fps: Option<f64>) {
    assert!(frames.len() >= 2 && frames.len() <= MAX_FRAMES, "{} keys", frames.len());
    assert_eq!(frames[0], 0);
    assert!(frames.windows(2).all(|w| w[0] < w[1]), "{frames:?}");
    assert!(*frames.last().unwrap() < MAX_FRAMES);
    assert!(offset <= MAX_KEY_FRAME, "offset {offset}");
    assert!(fps.is_none_or(|f| (1.0..=1000.0).contains(&f)), "{fps:?}");
}

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    let dofs: Vec<String> = DOF_NAMES.iter().map(|s| s.to_string()).collect();
    if let Ok(k) = parse_keys(text, &dofs) {
        check_frames(&k.frames, k.offset, k.fps);
        assert_eq!(k.poses.len(), k.frames.len());
        for p in &k.poses {
            assert_eq!(p.len(), dofs.len());
            assert!(p.iter().all(|v| v.is_finite() && v.abs() <= MAX_KEY_VALUE), "{p:?}");
        }
    }
    let joints: Vec<String> = ["Hips", "Spine", "Head"].iter().map(|s| s.to_string()).collect();
    if let Ok(k) = parse_humanoid_keys(text, &joints) {
        let frames: Vec<usize> = k.keys.iter().map(|k| k.frame).collect();
        check_frames(&frames, k.offset, k.fps);
        for (i, key) in k.keys.iter().enumerate() {
            assert!(key.source <= MAX_KEY_FRAME, "source frame {}", key.source);
            if let Some(m) = &key.fixed {
                assert_eq!(m.len(), 1 + joints.len());
                assert!(m.contains(&true));
                assert!(i > 0 || !m.contains(&false), "the first key fixes part of the pose");
            }
        }
    }
});

//! BVH reading and writing: hand-written files with known rotations, layout variants
//! (3/6 channels, rotation orders, interleaved channels, tabs/spaces/CRLF, End Sites), round
//! trips, and the real bandai2 clips (an ignored test: run it with `--ignored` where the
//! dataset is present).

use glam::{DQuat, DVec3};
use std::io::Read;
use std::path::{Path, PathBuf};
use zoo_data::bvh::{BvhError, ReadOptions, parse, read_file, to_string, write_file};
use zoo_motion::rng::SplitMix64;
use zoo_motion::{Clip, EulerOrder, JointChannels, Skeleton};

fn read(text: &str) -> Clip {
    parse(text, Path::new("test.bvh"), &ReadOptions::default()).unwrap()
}

/// Angle in degrees between two rotations (q and -q are the same rotation).
fn angle_deg(a: DQuat, b: DQuat) -> f64 {
    let d = a.inverse() * b;
    (2.0 * d.xyz().length().atan2(d.w.abs())).to_degrees()
}

fn q(axis: DVec3, deg: f64) -> DQuat {
    DQuat::from_axis_angle(axis, deg.to_radians())
}

/// Largest rotation (degrees) and translation difference between two clips of equal shape.
fn clip_error(a: &Clip, b: &Clip) -> (f64, f64) {
    assert_eq!(a.skeleton.names, b.skeleton.names);
    assert_eq!(a.skeleton.parents, b.skeleton.parents);
    assert_eq!(a.frames(), b.frames());
    let rot = a.local_rotations.iter().zip(&b.local_rotations).map(|(&x, &y)| angle_deg(x, y)).fold(0.0, f64::max);
    let pos = a
        .local_positions
        .iter()
        .zip(&b.local_positions)
        .map(|(x, y)| (*x - *y).abs().max_element())
        .fold(0.0, f64::max);
    (rot, pos)
}

fn round_trip(clip: &Clip) -> Clip {
    let text = to_string(clip);
    parse(&text, Path::new("written.bvh"), &ReadOptions::default()).unwrap_or_else(|e| panic!("{e}\n{text}"))
}

fn assert_round_trip(clip: &Clip) {
    let back = round_trip(clip);
    let (rot, pos) = clip_error(clip, &back);
    assert!(rot <= 1e-4, "rotation round-trip error {rot} degrees");
    assert!(pos <= 1e-4, "translation round-trip error {pos}");
    assert_eq!(back.skeleton.offsets, clip.skeleton.offsets);
    assert_eq!(back.skeleton.end_sites, clip.skeleton.end_sites);
    assert_eq!(back.skeleton.channels, clip.skeleton.channels);
    assert_eq!(back.frame_time, clip.frame_time);
}

/// XYZ root with 6 channels, a 3-channel XYZ child and a 3-channel YXZ grandchild.
const THREE_CHANNEL: &str = "HIERARCHY
ROOT Hips
{
\tOFFSET 0 90 0
\tCHANNELS 6 Xposition Yposition Zposition Xrotation Yrotation Zrotation
\tJOINT Thigh
\t{
\t\tOFFSET 10 -5 0
\t\tCHANNELS 3 Xrotation Yrotation Zrotation
\t\tJOINT Shin
\t\t{
\t\t\tOFFSET 0 -40 0
\t\t\tCHANNELS 3 Yrotation Xrotation Zrotation
\t\t\tEnd Site
\t\t\t{
\t\t\t\tOFFSET 0 -40 2.5
\t\t\t}
\t\t}
\t}
}
MOTION
Frames: 3
Frame Time: 0.008333
0 0 0 0 0 0 0 0 0 0 0 0
1.5 91 -2 90 0 0 0 90 0 0 0 90
1 2 3 30 45 60 10 20 30 -30 15 120
";

#[test]
fn reads_three_channel_joints_with_known_rotations() {
    let clip = read(THREE_CHANNEL);
    let sk = &clip.skeleton;
    assert_eq!(sk.names, ["Hips", "Thigh", "Shin"]);
    assert_eq!(sk.parents, [None, Some(0), Some(1)]);
    assert_eq!(sk.offsets[1], DVec3::new(10.0, -5.0, 0.0));
    assert_eq!(sk.end_sites, [None, None, Some(DVec3::new(0.0, -40.0, 2.5))]);
    assert_eq!(sk.channels[0], JointChannels { position: true, order: EulerOrder::Xyz });
    assert_eq!(sk.channels[1], JointChannels { position: false, order: EulerOrder::Xyz });
    assert_eq!(sk.channels[2], JointChannels { position: false, order: EulerOrder::Yxz });
    assert_eq!(clip.frames(), 3);
    assert!((clip.frame_time - 0.008333).abs() < 1e-15);
    // Frame 0: identity everywhere; 3-channel joints keep their offsets.
    for j in 0..3 {
        assert!(angle_deg(clip.rotations_at(0)[j], DQuat::IDENTITY) < 1e-12);
    }
    assert_eq!(clip.positions_at(0), &[DVec3::ZERO, sk.offsets[1], sk.offsets[2]]);
    // Frame 1: single-axis rotations, hand-computed.
    let r = clip.rotations_at(1);
    assert!(angle_deg(r[0], q(DVec3::X, 90.0)) < 1e-12);
    assert!(angle_deg(r[1], q(DVec3::Y, 90.0)) < 1e-12);
    assert!(angle_deg(r[2], q(DVec3::Z, 90.0)) < 1e-12);
    assert_eq!(clip.positions_at(1)[0], DVec3::new(1.5, 91.0, -2.0));
    assert_eq!(clip.positions_at(1)[2], sk.offsets[2]);
    // Frame 2: XYZ is qx*qy*qz; the YXZ joint is qy*qx*qz (channel order = multiplication order).
    let r = clip.rotations_at(2);
    let hips = q(DVec3::X, 30.0) * q(DVec3::Y, 45.0) * q(DVec3::Z, 60.0);
    let shin = q(DVec3::Y, -30.0) * q(DVec3::X, 15.0) * q(DVec3::Z, 120.0);
    assert!(angle_deg(r[0], hips) < 1e-12);
    assert!(angle_deg(r[2], shin) < 1e-12);
    // A point on the X axis rotated by Y 90 degrees ends on -Z (checks the handedness).
    assert!((clip.rotations_at(1)[1] * DVec3::X - DVec3::NEG_Z).length() < 1e-12);
    for r in &clip.local_rotations {
        assert!((r.length() - 1.0).abs() < 1e-12);
    }
}

#[test]
fn spaces_tabs_and_crlf_read_the_same() {
    let tabs = read(THREE_CHANNEL);
    let spaces = read(&THREE_CHANNEL.replace('\t', "    ").replace(" 0 ", "  0   "));
    let crlf = read(&THREE_CHANNEL.replace('\n', "\r\n"));
    let mixed = read(&THREE_CHANNEL.replace('\t', " \t").replace('\n', " \r\n\n"));
    assert_eq!(tabs, spaces);
    assert_eq!(tabs, crlf);
    assert_eq!(tabs, mixed);
}

#[test]
fn interleaved_position_channels_are_read_by_name() {
    let normal = read(THREE_CHANNEL);
    // Same motion, root channels reordered: rotation and position interleaved.
    let mut text = THREE_CHANNEL.replace(
        "CHANNELS 6 Xposition Yposition Zposition Xrotation Yrotation Zrotation",
        "CHANNELS 6 Xrotation Zposition Yrotation Xposition Zrotation Yposition",
    );
    for (old, new) in [("1.5 91 -2 90 0 0 ", "90 -2 0 1.5 0 91 "), ("1 2 3 30 45 60 ", "30 3 45 1 60 2 ")] {
        text = text.replace(old, new);
    }
    let clip = read(&text);
    assert_eq!(clip.local_positions, normal.local_positions);
    let (rot, _) = clip_error(&clip, &normal);
    assert!(rot < 1e-12);
    assert_eq!(clip.skeleton.channels[0], JointChannels { position: true, order: EulerOrder::Xyz });
}

#[test]
fn any_frame_time() {
    for ft in ["1", "0.0333333", "0.00416667", "2.5e-2"] {
        let clip = read(&THREE_CHANNEL.replace("0.008333", ft));
        assert_eq!(clip.frame_time, ft.parse::<f64>().unwrap());
    }
}

#[test]
fn round_trip_hand_written_file() {
    let clip = read(THREE_CHANNEL);
    assert_round_trip(&clip);
    // The written file re-reads to the same Euler angles too (no wrap past +-180 here).
    let back = round_trip(&clip);
    for f in 0..clip.frames() {
        for j in 0..3 {
            let order = clip.skeleton.channels[j].order;
            let (a, b) = (clip.euler_deg(f, j, order), back.euler_deg(f, j, order));
            for k in 0..3 {
                assert!((a[k] - b[k]).abs() <= 1e-4, "frame {f} joint {j}: {a:?} vs {b:?}");
            }
        }
    }
}

/// A chain with one joint per rotation order (alternating 3 and 6 channels) and random motion.
fn random_clip(frames: usize, seed: u64) -> Clip {
    let mut rng = SplitMix64::new(seed);
    let n = EulerOrder::ALL.len();
    let skeleton = Skeleton {
        names: (0..n).map(|j| format!("joint_{j}")).collect(),
        parents: (0..n).map(|j| j.checked_sub(1)).collect(),
        offsets: (0..n).map(|j| DVec3::new(j as f64 * 1.25, 10.0 / 3.0, -0.1)).collect(),
        end_sites: (0..n).map(|j| (j == n - 1).then_some(DVec3::new(0.0, 7.0, 0.0))).collect(),
        channels: EulerOrder::ALL
            .iter()
            .enumerate()
            .map(|(j, &order)| JointChannels { position: j % 2 == 0, order })
            .collect(),
    };
    let mut local_rotations = Vec::new();
    let mut local_positions = Vec::new();
    for _ in 0..frames {
        for j in 0..n {
            let angles =
                [360.0 * rng.next_f64() - 180.0, 360.0 * rng.next_f64() - 180.0, 360.0 * rng.next_f64() - 180.0];
            local_rotations.push(skeleton.channels[j].order.to_quat_deg(angles));
            local_positions.push(if skeleton.channels[j].position {
                DVec3::new(rng.next_f64() * 400.0 - 200.0, rng.next_f64() * 100.0, rng.next_f64() * 1e4 - 5e3)
            } else {
                skeleton.offsets[j]
            });
        }
    }
    Clip { skeleton, frame_time: 1.0 / 30.0, local_rotations, local_positions }
}

#[test]
fn round_trip_every_rotation_order() {
    assert_round_trip(&random_clip(200, 0x9e3779b97f4a7c15));
}

#[test]
fn writer_adds_position_channels_for_animated_translations() {
    let mut clip = random_clip(5, 7);
    clip.skeleton.channels[0].position = false; // a root built by code, moving
    let back = round_trip(&clip);
    assert!(back.skeleton.channels[0].position);
    let (_, pos) = clip_error(&clip, &back);
    assert!(pos <= 1e-4);
}

#[test]
fn written_file_has_the_standard_layout() {
    let text = to_string(&read(THREE_CHANNEL));
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines[0], "HIERARCHY");
    assert_eq!(lines[1], "ROOT Hips");
    assert_eq!(lines[2], "{");
    assert_eq!(lines[3], "\tOFFSET 0 90 0");
    assert_eq!(lines[4], "\tCHANNELS 6 Xposition Yposition Zposition Xrotation Yrotation Zrotation");
    assert_eq!(lines[5], "\tJOINT Thigh");
    assert_eq!(lines[8], "\t\tCHANNELS 3 Xrotation Yrotation Zrotation");
    assert_eq!(lines[12], "\t\t\tCHANNELS 3 Yrotation Xrotation Zrotation");
    assert_eq!(lines[13], "\t\t\tEnd Site");
    assert_eq!(lines[15], "\t\t\t\tOFFSET 0 -40 2.5");
    let motion = lines.iter().position(|l| *l == "MOTION").unwrap();
    assert_eq!(lines[motion - 1], "}");
    assert_eq!(lines[motion + 1], "Frames: 3");
    assert_eq!(lines[motion + 2], "Frame Time: 0.008333");
    assert_eq!(lines[motion + 3].split(' ').count(), 12);
    assert_eq!(lines.len(), motion + 6);
}

#[test]
fn write_file_plain_and_gzip_atomically() {
    let dir = tempfile::tempdir().unwrap();
    let clip = read(THREE_CHANNEL);
    for name in ["out.bvh", "out.bvh.gz"] {
        let path = dir.path().join(name);
        write_file(&clip, &path).unwrap();
        let raw = std::fs::read(&path).unwrap();
        assert_eq!(raw.starts_with(&[0x1f, 0x8b]), name.ends_with(".gz"));
        let back = read_file(&path, &ReadOptions::default()).unwrap();
        let (rot, pos) = clip_error(&clip, &back);
        assert!(rot <= 1e-4 && pos <= 1e-4);
        // Overwriting works too.
        write_file(&clip, &path).unwrap();
    }
    let mut left: Vec<String> =
        std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    left.sort();
    assert_eq!(left, ["out.bvh", "out.bvh.gz"], "no temporary files are left behind");
}

#[test]
fn read_file_reports_missing_files() {
    let err = read_file(Path::new("/nonexistent/x.bvh"), &ReadOptions::default()).unwrap_err();
    assert!(matches!(err, BvhError::Io { .. }));
    assert!(err.to_string().starts_with("/nonexistent/x.bvh: cannot read"));
}

/// Like bandai2: an all-zero 6-channel dummy root above `Hips`, ZXY order, CRLF, spaces.
const DUMMY_ROOT: &str = "HIERARCHY\r\nROOT joint_Root\r\n{\r\n  OFFSET 0.0 0.0 0.0\r\n  \
CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation \r\n  JOINT Hips\r\n  {\r\n    \
OFFSET 4.5 91.5 -427.25\r\n    CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\r\n    \
JOINT Spine\r\n    {\r\n      OFFSET 15.7 0 0\r\n      \
CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\r\n      \
End Site\r\n      {\r\n        OFFSET 0 0 0\r\n      }\r\n    }\r\n  }\r\n}\r\nMOTION\r\nFrames: 2\r\n\
Frame Time: 0.0333333\r\n\
0 0 0 0 0 0 4.5 91.5 -427.25 10 20 30 15.7 0 0 1 2 3\r\n\
0.0 -0 0 0 0 0 5.5 92.5 -420 -10 -20 -30 15.7 0 0 4 5 6\r\n";

#[test]
fn drop_dummy_root_makes_hips_the_root() {
    let raw = read(DUMMY_ROOT);
    assert_eq!(raw.joints(), 3);
    let opts = ReadOptions { drop_dummy_root: true };
    let clip = parse(DUMMY_ROOT, Path::new("d.bvh"), &opts).unwrap();
    assert_eq!(clip.skeleton.names, ["Hips", "Spine"]);
    assert_eq!(clip.skeleton.parents, [None, Some(0)]);
    assert_eq!(clip.skeleton.end_sites, [None, Some(DVec3::ZERO)]);
    assert_eq!(clip.root_position(1), DVec3::new(5.5, 92.5, -420.0));
    let zxy = EulerOrder::Zxy.to_quat_deg([-10.0, -20.0, -30.0]);
    assert!(angle_deg(clip.rotations_at(1)[0], zxy) < 1e-12);
    assert_eq!(clip.skeleton.channels[0], JointChannels { position: true, order: EulerOrder::Zxy });
    // Global motion is unchanged by dropping the dummy.
    let (_, gp_raw) = raw.global();
    let (_, gp) = clip.global();
    for f in 0..2 {
        for j in 0..2 {
            assert!((gp_raw[f * 3 + j + 1] - gp[f * 2 + j]).length() < 1e-9);
        }
    }
    assert_round_trip(&clip);
}

#[test]
fn drop_dummy_root_keeps_a_moving_or_offset_root() {
    let opts = ReadOptions { drop_dummy_root: true };
    let moving = DUMMY_ROOT.replace("0.0 -0 0 0 0 0 5.5", "0.0 -0 0 0 0.5 0 5.5");
    assert_eq!(parse(&moving, Path::new("d.bvh"), &opts).unwrap().joints(), 3);
    let offset = DUMMY_ROOT.replace("OFFSET 0.0 0.0 0.0", "OFFSET 0.0 1.0 0.0");
    assert_eq!(parse(&offset, Path::new("d.bvh"), &opts).unwrap().joints(), 3);
}

fn bandai2() -> PathBuf {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/bandai2");
    assert!(dir.is_dir(), "{} does not exist: this test needs the bandai2 dataset", dir.display());
    dir
}

/// The `Frames:` value of a gzip-compressed BVH file, read independently of the parser.
fn declared_frames(path: &Path) -> usize {
    let mut text = String::new();
    flate2::read::MultiGzDecoder::new(std::fs::File::open(path).unwrap()).read_to_string(&mut text).unwrap();
    let line = text.lines().find(|l| l.trim_start().starts_with("Frames:")).unwrap();
    line.trim_start()["Frames:".len()..].trim().parse().unwrap()
}

#[test]
#[ignore = "needs ../shared/data/bandai2 (CI runs it with --ignored when present)"]
fn bandai2_clips_read_and_round_trip() {
    let dir = bandai2();
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.to_string_lossy().ends_with(".bvh.gz"))
        .collect();
    files.sort();
    assert_eq!(files.len(), 962);
    let tmp = tempfile::tempdir().unwrap();
    for (i, path) in files.iter().enumerate().step_by(97) {
        let raw = read_file(path, &ReadOptions::default()).unwrap();
        assert_eq!(raw.joints(), 22);
        assert_eq!(raw.skeleton.names[0], "joint_Root");
        assert_eq!(raw.frames(), declared_frames(path), "{}", path.display());
        assert!((raw.fps() - 30.0).abs() < 1e-3);
        let clip = read_file(path, &ReadOptions { drop_dummy_root: true }).unwrap();
        assert_eq!(clip.joints(), 21);
        assert_eq!(clip.skeleton.names[0], "Hips");
        assert_eq!(clip.skeleton.parents[0], None);
        assert_eq!(clip.frames(), raw.frames());
        assert!(clip.skeleton.channels.iter().all(|c| c.position && c.order == EulerOrder::Zxy));
        clip.skeleton.validate().unwrap();
        assert_round_trip(&clip);
        if i == 0 {
            let out = tmp.path().join("clip.bvh.gz");
            write_file(&clip, &out).unwrap();
            let back = read_file(&out, &ReadOptions::default()).unwrap();
            let (rot, pos) = clip_error(&clip, &back);
            assert!(rot <= 1e-4 && pos <= 1e-4, "{rot} {pos}");
        }
    }
}

#[test]
fn writer_keeps_joint_names_single_tokens() {
    let mut clip = read(THREE_CHANNEL);
    clip.skeleton.names[1] = "Left Thigh".into();
    let back = round_trip(&clip);
    assert_eq!(back.skeleton.names, ["Hips", "Left_Thigh", "Shin"]);
}

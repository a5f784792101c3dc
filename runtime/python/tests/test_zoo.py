"""The `zoo` package against the Rust runtime it wraps: every task on the same inputs as
`tests/python.rs` gave the runtime (its outputs in `reference.json`), the package's own
conveniences, BVH read/write, and the errors (each bad input a named test with its message)."""

import os
import zipfile
from pathlib import Path

import numpy as np
import pytest

import zoo
from conftest import arr

K = 21  # the synthetic skeleton's joints


def max_diff(a, b):
    return float(np.max(np.abs(np.asarray(a, np.float64) - np.asarray(b, np.float64))))


def quat_diff(a, b):
    """Largest difference of unit quaternions up to sign."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    s = np.sign(np.sum(a * b, axis=-1, keepdims=True))
    s[s == 0] = 1
    return float(np.max(np.abs(a - s * b)))


# --- loading -----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "name, cls, task, kind, fps",
    [
        ("transition.onnx", zoo.TransitionModel, "transition", "rtn", 30),
        ("keyframes.onnx", zoo.KeyframeModel, "keyframes", "arnn", 30),
        ("keyframes_lamp.onnx", zoo.KeyframeModel, "keyframes", "arnn", 50),
        ("stitch.onnx", zoo.StitchModel, "stitch", "rmr", 30),
        ("synthesis.onnx", zoo.SynthesisModel, "synthesis", "rnn-gmm", 30),
    ],
)
def test_load_returns_the_type_of_the_task(data, name, cls, task, kind, fps):
    m = zoo.load(data / name)
    assert type(m) is cls and m.task == task and m.kind == kind
    assert m.format_version == zoo.FORMAT_VERSION == 5
    assert m.frame == zoo.CoordinateFrame(0.01, "y", "right")
    assert m.fps == fps
    sk = m.skeleton
    assert sk.parents.dtype == np.int32 and sk.parents[0] == -1
    assert sk.offsets.shape == (len(sk), 3) and sk.offsets.dtype == np.float32
    assert kind in repr(m)


def test_the_skeleton_is_the_clips(data, clip):
    m = zoo.load(data / "transition.onnx")
    assert m.skeleton.names == clip.names
    assert np.array_equal(m.skeleton.parents, clip.parents)
    assert max_diff(m.skeleton.offsets, clip.offsets) < 1e-5


# --- transition --------------------------------------------------------------------------------


def test_transition_poses_match_the_runtime(data, ref, clip):
    m = zoo.load(data / "transition.onnx")
    r = ref["transition"]
    a, b = r["past"]
    t, n = r["target"], r["next"]
    h, q = clip.hips, clip.rotations
    out = m.transition((h[a:b], q[a:b]), (h[t], q[t]), (h[n], q[n]))
    assert out.shape == (31,)
    assert out.global_positions.shape == (31, K, 3) and out.local_rotations.shape == (31, K, 4)
    assert all(isinstance(getattr(out, f), np.ndarray) for f in zoo._POSE_FIELDS)
    # The same inputs as the runtime's (the clip's frames as float32, rotations normalised): the
    # same outputs.
    assert max_diff(out.global_positions, arr(r["global_positions"], 31, K, 3)) == 0.0
    assert max_diff(out.hips, arr(r["hips"], 31, 3)) == 0.0
    assert max_diff(out.rotations, arr(r["rotations"], 31, K, 4)) == 0.0
    # The same frames as zoo.Poses (their rotations normalised once more): the same up to rounding.
    p = clip.poses()
    again = m.transition(p[a:b], p[t], p[n])
    assert max_diff(again.global_positions, out.global_positions) < 1e-3
    # The last frame is the target.
    assert max_diff(out.global_positions[-1], p.global_positions[t]) < 0.05


def test_transition_positions_match_the_runtime(data, ref, clip):
    m = zoo.load(data / "transition.onnx")
    r = ref["transition"]
    out = m.transition_positions(
        arr(r["past_positions"], 10, K, 3), arr(r["target_positions"], K, 3), arr(r["next_positions"], K, 3)
    )
    assert out.shape == (31, K, 3) and out.dtype == np.float32
    # The same input bits as the runtime got: the same output bits.
    assert max_diff(out, arr(r["positions"], 31, K, 3)) == 0.0
    # The clip's own positions (forward kinematics in float32 here, float64 there): the same
    # transition up to float rounding.
    g = clip.poses().global_positions
    a, b = r["past"]
    near = m.transition_positions(g[a:b], g[r["target"]], g[r["next"]])
    assert max_diff(near, out) < 1e-2


def test_a_batch_of_transitions_is_each_transition(data, clip):
    m = zoo.load(data / "transition.onnx")
    p = clip.poses()
    one = m.transition(p[20:30], p[60], p[61])
    two = m.transition(p[40:50], p[80], p[81])
    both = m.transition(
        zoo.Poses.concatenate([p[None, 20:30], p[None, 40:50]]),
        zoo.Poses.concatenate([p[None, 60], p[None, 80]]),
        zoo.Poses.concatenate([p[None, 61], p[None, 81]]),
    )
    assert both.shape == (2, 31)
    assert max_diff(both.global_positions[0], one.global_positions) < 1e-2
    assert max_diff(both.global_positions[1], two.global_positions) < 1e-2


def test_transition_length_and_the_trained_limit(data, clip):
    m = zoo.load(data / "transition.onnx")
    p = clip.poses()
    assert m.past_frames == 10 and m.transition_frames == 30
    assert m.transition(p[20:30], p[50], p[51], frames=20).shape == (21,)
    with pytest.raises(zoo.MotionError) as e:
        m.transition(p[20:30], p[80], p[81], frames=50)
    assert e.value.kind == "BeyondTrainedLength"
    assert "longer than the 30 frames" in str(e.value) and "allow_beyond_trained" in str(e.value)
    assert m.transition(p[20:30], p[80], p[81], frames=50, allow_beyond_trained=True).shape == (51,)


def lifted_target(clip):
    """Positions of frames 20..30, and frame 60 (and 61) lifted 1 m: a target the network misses."""
    g = clip.poses().global_positions
    up = np.array([0.0, 100.0, 0.0], np.float32)
    return g[20:30], g[60] + up, g[61] + up


def test_positions_apply_the_calibrated_fallback_by_default(data, clip):
    m = zoo.load(data / "transition_fallback.onnx")
    past, target, nxt = lifted_target(clip)
    default = m.transition_positions(past, target, nxt)
    on = m.transition_positions(past, target, nxt, fallback=True)
    off = m.transition_positions(past, target, nxt, fallback=False)
    # `zoo transition`'s default: the fallback on.
    assert max_diff(default, on) == 0.0
    # Missing a target lifted a metre, the fallback moves the frames (centimetres).
    assert max_diff(on, off) > 1.0


def test_transition_settings_do_not_carry_over_between_calls(data, clip):
    m = zoo.load(data / "transition_fallback.onnx")
    past, target, nxt = lifted_target(clip)
    off = m.transition_positions(past, target, nxt, fallback=False)
    plain = m.transition_positions(past, target, nxt, fallback=False, foot_lock=False)
    m.transition_positions(past, target, nxt, fallback=True, foot_lock=True)
    assert max_diff(m.transition_positions(past, target, nxt, fallback=False), off) == 0.0
    assert max_diff(plain, off) == 0.0
    # A longer transition allowed once is not allowed on the next call.
    p = clip.poses()
    m.transition(p[20:30], p[80], p[81], frames=50, allow_beyond_trained=True)
    with pytest.raises(zoo.MotionError):
        m.transition(p[20:30], p[80], p[81], frames=50)


def test_posed_transitions_apply_the_fallback_and_foot_lock_as_the_cli(data, ref, clip):
    m = zoo.load(data / "transition_fallback.onnx")
    r = ref["transition_locked"]
    h, q = clip.hips, clip.rotations
    args = ((h[20:30], q[20:30]), (h[60], q[60]), (h[61], q[61]))
    # The runtime's whole posed transition (`zoo transition --in-place --foot-lock`): the same bits.
    locked = m.transition(*args, foot_lock=True)
    assert r["fallback_weight"] > 0.0
    assert max_diff(locked.global_positions, arr(r["global_positions"], 31, K, 3)) == 0.0
    assert max_diff(locked.hips, arr(r["hips"], 31, 3)) == 0.0
    assert max_diff(locked.rotations, arr(r["rotations"], 31, K, 4)) == 0.0
    # The fallback is on by default, as in `zoo transition`, and a setting holds for one call.
    default = m.transition(*args)
    off = m.transition(*args, fallback=False)
    assert max_diff(default.global_positions, m.transition(*args, fallback=True).global_positions) == 0.0
    assert max_diff(default.global_positions, off.global_positions) > 1.0
    assert max_diff(m.transition(*args).global_positions, default.global_positions) == 0.0


def test_load_bytes_gives_the_files_outputs_bit_for_bit(data, clip):
    path = data / "transition_fallback.onnx"
    a = zoo.load(path)
    b = zoo.load_bytes(path.read_bytes())
    assert type(b) is zoo.TransitionModel and b.path == "<bytes>"
    assert b.skeleton.names == a.skeleton.names and b.fps == a.fps
    past, target, nxt = lifted_target(clip)
    assert np.array_equal(a.transition_positions(past, target, nxt), b.transition_positions(past, target, nxt))
    p = clip.poses()
    ta, tb = a.transition(p[20:30], p[60], p[61]), b.transition(p[20:30], p[60], p[61])
    for f in zoo._POSE_FIELDS:
        assert np.array_equal(getattr(ta, f), getattr(tb, f)), f
    s = zoo.load_bytes((data / "stitch.onnx").read_bytes())
    assert type(s) is zoo.StitchModel
    with pytest.raises(zoo.ModelFileError, match="zoo export"):
        zoo.load_bytes(b"HIERARCHY\nROOT Hips\n")
    with pytest.raises(TypeError, match="zoo.load"):
        zoo.load_bytes(str(path))


def test_clip_resample_keeps_the_duration_and_the_frames_it_lands_on(clip):
    assert clip.resample(clip.fps * (1 + 1e-6)) is clip
    half = clip.resample(clip.fps / 2)
    assert half.fps == pytest.approx(clip.fps / 2)
    assert half.frames == (clip.frames - 1) // 2 + 1
    # Every other frame of the clip, exactly where the new frames land on the old ones.
    assert max_diff(half.positions, clip.positions[::2][: half.frames]) < 1e-9
    assert quat_diff(half.rotations, clip.rotations[::2][: half.frames]) < 1e-9
    up = clip.resample(clip.fps * 2)
    assert up.frames == 2 * (clip.frames - 1) + 1
    mid = up.positions[1]
    assert max_diff(mid, (clip.positions[0] + clip.positions[1]) / 2) < 1e-9


def test_clip_resample_is_zoo_data_resample(clip, ref):
    # `tests/python.rs` wrote the clip resampled to 24 fps by `zoo_motion::Clip::resampled`, the
    # code of `zoo data resample`: the package calls the same code, bit for bit.
    want = ref["resample"]
    got = clip.resample(want["fps"])
    assert got.frames == want["frames"] == 192
    assert np.array_equal(got.rotations.ravel(), np.array(want["rotations"]))
    assert np.array_equal(got.positions.ravel(), np.array(want["positions"]))
    # BVH-style poses (a model's input): the same resampling of the hips and the rotations.
    hips, rot = zoo.resample_world(clip.hips, clip.rotations, clip.fps, want["fps"])
    assert hips.dtype == rot.dtype == np.float32 and rot.shape == (192, K, 4)
    assert np.array_equal(hips, got.positions[:, 0].astype(np.float32))
    assert np.array_equal(rot, got.rotations.astype(np.float32))
    back_h, back_r = zoo.resample_world(hips, rot, want["fps"], clip.fps)
    assert back_h.shape == (239, 3)  # 191 frames at 24 fps span 7.958 s: 239 frames at 30 fps
    with pytest.raises(zoo.ShapeError, match="resample_world takes hips"):
        zoo.resample_world(clip.hips, clip.rotations[:-1], 30, 24)


def test_a_clip_at_another_rate_is_refused_naming_the_fix(data, clip):
    m = zoo.load(data / "transition.onnx")
    m.check_fps(30.000030000029998)
    with pytest.raises(zoo.ShapeError, match=r"24 fps but the model was trained at 30 fps: resample it first \(`zoo.Clip.resample\(30\)`\)"):
        m.check_fps(24)


# --- keyframes ---------------------------------------------------------------------------------


def test_lamp_completion_matches_the_runtime(data, ref):
    m = zoo.load(data / "keyframes_lamp.onnx")
    r = ref["keyframes_lamp"]
    assert m.dofs == 6 and m.groups == 0 and not m.humanoid
    out = m.complete(r["frames"], arr(r["poses"], 3, 6))
    assert out.shape == (25, 6)
    assert max_diff(out, arr(r["completed"], 25, 6)) < 1e-5
    # Frames relative to the first key.
    assert max_diff(m.complete(np.array(r["frames"]) + 100, arr(r["poses"], 3, 6)), out) == 0.0


def test_humanoid_completion_matches_candle(data, ref, clip):
    """`complete_poses` (the runtime, with the canonical frame done in the package) against
    `zoo_arnn::humanoid::complete_clip` (candle): the same keys give the same motion."""
    m = zoo.load(data / "keyframes.onnx")
    r = ref["keyframes"]
    assert m.humanoid and m.groups == 1 + K
    p = clip.poses()
    hips, rot = m.complete_poses(r["frames"], p[r["source_frames"]])
    assert hips.shape == (31, 3) and rot.shape == (31, K, 4)
    # candle and tract round differently (relative 1e-6 over the sequence); the untrained model
    # walks the root hundreds of metres away, hence the relative tolerance.
    assert np.allclose(hips, arr(r["hips"], 31, 3), rtol=1e-5, atol=1e-2)
    assert quat_diff(rot, arr(r["rotations"], 31, K, 4)) < 1e-3


def test_a_lamp_model_refuses_humanoid_keys(data, clip):
    m = zoo.load(data / "keyframes_lamp.onnx")
    with pytest.raises(zoo.ShapeError, match="not the humanoid poses"):
        m.complete_poses([0, 10], clip.poses()[[0, 10]])


def test_bad_keys_are_refused_with_the_runtime_message(data):
    m = zoo.load(data / "keyframes_lamp.onnx")
    with pytest.raises(zoo.MotionError) as e:
        m.complete([0], np.zeros((1, 6)))
    assert e.value.kind == "Keys" and "at least 2" in str(e.value)
    with pytest.raises(zoo.ShapeError, match="strictly increase"):
        m.complete([0, 5, 5], np.zeros((3, 6)))


# --- stitch ------------------------------------------------------------------------------------


def test_stitch_matches_the_runtime_and_zoo_datas_alignment(data, ref, clip):
    m = zoo.load(data / "stitch.onnx")
    r = ref["stitch"]
    other = zoo.read_bvh(data / "clip2.bvh")
    a, b = clip.poses()[slice(*r["a"])], other.poses()[slice(*r["b"])]
    hips, rot, starts = m.align([a, b])
    t = len(hips)
    assert starts == r["starts"] == [0, 45] and t == 95
    assert max_diff(hips, arr(r["aligned_hips"], t, 3)) < 1e-3
    assert quat_diff(rot, arr(r["aligned_rotations"], t, K, 4)) < 1e-5
    assert m.pre_blend is False  # the fixture refines the raw concatenation: `stitch` gives no seams
    poses, contacts, starts = m.stitch([a, b])
    assert poses.shape == (t,) and contacts.shape == (t, 4) and contacts.dtype == bool
    assert max_diff(poses.hips, arr(r["hips"], t, 3)) < 1e-2
    assert quat_diff(poses.rotations, arr(r["rotations"], t, K, 4)) < 1e-3
    assert np.array_equal(contacts, np.asarray(r["contacts"]).reshape(t, 4))
    # The seam inertialized first (`zoo stitch --pre-blend`): the runtime's figures, not the plain ones.
    blended, _, _ = m.stitch([a, b], pre_blend=True)
    assert max_diff(blended.hips, arr(r["pre_blend_hips"], t, 3)) < 1e-2
    assert quat_diff(blended.rotations, arr(r["pre_blend_rotations"], t, K, 4)) < 1e-3
    assert quat_diff(blended.rotations, poses.rotations) > 1e-3
    with pytest.raises(zoo.MotionError, match="seam at frame 95"):
        m.refine_poses((hips, rot), seams=[95])


def test_stitch_stream_gives_the_whole_sequence(data, ref, clip):
    m = zoo.load(data / "stitch.onnx")
    r = ref["stitch"]
    other = zoo.read_bvh(data / "clip2.bvh")
    a, b = clip.poses()[slice(*r["a"])], other.poses()[slice(*r["b"])]
    hips, rot, starts = m.align([a, b])
    t = len(hips)
    whole, whole_contacts = m.refine_poses((hips, rot), seams=starts[1:])
    for cleanup in [True, False]:
        s = m.stream(place_ankles=cleanup, lock_feet=cleanup, seam_guard=cleanup, refine_everywhere=not cleanup)
        # The window, spread over the `stride - 1` pushes after it, then the lookahead of the
        # guard, the lock and the seams' reach and the frames they release at once.
        spread = m.window + m.stride - 1
        assert s.latency == (spread + 89 if cleanup else spread)
        got, contacts = [], []
        for f in range(t):
            if f in starts[1:]:
                s.mark_seam()
            s.push((hips[f : f + 1], rot[f : f + 1]))
            p, c = s.pop()
            assert len(p) == (1 if f >= s.latency else 0)
            got.append(p)
            contacts.append(c)
        s.finish()
        p, c = s.pop()
        got.append(p)
        contacts.append(c)
        hips_out = np.concatenate([g.hips for g in got])
        assert hips_out.shape == (t, 3) and s.popped == t
        if cleanup:
            assert max_diff(hips_out, whole.hips) < 1e-3
            assert np.array_equal(np.concatenate(contacts), whole_contacts)


def test_stitch_keeps_the_clips_away_from_their_seams_by_default(data, ref, clip):
    m = zoo.load(data / "stitch.onnx")
    r = ref["stitch"]
    other = zoo.read_bvh(data / "clip2.bvh")
    a, b = clip.poses()[slice(*r["a"])], other.poses()[slice(*r["b"])]
    hips, rot, starts = m.align([a, b])
    seams = starts[1:]
    kept, _ = m.refine_poses((hips, rot), seams=seams, seam_reach=12)
    everywhere, _ = m.refine_poses((hips, rot), seams=seams, refine_everywhere=True)
    far = [f for f in range(len(hips)) if min(abs(f - s) if f >= s else s - 1 - f for s in seams) >= 12]
    assert far, "frames 12 or more from the seam"
    assert max_diff(kept.hips[far], hips[far]) < 1e-4
    assert max_diff(everywhere.hips[far], hips[far]) > 1e-3
    # The default is the model's window, and nothing sticks between calls.
    default, _ = m.refine_poses((hips, rot), seams=seams)
    window, _ = m.refine_poses((hips, rot), seams=seams, seam_reach=m.window)
    assert max_diff(default.hips, window.hips) == 0.0
    with pytest.raises(ValueError, match="contradict"):
        m.refine_poses((hips, rot), seams=seams, seam_reach=5, refine_everywhere=True)
    with pytest.raises(ValueError, match="at least 1"):
        m.refine_poses((hips, rot), seams=seams, seam_reach=0)


def test_stitch_refuses_short_clips(data, clip):
    m = zoo.load(data / "stitch.onnx")
    p = clip.poses()
    with pytest.raises(zoo.ShapeError, match="at least 10 per clip"):
        m.stitch([p[0:40], p[50:55]])
    with pytest.raises(zoo.MotionError):
        m.refine_poses(p[0:12])  # shorter than the window


# --- synthesis and control ---------------------------------------------------------------------


def test_synthesis_matches_the_runtime(data, ref):
    m = zoo.load(data / "synthesis.onnx")
    r = ref["synthesis"]
    poses, contacts = m.generate(r["frames"], seeds=r["seeds"])
    assert poses.shape == (2, 20) and contacts.shape == (2, 20, 2)
    for c in range(2):
        assert max_diff(poses.hips[c], arr(r["hips"][c], 20, 3)) < 1e-3
        assert quat_diff(poses.rotations[c], arr(r["rotations"][c], 20, K, 4)) < 1e-4
    # A character's motion depends on its seed only.
    alone, _ = m.generate(20, seeds=2)
    assert max_diff(alone.hips, poses.hips[1]) == 0.0


def test_control_matches_the_runtime(data, ref):
    m = zoo.load(data / "synthesis.onnx")
    r = ref["synthesis"]["control"]
    ctl = m.controller(seeds=[r["seed"]])
    ctl.start(placements=[r["placement"]])
    hips, rot = [], []
    for _ in range(12):
        p, c = ctl.step(r["speed"], r["heading"])
        assert p.shape == (1,) and c.shape == (1, 2)
        hips.append(p.hips[0])
        rot.append(p.rotations[0])
    assert max_diff(hips, arr(r["hips"], 12, 3)) < 1e-3
    assert quat_diff(rot, arr(r["rotations"], 12, K, 4)) < 1e-4
    assert ctl.placements.shape == (1, 3)


def test_control_refuses_a_negative_speed(data):
    m = zoo.load(data / "synthesis.onnx")
    ctl = m.controller(seeds=[1, 2])
    ctl.start()
    with pytest.raises(zoo.MotionError) as e:
        ctl.step([100.0, -5.0], 0.0)
    assert e.value.kind == "Control" and "speed >= 0" in str(e.value)


def test_path_following_matches_the_runtime(data, ref):
    m = zoo.load(data / "synthesis.onnx")
    r = ref["synthesis"]["follow"]
    poses, contacts, reached = m.follow_path(r["points"], r["speed"], seed=r["seed"], max_frames=r["max_frames"])
    n = r["frames"]
    assert poses.shape == (n,) and contacts.shape == (n, 2) and reached == r["reached_end"]
    assert max_diff(poses.hips, arr(r["hips"], n, 3)) < 1e-3
    assert quat_diff(poses.rotations, arr(r["rotations"], n, K, 4)) < 1e-4


def test_a_trained_generator_follows_a_bend_to_its_end(data):
    """The generator trained in the test along the benchmark's `corner` path (docs/paths): to the
    end, close to the curve, and the same frames for the same seed."""
    m = zoo.load(data / "synthesis_trained.onnx")
    corner = np.array([[0, 0], [3, 118], [-4, 251], [2, 379], [0, 500], [88, 451.5], [183.2, 394.5], [261.8, 350], [346.4, 300]])
    poses, _, reached = m.follow_path(corner, seed=1)
    d = m.path_distances(corner, poses.root_position[:, [0, 2]])
    assert reached, f"stopped after {len(d)} frames"
    assert d.mean() < 3.0 and d.max() < 15.0, (d.mean(), d.max())
    assert np.linalg.norm(poses.root_position[-1, [0, 2]] - corner[-1]) < 50
    again, _, _ = m.follow_path(corner, seed=1)
    assert np.array_equal(again.hips, poses.hips)


def test_a_path_of_one_point_is_refused(data):
    m = zoo.load(data / "synthesis.onnx")
    with pytest.raises(zoo.MotionError) as e:
        m.follow_path([[0.0, 0.0], [0.0, 0.0]], 100.0)
    assert e.value.kind == "Control" and "a path needs at least 2" in str(e.value)
    with pytest.raises(ValueError, match="max_frames is 0"):
        m.follow_path([[0.0, 0.0], [0.0, 100.0]], 100.0, max_frames=0)


def test_encode_matches_zoo_rnngmm(data, ref):
    m = zoo.load(data / "synthesis.onnx")
    r = ref["synthesis"]["encode"]
    d = m.frame_dim
    feats, placements = m.encode((arr(r["hips"], 10, 3), arr(r["rotations"], 10, K, 4)), arr(r["contacts"], 10, 2))
    assert feats.shape == (10, d) and placements.shape == (10, 3)
    assert max_diff(feats, arr(r["features"], 10, d)) < 1e-4
    # Started from its encoded frames, a character continues from the clip's last placement.
    ctl = m.controller(seeds=[3])
    ctl.start(feats[None], placements[-1:])
    assert max_diff(ctl.placements, placements[-1:]) < 1e-5


# --- poses and frames --------------------------------------------------------------------------


def test_poses_from_world_are_the_clips_frames(clip):
    p = clip.poses()
    assert p.shape == (clip.frames,)
    # The BVH-style fields are the arrays given (float32, rotations normalised).
    assert np.array_equal(p.hips, clip.hips.astype(np.float32))
    r32 = clip.rotations.astype(np.float32)
    assert max_diff(p.rotations, r32 / np.linalg.norm(r32, axis=-1, keepdims=True)) < 1e-7
    # Global positions: forward kinematics over the skeleton; the hips on the ground project.
    assert max_diff(p.global_positions[:, 0], clip.hips) < 1e-4
    assert np.all(p.root_position[:, 1] == 0.0)
    # Root deltas integrate to the root positions.
    yaw = np.arctan2(p.root_rotation[:, 1], p.root_rotation[:, 3]) * 2
    c, s = np.cos(yaw[:-1]), np.sin(yaw[:-1])
    d = p.root_delta_position[1:]
    step = np.stack([c * d[:, 0] + s * d[:, 2], np.zeros(len(d)), -s * d[:, 0] + c * d[:, 2]], -1)
    assert max_diff(p.root_position[:-1] + step, p.root_position[1:]) < 1e-3


def test_conversion_to_blender_and_back(clip):
    p = clip.poses()[:5]
    b = p.convert(zoo.ZOO_CM, zoo.BLENDER)
    # Blender: metres, Z up, right-handed: (x, y, z) cm -> (x, -z, y) / 100.
    g = p.global_positions
    assert max_diff(b.global_positions, np.stack([g[..., 0], -g[..., 2], g[..., 1]], -1) / 100) < 1e-6
    back = b.convert(zoo.BLENDER, zoo.ZOO_CM)
    assert max_diff(back.global_positions, g) < 1e-4
    assert quat_diff(back.local_rotations, p.local_rotations) < 1e-6
    assert max_diff(zoo.convert_positions(g, zoo.ZOO_CM, zoo.BLENDER), b.global_positions) < 1e-6


# --- BVH ---------------------------------------------------------------------------------------


def test_bvh_round_trip(tmp_path, clip):
    assert clip.frames == 240 and len(clip.names) == K and clip.fps == pytest.approx(30.0)
    assert clip.rotations.shape == (240, K, 4) and clip.rotations.dtype == np.float64
    out = tmp_path / "out.bvh.gz"
    zoo.write_bvh(out, clip)
    back = zoo.read_bvh(out)
    assert back.names == clip.names and back.euler_orders == clip.euler_orders
    assert max_diff(back.positions, clip.positions) < 1e-5
    assert quat_diff(back.rotations, clip.rotations) < 1e-7


def test_a_bad_bvh_names_its_line(tmp_path):
    f = tmp_path / "bad.bvh"
    f.write_text("HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0\n}\n")
    with pytest.raises(zoo.BvhError, match=r"bad\.bvh:\d+: "):
        zoo.read_bvh(f)
    with pytest.raises(zoo.BvhError, match="cannot read"):
        zoo.read_bvh(tmp_path / "missing.bvh")


def test_clip_poses_on_a_model_skeleton(data, clip):
    m = zoo.load(data / "transition.onnx")
    p = clip.poses(m.skeleton.names)
    assert max_diff(p.global_positions, clip.poses().global_positions) < 1e-4
    with pytest.raises(zoo.ShapeError, match="no joint named Tail"):
        clip.poses(m.skeleton.names + ["Tail"])


# --- errors ------------------------------------------------------------------------------------


def test_a_missing_file_is_a_model_file_error(tmp_path):
    with pytest.raises(zoo.ModelFileError) as e:
        zoo.load(tmp_path / "none.onnx")
    assert "cannot read model file" in str(e.value) and e.value.kind == "Io"
    assert isinstance(e.value, zoo.MotionError) and isinstance(e.value, zoo.ZooError)


def test_a_file_that_is_not_a_model_says_how_to_make_one(tmp_path):
    f = tmp_path / "clip.onnx"
    f.write_text("HIERARCHY\nROOT Hips\n")
    with pytest.raises(zoo.ModelFileError, match="zoo export"):
        zoo.load(f)


def test_wrong_shapes_are_shape_errors(data, clip):
    m = zoo.load(data / "transition.onnx")
    p = clip.poses()
    with pytest.raises(zoo.ShapeError, match=r"`past_rotations` must have shape \(N=1, P=10, K=21, 4\), found \(1, 10, 20, 4\)"):
        m.transition((p.hips[0:10], p.rotations[0:10, :20]), p[60], p[61])
    with pytest.raises(zoo.ShapeError, match="zero quaternion"):
        m.transition((p.hips[0:10], np.zeros((10, K, 4))), p[60], p[61])
    with pytest.raises(zoo.ShapeError, match="must be zoo.Poses"):
        m.transition("walk", p[60], p[61])


def test_a_nan_is_a_non_finite_error_not_a_shape_error(data, clip):
    m = zoo.load(data / "transition.onnx")
    p = clip.poses()
    with pytest.raises(zoo.NonFiniteError, match=r"`past` holds NaN at flat index 0; every value must be finite"):
        m.transition_positions(np.full((10, K, 3), np.nan), np.zeros((K, 3)), np.zeros((K, 3)))
    h = p.hips[20:30].copy()
    h[3, 1] = np.inf
    with pytest.raises(zoo.NonFiniteError) as e:
        m.transition((h, p.rotations[20:30]), p[60], p[61])
    assert not isinstance(e.value, zoo.ShapeError) and isinstance(e.value, zoo.ZooError)


def test_a_model_of_another_task_is_a_wrong_task_error(data, clip):
    stitch = zoo.load(data / "stitch.onnx")
    p = clip.poses()
    with pytest.raises(zoo.WrongTaskError, match=r"`transition` is a method of transition models, but .*stitch.onnx is a stitch model \(rmr\)"):
        stitch.transition(p[20:30], p[60], p[61])
    with pytest.raises(zoo.WrongTaskError, match="keyframes models"):
        zoo.load(data / "transition.onnx").complete_poses([0, 10], p[[0, 10]])
    # Not a method of any task: the usual AttributeError.
    with pytest.raises(AttributeError):
        stitch.no_such_thing


def test_a_run_folder_is_answered_with_the_export_command(tmp_path):
    run = tmp_path / "rtn_run"
    run.mkdir()
    with pytest.raises(zoo.ModelFileError) as e:
        zoo.load(run)
    assert f"zoo export --onnx {run} --out model.onnx" in str(e.value)


# --- the package itself ------------------------------------------------------------------------


def test_the_stubs_name_what_the_module_has():
    """Every public name of `_native.pyi` exists in the module, and the other way round."""
    import ast

    stub = ast.parse((Path(zoo.__file__).parent / "_native.pyi").read_text())
    names = {n.name for n in stub.body if isinstance(n, (ast.FunctionDef, ast.ClassDef))}
    names |= {t.id for n in stub.body if isinstance(n, ast.AnnAssign) for t in [n.target]}
    names -= {"F32", "PoseDict", "Frame"}
    have = {n for n in dir(zoo._native) if not n.startswith("_")} | {"__version__"}
    assert names - have == set(), f"stubbed but missing: {names - have}"
    assert have - names - {"__version__"} == set(), f"not stubbed: {have - names}"
    assert (Path(zoo.__file__).parent / "py.typed").exists()


def test_the_wheel_depends_on_numpy_only():
    wheel = os.environ.get("ZOO_TEST_WHEEL")
    if not wheel:
        pytest.skip("ZOO_TEST_WHEEL is not set (tests/python.rs sets it)")
    with zipfile.ZipFile(wheel) as z:
        meta = next(n for n in z.namelist() if n.endswith(".dist-info/METADATA"))
        text = z.read(meta).decode()
        wheel_tags = z.read(meta.replace("METADATA", "WHEEL")).decode()
    requires = [line.split(":", 1)[1].strip() for line in text.splitlines() if line.startswith("Requires-Dist:")]
    assert requires == ["numpy>=1.17"], requires
    assert "Requires-Python: >=3.9" in text
    assert "cp39-abi3" in wheel_tags

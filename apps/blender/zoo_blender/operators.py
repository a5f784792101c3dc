"""The add-on's operators: check the bones, in-between, stitch, walk along a curve.

Every operator checks everything and computes its result before it changes anything: a
refusal (a `Refusal`, or an error of the runtime) is reported in the status bar and leaves the
file as it was. Each one that changes the file is one undo step.
"""

import math
import time

import bpy
import numpy as np

from . import rig as rigmod
from . import walk as walkmod
from .runtime import Refusal, model_of_task, zoo


def settings(context):
    return context.scene.zoo


def active_armature(context):
    ob = context.active_object
    if ob is None or ob.type != "ARMATURE":
        raise Refusal("select an armature: the active object is not one")
    return ob


def bone_map(s):
    """The bone map of the panel: the shipped one chosen (Mixamo, Rigify), then the JSON file's
    entries over it."""
    m = {} if s.bone_names == "MODEL" else rigmod.shipped_map(s.bone_names.lower())
    m.update(rigmod.read_bone_map(s.bone_map))
    return m


def matched_rig(context, model):
    s = settings(context)
    return rigmod.Rig(active_armature(context), model, bone_map(s))


def scene_fps(scene):
    return scene.render.fps / scene.render.fps_base


def check_frame_rate(context, model, operation):
    """Refuses a scene whose frame rate differs from the model's by more than 0.01 % (a BVH frame
    time is stored rounded: 30.00003 fps is 30), naming the fix."""
    fps = scene_fps(context.scene)
    if abs(fps - model.fps) > 1e-4 * model.fps:
        raise Refusal(
            f"{operation}: the scene runs at {fps:g} fps but the model was trained at {model.fps:g} fps: set the scene's "
            f"frame rate to {model.fps:g} fps (Output Properties > Format > Frame Rate; the action's keys stay on their "
            "frames), or use a model trained at the scene's rate"
        )


class Progress:
    """The window manager's progress indicator (the cursor's counter)."""

    def __init__(self, context, total):
        self.wm = context.window_manager
        self.total = max(int(total), 1)
        self.wm.progress_begin(0, self.total)

    def __call__(self, done, total=None):
        self.wm.progress_update(min(int(done), self.total))

    def end(self):
        self.wm.progress_end()


def run_refusable(op, context, body):
    """Runs `body()`; a refusal is reported as an error and cancels the operator."""
    try:
        return body()
    except Refusal as e:
        op.report({"ERROR"}, f"zoo: {e}")
        return {"CANCELLED"}
    except Exception as e:  # the runtime's errors (zoo.ZooError) and anything unexpected
        z = zoo()
        if isinstance(e, z.ZooError):
            op.report({"ERROR"}, f"zoo: {e}")
            return {"CANCELLED"}
        raise


def action_frames(action):
    """The integer frames an action spans."""
    a, b = action.frame_range
    return list(range(int(math.floor(a + 1e-6)), int(math.floor(b + 1e-6)) + 1))


def selected_markers(scene):
    """Frames of the selected timeline markers."""
    return sorted(m.frame for m in scene.timeline_markers if m.select)


def selected_key_frames(action, rig):
    """Frames holding a selected key on a matched bone's channels."""
    frames = set()
    prefixes = tuple(f'pose.bones["{bpy.utils.escape_identifier(b)}"]' for b in rig.bones)
    for fc in action.fcurves:
        if not fc.data_path.startswith(prefixes):
            continue
        n = len(fc.keyframe_points)
        if n == 0:
            continue
        sel = np.zeros(n, dtype=bool)
        fc.keyframe_points.foreach_get("select_control_point", sel)
        if sel.any():
            co = np.empty(2 * n, dtype=np.float32)
            fc.keyframe_points.foreach_get("co", co)
            frames.update(int(round(float(x))) for x in co[0::2][sel])
    return frames


def pinned_bones(s):
    """The bones named in the panel's Pinned bones (comma-separated)."""
    return [b.strip() for b in s.pinned_bones.split(",") if b.strip()]


def pinned_flags(s, rig, keys, start, end):
    """The keyframe model's `fixed` flags `(n, 1 + K)` for `keys`: with pinned bones, the keys
    strictly inside the range fix only those bones' rotations (and the root's position when the
    root bone is pinned), the two ends fix everything; without, every key fixes everything
    (`None`)."""
    pins = pinned_bones(s)
    if not pins:
        return None
    unknown = [b for b in pins if b not in rig.bones]
    if unknown:
        raise Refusal(
            f"pinned bones {', '.join(unknown)} are not bones matched to the model's joints: fix Pinned bones in the zoo panel"
        )
    flags = np.ones((len(keys), 1 + rig.joints), dtype=np.float32)
    for i, f in enumerate(keys):
        if start < f < end:
            flags[i] = 0.0
            flags[i, 0] = 1.0 if rig.bones[0] in pins else 0.0
            for b in pins:
                flags[i, 1 + rig.bones.index(b)] = 1.0
    return flags


class ZOO_OT_pin_selected(bpy.types.Operator):
    """Pin the selected pose bones: at the keys inside the range a keyframe model keeps only their keyed rotations"""

    bl_idname = "zoo.pin_selected"
    bl_label = "Pin selected bones"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        ob = context.active_object
        if ob is None or ob.type != "ARMATURE":
            self.report({"ERROR"}, "zoo: select an armature: the active object is not one")
            return {"CANCELLED"}
        names = [b.name for b in ob.data.bones if b.select]
        settings(context).pinned_bones = ", ".join(names)
        self.report({"INFO"}, f"zoo: pinned {len(names)} bones" + (f": {', '.join(names)}" if names else " (none: every key fixes every bone)"))
        return {"FINISHED"}


class ZOO_OT_check_bones(bpy.types.Operator):
    """Match the active armature's bones to the model's joints and report what is missing"""

    bl_idname = "zoo.check_bones"
    bl_label = "Check bones"

    def execute(self, context):
        def body():
            model = model_of_task(settings(context).model_path, ("transition", "keyframes", "stitch", "synthesis"), "zoo")
            r = matched_rig(context, model)
            msg = f"zoo: all {r.joints} joints of {model.kind} matched ({r.describe()})"
            w = r.warnings()
            self.report({"WARNING"} if w else {"INFO"}, msg + ("; " + "; ".join(w) if w else ""))
            return {"FINISHED"}

        return run_refusable(self, context, body)


class ZOO_OT_inbetween(bpy.types.Operator):
    """Fill the frames strictly between the ends of the selected range of the active action with the model: a transition model from the frames before the range to its last frame, or a keyframe model from the keys. The ends and every key outside stay as they are"""

    bl_idname = "zoo.inbetween"
    bl_label = "In-between"
    bl_options = {"REGISTER", "UNDO"}

    # SKIP_SAVE: a range given once (by a script) is not remembered for the next call.
    start: bpy.props.IntProperty(
        name="Start", default=-1, options={"SKIP_SAVE"}, description="First frame of the range (-1: the selected keys or the preview range)"
    )
    end: bpy.props.IntProperty(
        name="End", default=-1, options={"SKIP_SAVE"}, description="Last frame of the range (-1: the selected keys or the preview range)"
    )
    allow_longer: bpy.props.BoolProperty(name="Allow longer than trained", default=False)

    def range(self, context, action, rig):
        """The range, by the first rule that gives one: the operator's Start and End, the preview
        range when it is on, two selected markers, the span of the selected keys."""
        if self.start >= 0 and self.end >= 0:
            return self.start, self.end, "given"
        sc = context.scene
        if sc.use_preview_range:
            return sc.frame_preview_start, sc.frame_preview_end, "preview range"
        markers = selected_markers(sc)
        if len(markers) == 2:
            return markers[0], markers[1], "selected markers"
        if len(markers) > 2:
            raise Refusal(f"{len(markers)} markers are selected: select the two at the range's ends")
        sel = selected_key_frames(action, rig)
        if len(sel) >= 2:
            return min(sel), max(sel), "selected keys"
        raise Refusal(
            "no range: set a preview range, select two markers, or select the keys at both ends of the range (Dope "
            "Sheet or Graph Editor)"
        )

    def execute(self, context):
        return run_refusable(self, context, lambda: self.run(context))

    def run(self, context):
        t0 = time.perf_counter()
        s = settings(context)
        model = model_of_task(s.model_path, ("transition", "keyframes"), "In-between")
        check_frame_rate(context, model, "In-between")
        r = matched_rig(context, model)
        ad = r.arm.animation_data
        action = ad.action if ad else None
        if action is None:
            raise Refusal(f"armature '{r.arm.name}' has no active action to in-between")
        start, end, source = self.range(context, action, r)
        if end - start < 2:
            raise Refusal(f"the range {start}-{end} has no frame strictly between its ends")
        first, last = action_frames(action)[0], action_frames(action)[-1]
        if start < first or end > last:
            raise Refusal(f"the range {start}-{end} is outside the action '{action.name}' (frames {first}-{last})")
        inner = list(range(start + 1, end))
        if model.task == "transition":
            p = model.past_frames
            if start - (p - 1) < first:
                raise Refusal(
                    f"In-between needs {p} frames of context up to the range's first frame {start} (frames "
                    f"{start - p + 1} to {start}), but the action '{action.name}' starts at frame {first}: start the range at "
                    f"frame {first + p - 1} or later"
                )
            length = end - start - 1
            if length > model.transition_frames and not self.allow_longer:
                raise Refusal(
                    f"{length} frames between {start} and {end}, but the model was trained for {model.transition_frames}: "
                    "choose a shorter range, or turn on 'Allow longer than trained' (the motion drifts beyond it)"
                )
            nxt = end + 1 if end + 1 <= last else end
            frames = list(range(start - p + 1, start + 1)) + [end, nxt]
            hips, rot = r.sample(action, frames)
            out = model.transition(
                (hips[:p], rot[:p]), (hips[p], rot[p]), (hips[p + 1], rot[p + 1]), frames=length, allow_beyond_trained=self.allow_longer
            )
            new_hips, new_rot = out.hips[:length], out.rotations[:length]
            write_frames = inner
            drop = lambda x: start < x < end  # noqa: E731
        else:
            if not model.humanoid:
                raise Refusal(
                    f"this keyframe model completes {model.dofs} values per pose (the lamp), not an armature: choose a "
                    "keyframe model trained on humanoid motion"
                )
            keys = sorted({start, end} | {f for f in selected_key_frames(action, r) if start < f < end})
            hips, rot = r.sample(action, keys)
            fixed = pinned_flags(s, r, keys, start, end)
            all_h, all_r = model.complete_poses(np.array(keys) - start, (hips, rot), fixed)
            if fixed is None:
                write_frames = [f for f in inner if f not in keys]
                keyset = set(keys)
                # Everything strictly inside goes, except the keys the completion kept.
                drop = lambda x: start < x < end and not (abs(x - round(x)) < 1e-4 and int(round(x)) in keyset)  # noqa: E731
            else:
                # Pinned bones: the keys inside are partial, so their frames are the model's too
                # (the pinned bones' keyed rotations hit, the other bones free).
                write_frames = inner
                drop = lambda x: start < x < end  # noqa: E731
            idx = [f - start for f in write_frames]
            new_hips, new_rot = all_h[idx], all_r[idx]
        spacing = int(s.key_spacing)
        if spacing > 1:
            every = [i for i, f in enumerate(write_frames) if (f - start) % spacing == 0]
            write_frames = [write_frames[i] for i in every]
            new_hips, new_rot = new_hips[every], new_rot[every]
        if write_frames:
            r.write(
                action, write_frames, new_hips, new_rot, drop=drop, previous=start, strength=s.strength, keep_root=s.keep_root
            )
        ms = 1000 * (time.perf_counter() - t0)
        context.scene["zoo_last_ms"] = ms
        context.scene["zoo_last_range"] = [start, end]
        context.scene["zoo_last_range_source"] = source
        how = [f"keys every {spacing} frames"] if spacing > 1 else []
        how += [f"strength {s.strength:.2f}"] if s.strength < 1 else []
        how += ["root path kept"] if s.keep_root else []
        msg = (
            f"zoo: in-between {start}-{end} ({source}): {len(write_frames)} keyed frames from {model.kind}"
            + (f" ({', '.join(how)})" if how else "")
            + f" in {ms:.0f} ms"
        )
        w = r.warnings()
        self.report({"WARNING"} if w else {"INFO"}, msg + ("; " + "; ".join(w) if w else ""))
        return {"FINISHED"}


def stitch_inputs(context, rig):
    """The two clips to stitch: the panel's actions, else the armature's two selected NLA strips."""
    s = settings(context)
    if s.stitch_first is not None and s.stitch_second is not None:
        a, b = s.stitch_first, s.stitch_second
        return [(a.name, a, action_frames(a)), (b.name, b, action_frames(b))]
    ad = rig.arm.animation_data
    strips = [st for tr in (ad.nla_tracks if ad else []) for st in tr.strips if st.select and st.action]
    if len(strips) == 2:
        strips.sort(key=lambda st: st.frame_start)
        out = []
        for st in strips:
            a, b = st.action_frame_start, st.action_frame_end
            out.append((st.name, st.action, list(range(int(a), int(b) + 1))))
        return out
    raise Refusal("choose the two actions to stitch in the zoo panel, or select two NLA strips of the armature")


class ZOO_OT_stitch(bpy.types.Operator):
    """Join two actions (or two selected NLA strips) end to start with a stitching model, into a new action on the armature"""

    bl_idname = "zoo.stitch"
    bl_label = "Stitch"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        return run_refusable(self, context, lambda: self.run(context))

    def run(self, context):
        t0 = time.perf_counter()
        s = settings(context)
        model = model_of_task(s.model_path, ("stitch",), "Stitch")
        check_frame_rate(context, model, "Stitch")
        r = matched_rig(context, model)
        clips = stitch_inputs(context, r)
        for name, _, frames in clips:
            if len(frames) < model.min_clip_frames:
                raise Refusal(f"'{name}' has {len(frames)} frames; stitching needs at least {model.min_clip_frames} per clip")
        total = sum(len(f) for _, _, f in clips)
        if total < model.window:
            raise Refusal(f"the two clips have {total} frames together; the model refines at least {model.window}")
        progress = Progress(context, 3)
        try:
            parts = [r.sample(a, f) for _, a, f in clips]
            progress(1)
            poses, _, starts = model.stitch(parts)
            progress(2)
            action = bpy.data.actions.new(f"{clips[0][0]}+{clips[1][0]}")
            first = clips[0][2][0]
            frames = list(range(first, first + len(poses)))
            r.write(action, frames, poses.hips, poses.rotations)
            ad = r.arm.animation_data or r.arm.animation_data_create()
            ad.action = action
            progress(3)
        finally:
            progress.end()
        ms = 1000 * (time.perf_counter() - t0)
        self.report({"INFO"}, f"zoo: stitched '{clips[0][0]}' and '{clips[1][0]}' into '{action.name}': {len(poses)} frames ({ms:.0f} ms)")
        return {"FINISHED"}


def curve_points(context, curve, arm):
    """The curve's evaluated points in the armature's space `(M, 3)`."""
    deps = context.evaluated_depsgraph_get()
    ev = curve.evaluated_get(deps)
    mesh = ev.to_mesh()
    try:
        to_arm = arm.matrix_world.inverted() @ curve.matrix_world
        pts = np.array([tuple(to_arm @ v.co) for v in mesh.vertices], dtype=np.float64)
    finally:
        ev.to_mesh_clear()
    return pts


class ZOO_OT_walk(bpy.types.Operator):
    """Generate locomotion with a synthesis model that follows the chosen curve to its end, into a new action"""

    bl_idname = "zoo.walk"
    bl_label = "Walk along curve"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        return run_refusable(self, context, lambda: self.run(context))

    def run(self, context):
        t0 = time.perf_counter()
        s = settings(context)
        model = model_of_task(s.model_path, ("synthesis",), "Walk along curve")
        check_frame_rate(context, model, "Walk along curve")
        if model.frame.up_axis != "y":
            raise Refusal("the model's frame is not Y up; synthesis models steer about +Y")
        r = matched_rig(context, model)
        curve = s.curve
        if curve is None:
            curve = next((o for o in context.selected_objects if o.type == "CURVE"), None)
        if curve is None or curve.type != "CURVE":
            raise Refusal("choose a curve object in the zoo panel (or select one) for the character to follow")
        pts = curve_points(context, curve, r.arm)
        if len(pts) < 2:
            raise Refusal(f"curve '{curve.name}' has fewer than 2 points")
        z = zoo()
        ground = z.convert_positions(pts / r.units_per_metre, z.BLENDER, model.frame)[:, [0, 2]].astype(np.float64)
        keep = np.concatenate([[True], np.linalg.norm(np.diff(ground, axis=0), axis=1) > 1e-6])
        ground = ground[keep]
        if len(ground) < 2:
            raise Refusal(f"curve '{curve.name}' has no length")
        speed = s.walk_speed / model.frame.metres_per_unit if s.walk_speed > 0 else walkmod.natural_speed(model)
        most = 3 * walkmod.walk_frames(ground, speed, model.fps) + int(model.fps)
        progress = Progress(context, most)
        try:
            poses, dist, reached = walkmod.follow(model, ground, speed, seed=s.seed, max_frames=most, progress=progress)
            frames = len(dist)
            action = bpy.data.actions.new(f"walk along {curve.name}")
            f0 = context.scene.frame_current
            r.write(action, list(range(f0, f0 + frames)), poses.hips, poses.rotations)
            ad = r.arm.animation_data or r.arm.animation_data_create()
            ad.action = action
        finally:
            progress.end()
        mpu = model.frame.metres_per_unit
        ms = 1000 * (time.perf_counter() - t0)
        context.scene["zoo_walk_distance_cm"] = [float(dist.mean() * mpu * 100), float(dist.max() * mpu * 100)]
        self.report(
            {"INFO"},
            f"zoo: '{action.name}': {frames} frames; root to curve {dist.mean() * mpu * 100:.1f} cm mean, "
            f"{dist.max() * mpu * 100:.1f} cm max ({ms:.0f} ms)"
            + ("" if reached else f"; stopped after {frames} frames before the curve's end (the model could not follow it further)"),
        )
        return {"FINISHED"}


classes = (ZOO_OT_check_bones, ZOO_OT_pin_selected, ZOO_OT_inbetween, ZOO_OT_stitch, ZOO_OT_walk)

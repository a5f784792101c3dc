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


def same_rate(fps, model):
    """Whether `fps` is the model's frame rate: within 0.01 % (a BVH frame time is stored
    rounded: 30.00003 fps is 30)."""
    return abs(fps - model.fps) <= 1e-4 * model.fps


def resample(hips, rot, fps, new_fps):
    """BVH-style poses at `fps` resampled to `new_fps` over the same span, as `zoo data resample`
    does (`zoo.resample_world`, the same code)."""
    return zoo().resample_world(hips, rot, fps, new_fps)


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


class Inbetween:
    """What In-between and Preview share: the range, the model's frames, the report."""

    # SKIP_SAVE: a range given once (by a script) is not remembered for the next call.
    start: bpy.props.IntProperty(
        name="Start", default=-1, options={"SKIP_SAVE"}, description="First frame of the range (-1: the selected keys or the preview range)"
    )
    end: bpy.props.IntProperty(
        name="End", default=-1, options={"SKIP_SAVE"}, description="Last frame of the range (-1: the selected keys or the preview range)"
    )
    allow_longer: bpy.props.BoolProperty(name="Allow longer than trained", default=False)
    # A transition model's post-processes, as `zoo transition` (and the Python package) default them.
    fallback: bpy.props.BoolProperty(
        name="Fallback",
        default=True,
        options={"SKIP_SAVE"},
        description="Move a transition that misses its target by more than the model's calibrated thresholds towards the interpolation (zoo transition's default)",
    )
    foot_lock: bpy.props.BoolProperty(
        name="Foot lock",
        default=False,
        options={"SKIP_SAVE"},
        description="Lock the planted feet of a transition (zoo transition --foot-lock)",
    )
    preview = False

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
        plan = self.plan(context)
        action = plan["action"]
        if self.preview:
            action = make_preview(plan["rig"].arm, action)
        fit, keyed = write_plan(plan, action, s)
        ms = 1000 * (time.perf_counter() - t0)
        self.finish(context, plan, fit, keyed, ms)
        return {"FINISHED"}

    def plan(self, context):
        """Everything the in-between writes, computed before anything changes: the rig, the
        action, the range, the frames and the model's poses on them (at the scene's rate)."""
        s = settings(context)
        model = model_of_task(s.model_path, ("transition", "keyframes"), "In-between")
        r = matched_rig(context, model)
        ad = r.arm.animation_data
        action = ad.action if ad else None
        if action is None:
            raise Refusal(f"armature '{r.arm.name}' has no active action to in-between")
        if is_preview(action):
            if not self.preview:
                raise Refusal(f"armature '{r.arm.name}' shows a preview: Apply or Discard it first")
            # Previewing again: the range and keys are the original action's.
            action = original_of(action)
        start, end, source = self.range(context, action, r)
        if end - start < 2:
            raise Refusal(f"the range {start}-{end} has no frame strictly between its ends")
        first, last = action_frames(action)[0], action_frames(action)[-1]
        if start < first or end > last:
            raise Refusal(f"the range {start}-{end} is outside the action '{action.name}' (frames {first}-{last})")
        fps = scene_fps(context.scene)
        # At another rate than the model's, the scene's frames are resampled to the model's rate
        # (`zoo data resample`'s resampling), the model runs, and its frames are resampled back.
        rate = None if same_rate(fps, model) else (fps, model.fps)
        inner = list(range(start + 1, end))
        if model.task == "transition":
            write_frames, new_hips, new_rot, drop, keyset = self.transition(model, r, action, start, end, first, last, rate)
        else:
            write_frames, new_hips, new_rot, drop, keyset = self.keyframes(model, r, action, s, start, end, rate)
        spacing = int(s.key_spacing)
        keys = write_frames
        if spacing > 1:
            # Every `spacing` frames from the range's start, and the frames next to the keys that
            # stay (the ends, a keyframe model's keys): those keep their handles and interpolation
            # (the BVH importer's are linear, or a third of a frame long), which would bend the
            # segments next to them away from the model's motion.
            kept = {start, end} | keyset
            keys = [f for f in write_frames if (f - start) % spacing == 0 or f - 1 in kept or f + 1 in kept]
            if not s.fit_handles:
                every = [i for i, f in enumerate(write_frames) if f in keys]
                write_frames, new_hips, new_rot = keys, new_hips[every], new_rot[every]
        return {
            "rig": r,
            "model": model,
            "action": action,
            "start": start,
            "end": end,
            "source": source,
            "inner": inner,
            "frames": write_frames,
            "keys": keys,
            "hips": new_hips,
            "rotations": new_rot,
            "drop": drop,
            "spacing": spacing,
            "rate": rate,
        }

    def transition(self, model, r, action, start, end, first, last, rate):
        """A transition model's frames strictly between `start` and `end`."""
        p = model.past_frames
        # Scene frames per model frame (1 at the model's rate).
        step = 1.0 if rate is None else rate[0] / rate[1]
        back = p - 1 if rate is None else int(math.ceil((p - 1) * step - 1e-6))
        if start - back < first:
            need = f"{p} frames of context" + ("" if rate is None else f" ({p} frames at the model's {rate[1]:g} fps)")
            raise Refusal(
                f"In-between needs {need} up to the range's first frame {start} (frames "
                f"{start - back} to {start}), but the action '{action.name}' starts at frame {first}: start the range at "
                f"frame {first + back} or later"
            )
        length = end - start - 1 if rate is None else int(round((end - start) / step)) - 1
        if length < 1:
            raise Refusal(f"the range {start}-{end} is shorter than two frames at the model's {rate[1]:g} fps")
        if length > model.transition_frames and not self.allow_longer:
            raise Refusal(
                f"{length} frames between {start} and {end}"
                + ("" if rate is None else f" at the model's {rate[1]:g} fps")
                + f", but the model was trained for {model.transition_frames}: "
                "choose a shorter range, or turn on 'Allow longer than trained' (the motion drifts beyond it)"
            )
        if rate is None:
            nxt = end + 1 if end + 1 <= last else end
            frames = list(range(start - p + 1, start + 1)) + [end, nxt]
            hips, rot = r.sample(action, frames)
            past, target, after = (hips[:p], rot[:p]), (hips[p], rot[p]), (hips[p + 1], rot[p + 1])
        else:
            # The context backwards from the range's first frame, so that it lands on it.
            h, q = r.sample(action, list(range(start, start - back - 1, -1)))
            h, q = resample(h, q, rate[0], rate[1])
            past = (h[:p][::-1].copy(), q[:p][::-1].copy())
            ahead = int(math.ceil(step - 1e-6))
            if end + ahead <= last:
                h, q = resample(*r.sample(action, list(range(end, end + ahead + 1))), rate[0], rate[1])
                target, after = (h[0], q[0]), (h[1], q[1])
            else:
                h, q = r.sample(action, [end])
                target = after = (h[0], q[0])
        out = model.transition(
            past,
            target,
            after,
            frames=length,
            allow_beyond_trained=self.allow_longer,
            fallback=self.fallback,
            foot_lock=self.foot_lock,
        )
        new_hips, new_rot = out.hips[:length], out.rotations[:length]
        if rate is not None:
            # The range's first frame, the model's frames and its target span the range: they are
            # resampled from (length + 1) frames per range to the scene's frames.
            hips = np.concatenate([past[0][-1:], out.hips[: length + 1]])
            rot = np.concatenate([past[1][-1:], out.rotations[: length + 1]])
            h, q = resample(hips, rot, (length + 1) / (end - start), 1.0)
            new_hips, new_rot = h[1 : end - start], q[1 : end - start]
        drop = lambda x: start < x < end  # noqa: E731
        return list(range(start + 1, end)), new_hips, new_rot, drop, set()

    def keyframes(self, model, r, action, s, start, end, rate):
        """A keyframe model's frames strictly between `start` and `end`, from the keys."""
        if not model.humanoid:
            raise Refusal(
                f"this keyframe model completes {model.dofs} values per pose (the lamp), not an armature: choose a "
                "keyframe model trained on humanoid motion"
            )
        inner = list(range(start + 1, end))
        keys = sorted({start, end} | {f for f in selected_key_frames(action, r) if start < f < end})
        hips, rot = r.sample(action, keys)
        fixed = pinned_flags(s, r, keys, start, end)
        if rate is None:
            at = np.array(keys) - start
            span = end - start
        else:
            # The keys' times at the model's rate, the range a whole number of model frames.
            span = max(int(round((end - start) * rate[1] / rate[0])), 2)
            at = np.round((np.array(keys) - start) * span / (end - start)).astype(int)
            same = [(keys[i], keys[i + 1]) for i in range(len(keys) - 1) if at[i] == at[i + 1]]
            if same:
                raise Refusal(
                    f"the keys at frames {same[0][0]} and {same[0][1]} fall on the same frame at the model's "
                    f"{rate[1]:g} fps: key fewer frames, or set the scene's rate to {rate[1]:g} fps"
                )
        all_h, all_r = model.complete_poses(at, (hips, rot), fixed)
        if rate is not None:
            all_h, all_r = resample(all_h[: span + 1], all_r[: span + 1], span / (end - start), 1.0)
        keyset = set(keys)
        if fixed is None:
            write_frames = [f for f in inner if f not in keys]
            # Everything strictly inside goes, except the keys the completion kept.
            drop = lambda x: start < x < end and not (abs(x - round(x)) < 1e-4 and int(round(x)) in keyset)  # noqa: E731
        else:
            # Pinned bones: the keys inside are partial, so their frames are the model's too
            # (the pinned bones' keyed rotations hit, the other bones free).
            write_frames = inner
            drop = lambda x: start < x < end  # noqa: E731
        idx = [f - start for f in write_frames]
        # The keys that stay as they are (with pinned bones the keys inside are written over).
        return write_frames, all_h[idx], all_r[idx], drop, keyset if fixed is None else set()

    def finish(self, context, plan, fit, keyed, ms):
        """Reports what was written (and remembers it in the scene for scripts)."""
        s = settings(context)
        sc = context.scene
        start, end, spacing, rate = plan["start"], plan["end"], plan["spacing"], plan["rate"]
        sc["zoo_last_ms"] = ms
        sc["zoo_last_range"] = [start, end]
        sc["zoo_last_range_source"] = plan["source"]
        sc["zoo_last_keys"] = keyed
        sc["zoo_last_fit_residual"] = fit
        sc["zoo_last_resampled"] = rate is not None
        how = []
        if spacing > 1:
            how.append(f"keys every {spacing} frames" + (", handles fitted" if s.fit_handles else ""))
        how += [f"strength {s.strength:.2f}"] if s.strength < 1 else []
        how += ["root path kept"] if s.keep_root else []
        if rate is not None:
            how.append(f"resampled from the scene's {rate[0]:g} fps to the model's {rate[1]:g} fps and back")
        what = "preview of" if self.preview else "in-between"
        msg = (
            f"zoo: {what} {start}-{end} ({plan['source']}): {keyed} keyed frames from {plan['model'].kind}"
            + (f" ({', '.join(how)})" if how else "")
            + f" in {ms:.0f} ms"
        )
        if self.preview:
            msg += f"; play '{plan['rig'].arm.animation_data.action.name}', then Apply or Discard"
        w = plan["rig"].warnings()
        self.report({"WARNING"} if w else {"INFO"}, msg + ("; " + "; ".join(w) if w else ""))


def write_plan(plan, action, s):
    """Writes an in-between's plan into `action`; returns the handle fit's largest residual and
    the most keys written on one F-curve."""
    if not plan["frames"]:
        return 0.0, 0
    fit = plan["spacing"] > 1 and s.fit_handles
    return plan["rig"].write(
        action,
        plan["frames"],
        plan["hips"],
        plan["rotations"],
        drop=plan["drop"],
        previous=plan["start"],
        strength=s.strength,
        keep_root=s.keep_root,
        keys=plan["keys"] if fit else None,
        fit=fit,
    )


# --- preview ----------------------------------------------------------------------------------

PREVIEW = "zoo_preview_of"
"""The custom property of a preview action: the name of the action it previews."""


def is_preview(action):
    return action is not None and PREVIEW in action.keys()


def original_of(preview):
    """The action a preview stands for."""
    name = preview[PREVIEW]
    a = bpy.data.actions.get(name)
    if a is None:
        raise Refusal(f"the preview '{preview.name}' stands for action '{name}', which no longer exists: discard it")
    return a


def make_preview(arm, original):
    """A copy of `original` made the armature's action for the preview (an earlier preview of it
    removed); `original` stays as it was, kept by a fake user while nothing else uses it."""
    ad = arm.animation_data
    current = ad.action
    fake = original.use_fake_user
    if is_preview(current):
        fake = bool(current["zoo_fake_user"])
        ad.action = original
        bpy.data.actions.remove(current)
    preview = original.copy()
    preview.name = f"{original.name} (zoo preview)"
    preview[PREVIEW] = original.name
    preview["zoo_fake_user"] = fake
    original.use_fake_user = True
    ad.action = preview
    return preview


class ZOO_OT_inbetween(Inbetween, bpy.types.Operator):
    """Fill the frames strictly between the ends of the selected range of the active action with the model: a transition model from the frames before the range to its last frame, or a keyframe model from the keys. The ends and every key outside stay as they are"""

    bl_idname = "zoo.inbetween"
    bl_label = "In-between"
    bl_options = {"REGISTER", "UNDO"}


class ZOO_OT_preview(Inbetween, bpy.types.Operator):
    """In-between into a preview action (a copy of the action, made the armature's) to play before applying: Apply puts it in place of the action, Discard goes back to the action as it was"""

    bl_idname = "zoo.preview"
    bl_label = "Preview"
    bl_options = {"REGISTER", "UNDO"}
    preview = True


def active_preview(context):
    """The active armature's preview action, or a refusal."""
    ob = active_armature(context)
    ad = ob.animation_data
    action = ad.action if ad else None
    if not is_preview(action):
        raise Refusal(f"armature '{ob.name}' shows no preview: press Preview first")
    return ob, action, original_of(action)


class ZOO_OT_apply_preview(bpy.types.Operator):
    """Put the preview in place of the action it previews, everywhere that action is used"""

    bl_idname = "zoo.apply_preview"
    bl_label = "Apply"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        def body():
            ob, preview, original = active_preview(context)
            name, fake = original.name, bool(preview["zoo_fake_user"])
            original.use_fake_user = False
            original.user_remap(preview)
            bpy.data.actions.remove(original)
            del preview[PREVIEW]
            del preview["zoo_fake_user"]
            preview.name = name
            preview.use_fake_user = fake
            self.report({"INFO"}, f"zoo: the preview applied to action '{name}'")
            return {"FINISHED"}

        return run_refusable(self, context, body)


class ZOO_OT_discard_preview(bpy.types.Operator):
    """Remove the preview and give the armature back the action as it was"""

    bl_idname = "zoo.discard_preview"
    bl_label = "Discard"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        def body():
            ob, preview, original = active_preview(context)
            original.use_fake_user = bool(preview["zoo_fake_user"])
            ob.animation_data.action = original
            bpy.data.actions.remove(preview)
            self.report({"INFO"}, f"zoo: preview discarded; action '{original.name}' as it was")
            return {"FINISHED"}

        return run_refusable(self, context, body)


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
        fps = scene_fps(context.scene)
        # At another rate than the model's: the clips resampled to it, the result back.
        rate = None if same_rate(fps, model) else (fps, model.fps)
        at = "" if rate is None else f" at the model's {model.fps:g} fps"
        r = matched_rig(context, model)
        clips = stitch_inputs(context, r)
        progress = Progress(context, 3)
        try:
            parts = [r.sample(a, f) for _, a, f in clips]
            if rate is not None:
                parts = [resample(h, q, fps, model.fps) for h, q in parts]
            for (name, _, _), (h, _) in zip(clips, parts):
                if len(h) < model.min_clip_frames:
                    raise Refusal(f"'{name}' has {len(h)} frames{at}; stitching needs at least {model.min_clip_frames} per clip")
            total = sum(len(h) for h, _ in parts)
            if total < model.window:
                raise Refusal(f"the two clips have {total} frames{at} together; the model refines at least {model.window}")
            progress(1)
            poses, _, starts = model.stitch(parts)
            hips, rot = poses.hips, poses.rotations
            if rate is not None:
                hips, rot = resample(hips, rot, model.fps, fps)
            progress(2)
            action = bpy.data.actions.new(f"{clips[0][0]}+{clips[1][0]}")
            first = clips[0][2][0]
            frames = list(range(first, first + len(hips)))
            r.write(action, frames, hips, rot)
            ad = r.arm.animation_data or r.arm.animation_data_create()
            ad.action = action
            progress(3)
        finally:
            progress.end()
        ms = 1000 * (time.perf_counter() - t0)
        note = "" if rate is None else f"; resampled from the scene's {fps:g} fps to the model's {model.fps:g} fps and back"
        self.report(
            {"INFO"},
            f"zoo: stitched '{clips[0][0]}' and '{clips[1][0]}' into '{action.name}': {len(hips)} frames ({ms:.0f} ms){note}",
        )
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
        fps = scene_fps(context.scene)
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
            hips, rot = poses.hips, poses.rotations
            if not same_rate(fps, model):
                # Generated at the model's rate, resampled to the scene's.
                hips, rot = resample(hips, rot, model.fps, fps)
            frames = len(hips)
            action = bpy.data.actions.new(f"walk along {curve.name}")
            f0 = context.scene.frame_current
            r.write(action, list(range(f0, f0 + frames)), hips, rot)
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
            + ("" if reached else f"; stopped after {frames} frames before the curve's end (the model could not follow it further)")
            + ("" if same_rate(fps, model) else f"; resampled from the model's {model.fps:g} fps to the scene's {fps:g} fps"),
        )
        return {"FINISHED"}


classes = (
    ZOO_OT_check_bones,
    ZOO_OT_pin_selected,
    ZOO_OT_inbetween,
    ZOO_OT_preview,
    ZOO_OT_apply_preview,
    ZOO_OT_discard_preview,
    ZOO_OT_stitch,
    ZOO_OT_walk,
)

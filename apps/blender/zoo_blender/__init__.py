"""zoo for Blender: in-betweening, stitching and walking along a curve with zoo's models, on the
active armature, in the 3D view's sidebar (N panel, tab "zoo").

The models are files of `zoo export --onnx`; they run on zoo's runtime through the `zoo`
Python package (its wheel ships inside the add-on zip made by `apps/blender/make_addon.py`). See
docs/blender.md."""

bl_info = {
    "name": "zoo: learned in-betweening",
    "author": "zoo maintainers",
    "version": (0, 1, 0),
    "blender": (3, 4, 0),
    "location": "View3D > Sidebar > zoo",
    "description": "In-between, stitch and walk along a curve on the active armature with zoo's models",
    "category": "Animation",
}

import bpy

from . import operators


def _is_curve(_self, obj):
    return obj.type == "CURVE"


class ZooSettings(bpy.types.PropertyGroup):
    model_path: bpy.props.StringProperty(
        name="Model", subtype="FILE_PATH", description="A model exported by `zoo export --onnx` (.onnx)"
    )
    bone_names: bpy.props.EnumProperty(
        name="Bone names",
        items=[
            ("MODEL", "Model's", "Bones named as the model's joints (case and a namespace prefix ignored)"),
            ("MIXAMO", "Mixamo", "Mixamo's names (mixamorig:Hips, LeftUpLeg, ...; maps/mixamo.json)"),
            ("RIGIFY", "Rigify", "Rigify's metarig names (spine, thigh.L, ...; maps/rigify.json)"),
        ],
        default="MODEL",
    )
    bone_map: bpy.props.StringProperty(
        name="Bone map",
        subtype="FILE_PATH",
        description='Optional JSON {"model joint": "bone"} for bones named otherwise (over the names chosen above)',
    )
    key_spacing: bpy.props.EnumProperty(
        name="Keys",
        items=[("1", "Every frame", ""), ("2", "Every 2 frames", ""), ("4", "Every 4 frames", "")],
        default="1",
        description="In-between keys on every frame, or every 2 or 4 frames from the range's start and on the frames "
        "next to the keys that stay (Blender's curves between)",
    )
    fit_handles: bpy.props.BoolProperty(
        name="Fit handles",
        default=True,
        description="With keys every 2 or 4 frames: Bezier handles fitted to the model's motion between the keys (least "
        "squares), so that the curves follow it; off: automatic handles",
    )
    strength: bpy.props.FloatProperty(
        name="Strength",
        default=1.0,
        min=0.0,
        max=1.0,
        subtype="FACTOR",
        description="0: the action's own curves, 1: the model's motion; between, each channel blended",
    )
    keep_root: bpy.props.BoolProperty(
        name="Keep root path", default=False, description="The root bone's location keeps the action's curves"
    )
    pinned_bones: bpy.props.StringProperty(
        name="Pinned",
        description="Bones whose keyed rotations a keyframe model keeps at the keys inside the range (comma-separated; "
        "empty: every key fixes every bone)",
    )
    stitch_first: bpy.props.PointerProperty(name="First", type=bpy.types.Action)
    stitch_second: bpy.props.PointerProperty(name="Second", type=bpy.types.Action)
    curve: bpy.props.PointerProperty(name="Curve", type=bpy.types.Object, poll=_is_curve)
    walk_speed: bpy.props.FloatProperty(
        name="Speed",
        default=0.0,
        min=0.0,
        max=10.0,
        unit="VELOCITY",
        description="Walking speed, metres per second (0: the model's own, the speed of its data's mean frame)",
    )
    seed: bpy.props.IntProperty(name="Seed", default=0, min=0)


class ZOO_PT_panel(bpy.types.Panel):
    bl_label = "zoo"
    bl_idname = "ZOO_PT_panel"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "zoo"

    def draw(self, context):
        s = context.scene.zoo
        col = self.layout.column()
        col.prop(s, "model_path")
        col.prop(s, "bone_names")
        col.prop(s, "bone_map")
        col.operator("zoo.check_bones", icon="BONE_DATA")
        box = self.layout.box()
        box.label(text="In-between")
        rules = box.column(align=True)
        rules.label(text="Range: the preview range when on,")
        rules.label(text="else two selected markers,")
        rules.label(text="else the selected keys' first and last")
        row = box.row(align=True)
        row.prop(s, "key_spacing")
        row.prop(s, "fit_handles", text="Fit")
        box.prop(s, "strength", slider=True)
        box.prop(s, "keep_root")
        row = box.row(align=True)
        row.prop(s, "pinned_bones")
        row.operator("zoo.pin_selected", text="", icon="PINNED")
        box.operator("zoo.inbetween", icon="IPO_BEZIER")
        row = box.row(align=True)
        row.operator("zoo.preview", icon="HIDE_OFF")
        row.operator("zoo.apply_preview", icon="CHECKMARK")
        row.operator("zoo.discard_preview", icon="X")
        box = self.layout.box()
        box.label(text="Stitch two actions (or two NLA strips)")
        box.prop(s, "stitch_first")
        box.prop(s, "stitch_second")
        box.operator("zoo.stitch", icon="NLA")
        box = self.layout.box()
        box.label(text="Walk along a curve")
        box.prop(s, "curve")
        row = box.row()
        row.prop(s, "walk_speed")
        row.prop(s, "seed")
        box.operator("zoo.walk", icon="CURVE_PATH")


classes = (ZooSettings, ZOO_PT_panel) + operators.classes


def register():
    for c in classes:
        bpy.utils.register_class(c)
    bpy.types.Scene.zoo = bpy.props.PointerProperty(type=ZooSettings)


def unregister():
    del bpy.types.Scene.zoo
    for c in reversed(classes):
        bpy.utils.unregister_class(c)

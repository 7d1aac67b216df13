"""Motion Style: restyle the active armature's action through a motion-style service.

A panel in the 3D view's sidebar (N, tab "Motion Style"): server URL, style (from the
service's ``GET /v1/styles``), strength, Keep timing (no time warp: the new action as long
as the original), Restyle. The operator ``motion_style.transfer`` (properties ``server``,
``style_name``, ``strength``, ``keep_timing``) also runs from scripts and in ``blender
-b``; the result becomes a new action named after the original and the style
("Walk.elderly") on the same armature, the original kept.

A service that needs an API key gets the one in the add-on's preferences (Edit >
Preferences > Add-ons > Motion Style), else ``$MOTION_API_KEY``. Preferences live in
Blender's user settings, never in a .blend file, so a scene passed on carries no key.
"""

bl_info = {
    "name": "Motion Style",
    "author": "motion-style",
    "version": (0, 1, 0),
    "blender": (3, 4, 0),
    "location": "View3D > Sidebar > Motion Style",
    "description": "Restyle an armature's action through a motion-style service",
    "category": "Animation",
}

import bpy  # noqa: E402

from . import restyle, service  # noqa: E402

DEFAULT_SERVER = "http://localhost:8000"
_style_items: list[tuple[str, str, str]] = []  # Blender needs the enum's strings kept alive


class MotionStylePreferences(bpy.types.AddonPreferences):
    bl_idname = __name__

    api_key: bpy.props.StringProperty(
        name="API key",
        subtype="PASSWORD",
        default="",
        description="the service's API key, if it needs one (else $MOTION_API_KEY)",
    )

    def draw(self, context):
        self.layout.prop(self, "api_key")


def api_key(context) -> str:
    """The key in the add-on's preferences ("" leaves it to $MOTION_API_KEY)."""
    addon = context.preferences.addons.get(__name__)
    return addon.preferences.api_key if addon is not None and addon.preferences else ""


def style_items(self, context):
    return _style_items or [("", "(refresh the list)", "no styles loaded from the service")]


def active_armature(context):
    obj = context.active_object
    if obj is None or obj.type != "ARMATURE":
        return None, "the active object is not an armature"
    if obj.animation_data is None or obj.animation_data.action is None:
        return None, f"armature {obj.name!r} has no action to restyle"
    return obj, None


class MOTION_STYLE_OT_refresh_styles(bpy.types.Operator):
    """Load the style names from the service"""

    bl_idname = "motion_style.refresh_styles"
    bl_label = "Refresh Styles"

    server: bpy.props.StringProperty(name="Server", default="")

    def execute(self, context):
        server = self.server or context.scene.motion_style_server
        try:
            names = service.styles(server, api_key(context))
        except service.ServiceError as exc:
            self.report({"ERROR"}, f"Motion Style: {exc}")
            return {"CANCELLED"}
        _style_items[:] = [(n, n, f"the translator's {n} style") for n in names]
        if names and context.scene.motion_style_style not in names:
            context.scene.motion_style_style = names[0]
        self.report({"INFO"}, f"Motion Style: {len(names)} styles")
        return {"FINISHED"}


class MOTION_STYLE_OT_transfer(bpy.types.Operator):
    """Restyle the active armature's action; the result is a new action, the original kept"""

    bl_idname = "motion_style.transfer"
    bl_label = "Restyle"
    bl_options = {"REGISTER", "UNDO"}

    server: bpy.props.StringProperty(name="Server", default=DEFAULT_SERVER)
    style_name: bpy.props.StringProperty(name="Style", default="")
    strength: bpy.props.FloatProperty(name="Strength", default=1.0, min=0.0, max=1.0)
    keep_timing: bpy.props.BoolProperty(
        name="Keep timing", default=False, description="no time warp: as many frames as sent"
    )

    @classmethod
    def poll(cls, context):
        return active_armature(context)[0] is not None

    def execute(self, context):
        obj, problem = active_armature(context)
        if problem:
            self.report({"ERROR"}, f"Motion Style: {problem}")
            return {"CANCELLED"}
        if not self.style_name:
            self.report({"ERROR"}, "Motion Style: no style chosen")
            return {"CANCELLED"}
        try:
            action, warnings = restyle.restyle(
                context,
                obj,
                self.server,
                self.style_name,
                self.strength,
                api_key(context),
                self.keep_timing,
            )
        except service.ServiceError as exc:
            self.report({"ERROR"}, f"Motion Style: {exc}")
            return {"CANCELLED"}
        for warning in warnings:
            self.report({"WARNING"}, f"Motion Style: {warning}")
        self.report({"INFO"}, f"Motion Style: new action {action.name!r}")
        return {"FINISHED"}


class VIEW3D_PT_motion_style(bpy.types.Panel):
    bl_label = "Motion Style"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Motion Style"

    def draw(self, context):
        scene = context.scene
        layout = self.layout
        layout.prop(scene, "motion_style_server")
        row = layout.row(align=True)
        row.prop(scene, "motion_style_style")
        row.operator(MOTION_STYLE_OT_refresh_styles.bl_idname, text="", icon="FILE_REFRESH")
        layout.prop(scene, "motion_style_strength")
        layout.prop(scene, "motion_style_keep_timing")
        op = layout.operator(MOTION_STYLE_OT_transfer.bl_idname, icon="ARMATURE_DATA")
        op.server = scene.motion_style_server
        op.style_name = scene.motion_style_style
        op.strength = scene.motion_style_strength
        op.keep_timing = scene.motion_style_keep_timing
        obj, problem = active_armature(context)
        if problem:
            layout.label(text=problem, icon="INFO")


CLASSES = (
    MotionStylePreferences,
    MOTION_STYLE_OT_refresh_styles,
    MOTION_STYLE_OT_transfer,
    VIEW3D_PT_motion_style,
)


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.Scene.motion_style_server = bpy.props.StringProperty(
        name="Server", default=DEFAULT_SERVER, description="URL of the motion-style service"
    )
    bpy.types.Scene.motion_style_style = bpy.props.EnumProperty(
        name="Style", items=style_items, description="the translator's styles (Refresh loads them)"
    )
    bpy.types.Scene.motion_style_strength = bpy.props.FloatProperty(
        name="Strength", default=1.0, min=0.0, max=1.0, description="0 keeps the clip, 1 full style"
    )
    bpy.types.Scene.motion_style_keep_timing = bpy.props.BoolProperty(
        name="Keep timing",
        default=False,
        description="no time warp: the new action has as many frames as the original",
    )


def unregister():
    for name in (
        "motion_style_server",
        "motion_style_style",
        "motion_style_strength",
        "motion_style_keep_timing",
    ):
        delattr(bpy.types.Scene, name)
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)

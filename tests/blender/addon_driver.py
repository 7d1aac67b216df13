"""Run inside Blender: ``blender -b --factory-startup --python addon_driver.py -- ZIP CLIP
SERVER STYLE STRENGTH OUT_FOLDER [KEY_SOURCE]``. Installs and enables the add-on from its
zip, imports the clip (BVH, or a GLB through Blender's glTF importer), loads the styles,
runs ``motion_style.transfer`` on the armature, and writes what happened to
OUT_FOLDER/report.json, with BVH exports of the action before (before.bvh) and after
(after.bvh) for the test to compare with the service's answer, and the scene saved as
OUT_FOLDER/scene.blend; then restyles the original once more with "Keep timing".

KEY_SOURCE ``preferences``: the service needs a key; the driver first loads the styles
without one, then puts ``$MOTION_STYLE_TEST_KEY`` in the add-on's preferences.
``environment``: the add-on finds the key in ``$MOTION_API_KEY`` itself."""

import json
import os
import sys

import addon_utils
import bpy


def export(obj, path):
    start, end = (int(round(f)) for f in obj.animation_data.action.frame_range)
    with bpy.context.temp_override(active_object=obj, object=obj, selected_objects=[obj]):
        bpy.ops.export_anim.bvh(filepath=path, frame_start=start, frame_end=end)


def main():
    args = sys.argv[sys.argv.index("--") + 1 :]
    zip_path, clip_path, server, style, strength, out = args[:6]
    key_source = args[6] if len(args) > 6 else ""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.preferences.addon_install(filepath=zip_path)
    addon_utils.enable("motion_style", default_set=True, handle_error=None)
    import motion_style
    from motion_style import restyle

    if clip_path.endswith(".glb"):  # bones oriented by the glTF importer, not by a BVH's
        import numpy

        if not hasattr(numpy, "bool"):  # Blender 3.4's glTF importer uses np.bool (numpy<1.24)
            numpy.bool = bool
        bpy.context.scene.render.fps = 30
        bpy.ops.import_scene.gltf(filepath=clip_path)
        armature = next(o for o in bpy.data.objects if o.type == "ARMATURE")
        bpy.context.view_layer.objects.active = armature
    else:
        restyle.readable_bvh_importer()
        bpy.ops.import_anim.bvh(
            filepath=clip_path, update_scene_fps=True, update_scene_duration=True
        )
        armature = bpy.context.view_layer.objects.active
    original = armature.animation_data.action
    report = {
        "addon_file": motion_style.__file__,
        "panel": hasattr(bpy.types, "VIEW3D_PT_motion_style"),
        "objects_before": sorted(o.name for o in bpy.data.objects),
        "original": original.name,
        "original_range": list(original.frame_range),
        "original_curves": len(original.fcurves),
    }
    export(armature, os.path.join(out, "before.bvh"))
    bpy.context.scene.motion_style_server = server
    if key_source == "preferences":
        try:
            bpy.ops.motion_style.refresh_styles()
            report["refresh_without_key"] = "no error"
        except RuntimeError as exc:
            report["refresh_without_key"] = str(exc)
        preferences = bpy.context.preferences.addons["motion_style"].preferences
        preferences.api_key = os.environ["MOTION_STYLE_TEST_KEY"]
    report["refresh"] = sorted(bpy.ops.motion_style.refresh_styles())
    report["styles"] = [item[0] for item in motion_style.style_items(None, bpy.context)]
    report["transfer"] = sorted(
        bpy.ops.motion_style.transfer(server=server, style_name=style, strength=float(strength))
    )
    action = armature.animation_data.action
    report.update(
        objects_after=sorted(o.name for o in bpy.data.objects),
        actions=sorted(a.name for a in bpy.data.actions),
        active_action=action.name,
        active_range=list(action.frame_range),
        keys=max(len(c.keyframe_points) for c in action.fcurves),
        original_kept=original.name in bpy.data.actions,
        original_fake_user=original.use_fake_user,
        original_range_after=list(original.frame_range),
        original_curves_after=len(original.fcurves),
        fps=bpy.context.scene.render.fps / bpy.context.scene.render.fps_base,
    )
    export(armature, os.path.join(out, "after.bvh"))
    # a bad style is reported, not raised, and leaves the armature alone
    try:
        bpy.ops.motion_style.transfer(server=server, style_name="no-such-style")
        report["bad_style"] = "no error"
    except RuntimeError as exc:
        report["bad_style"] = str(exc)
    report["action_after_bad_style"] = armature.animation_data.action.name
    bpy.ops.wm.save_as_mainfile(filepath=os.path.join(out, "scene.blend"), compress=False)
    # "Keep timing": the original restyled again without the time warp
    armature.animation_data.action = original
    bpy.context.scene.motion_style_keep_timing = True
    report["panel_keep_timing"] = bpy.context.scene.motion_style_keep_timing
    report["kept_timing"] = sorted(
        bpy.ops.motion_style.transfer(
            server=server, style_name=style, strength=float(strength), keep_timing=True
        )
    )
    kept = armature.animation_data.action
    report.update(kept_timing_action=kept.name, kept_timing_range=list(kept.frame_range))
    with open(os.path.join(out, "report.json"), "w") as f:
        json.dump(report, f)


main()

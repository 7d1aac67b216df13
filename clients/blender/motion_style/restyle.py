"""An armature's action through the service: export it with Blender's BVH exporter, send
it, import the answer with Blender's BVH importer onto a scratch armature, and bake that
armature's motion onto the original as a new action.

The exported BVH's joints are the bones, with frames that the rest pose leaves aligned
with the armature, and the service answers on the same joints. So each bone of the
scratch armature, posed, differs from its own rest by the transform ``D`` (armature
space) that the original bone must make from its rest: ``pose = D @ rest`` on both.
"""

from __future__ import annotations

import builtins
import os
import tempfile

import bpy
from mathutils import Matrix

from . import service


def readable_bvh_importer() -> None:
    """Blender 3.4's BVH importer opens files with mode ``'rU'``, which Python 3.11 (as in
    Debian's Blender 3.4) refuses; drop the ``U`` (universal newlines are the default)."""
    from io_anim_bvh import import_bvh

    def open_without_u(file, mode="r", *args, **kwargs):
        return builtins.open(file, mode.replace("U", ""), *args, **kwargs)

    import_bvh.open = open_without_u


def action_frames(obj) -> tuple[int, int]:
    start, end = obj.animation_data.action.frame_range
    return int(round(start)), int(round(end))


def export_bvh(context, obj, path: str) -> None:
    start, end = action_frames(obj)
    with context.temp_override(active_object=obj, object=obj, selected_objects=[obj]):
        bpy.ops.export_anim.bvh(
            filepath=path, frame_start=start, frame_end=end, rotate_mode="NATIVE",
            root_transform_only=False,
        )  # fmt: skip


def import_bvh(context, path: str, frame_start: int):
    """The BVH as a new armature object (exported axes: no conversion), and its action."""
    readable_bvh_importer()
    before = set(bpy.data.objects)
    bpy.ops.import_anim.bvh(
        filepath=path, axis_forward="Y", axis_up="Z", frame_start=frame_start,
        update_scene_fps=False, update_scene_duration=False, use_fps_scale=False,
        rotate_mode="NATIVE",
    )  # fmt: skip
    (scratch,) = [o for o in bpy.data.objects if o not in before and o.type == "ARMATURE"]
    return scratch


def bake(context, scratch, target, name: str, frame_start: int, frames: int):
    """A new action on ``target`` that poses each of its bones as ``scratch`` poses the bone
    of the same name, relative to each one's own rest; bones the answer lacks follow their
    parent."""
    scene = context.scene
    bones = list(target.pose.bones)  # parents come before children in this list
    rest = {b.name: b.bone.matrix_local.copy() for b in bones}
    scratch_rest = {b.name: b.matrix_local.copy() for b in scratch.data.bones}
    samples: dict[str, list[Matrix]] = {b.name: [] for b in bones}
    for k in range(frames):
        scene.frame_set(frame_start + k)
        desired: dict[str, Matrix] = {}
        for pb in bones:
            source = scratch.pose.bones.get(pb.name)
            if source is not None:
                delta = source.matrix @ scratch_rest[pb.name].inverted()
            elif pb.parent is not None:
                delta = desired[pb.parent.name] @ rest[pb.parent.name].inverted()
            else:
                delta = Matrix.Identity(4)
            desired[pb.name] = delta @ rest[pb.name]
            if pb.parent is None:
                basis = rest[pb.name].inverted() @ desired[pb.name]
            else:
                parent = pb.parent.name
                basis = (desired[parent] @ rest[parent].inverted() @ rest[pb.name]).inverted()
                basis = basis @ desired[pb.name]
            samples[pb.name].append(basis)

    action = bpy.data.actions.new(name)
    for pb in bones:
        write_bone_curves(action, pb, samples[pb.name], frame_start)
    return action


def write_bone_curves(action, pb, matrices: list[Matrix], frame_start: int) -> None:
    base = f'pose.bones["{bpy.utils.escape_identifier(pb.name)}"]'
    locations, rotations, scales = [], [], []
    previous = None
    for m in matrices:
        loc, quat, scale = m.decompose()
        if pb.rotation_mode == "QUATERNION":
            if previous is not None and previous.dot(quat) < 0:
                quat.negate()
            rotation, path = list(quat), "rotation_quaternion"
            previous = quat
        elif pb.rotation_mode == "AXIS_ANGLE":
            axis, angle = quat.to_axis_angle()
            rotation, path = [angle, *axis], "rotation_axis_angle"
        else:
            euler = (
                quat.to_euler(pb.rotation_mode, previous)
                if previous
                else quat.to_euler(pb.rotation_mode)
            )
            rotation, path = list(euler), "rotation_euler"
            previous = euler
        locations.append(list(loc))
        rotations.append(rotation)
        scales.append(list(scale))
    for path_name, values in (("location", locations), (path, rotations), ("scale", scales)):
        for index in range(len(values[0])):
            curve = action.fcurves.new(f"{base}.{path_name}", index=index, action_group=pb.name)
            curve.keyframe_points.add(len(values))
            coords = []
            for k, value in enumerate(values):
                coords += [frame_start + k, value[index]]
            curve.keyframe_points.foreach_set("co", coords)
            for point in curve.keyframe_points:
                point.interpolation = "LINEAR"
            curve.update()


def remove_scratch(scratch) -> None:
    data, action = scratch.data, scratch.animation_data and scratch.animation_data.action
    bpy.data.objects.remove(scratch, do_unlink=True)
    bpy.data.armatures.remove(data)
    if action is not None:
        bpy.data.actions.remove(action)


def restyle(
    context,
    obj,
    server: str,
    style_name: str,
    strength: float,
    api_key: str = "",
    keep_timing: bool = False,
):
    """The new action, named after the original and the style (assigned to ``obj``; the
    original is kept with a fake user), and the service's warnings; ``keep_timing``: as many
    frames as the original."""
    original = obj.animation_data.action
    start, _ = action_frames(obj)
    frame = context.scene.frame_current
    active, selected = context.view_layer.objects.active, list(context.selected_objects)
    with tempfile.TemporaryDirectory(prefix="motion-style-") as folder:
        sent, answer = os.path.join(folder, "content.bvh"), os.path.join(folder, "result.bvh")
        export_bvh(context, obj, sent)
        with open(sent, "rb") as f:
            result = service.transfer(
                server, f.read(), style_name, strength, api_key, keep_timing=keep_timing
            )
        with open(answer, "wb") as f:
            f.write(result.bvh)
        frames = frames_in(result.bvh)
        scratch = import_bvh(context, answer, start)
    try:
        action = bake(context, scratch, obj, f"{original.name}.{style_name}", start, frames)
    finally:
        remove_scratch(scratch)
        for o in context.view_layer.objects:
            o.select_set(o in selected)
        context.view_layer.objects.active = active
        context.scene.frame_set(frame)
    original.use_fake_user = True  # kept although no object uses it now
    obj.animation_data.action = action
    return action, result.warnings


def frames_in(bvh: bytes) -> int:
    """The BVH answer's frame count (its ``Frames:`` line)."""
    for line in bvh.decode("utf-8", "replace").splitlines():
        if line.strip().lower().startswith("frames"):
            return int(line.split(":")[1])
    raise service.ServiceError("the service's answer has no 'Frames:' line")

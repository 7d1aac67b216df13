"""The Blender side of FBX in and out: runs in a worker process of :mod:`service.fbx`'s
pool, never in the service's own process (bpy is neither thread-safe nor re-entrant).

``serve(connection)`` answers requests ``(op, kwargs)`` with ``("ok", value)`` or
``("error", kind, message)`` (a :class:`~motion.errors.MotionError`'s kind):

- ``read(data, max_frames, rest_if_unanimated)``: Blender's FBX importer reads the file;
  the armature (the animated one, else the one with most bones), its rest pose, and every
  frame of its action evaluated by Blender (constraints and all) as armature-space bone
  matrices, with the object's world matrix per frame; frames counted before sampling.
- ``write(data, location, rotation, fps)``: the file with a new action on its armature
  (each bone's ``matrix_basis``: location and quaternion, from :func:`motion.armature.to_basis`)
  exported by Blender's FBX exporter: meshes, materials, skin, bone names (no leaf bones
  added) and the other objects as the importer read them, textures embedded.

The worker keeps the last file it imported (by its SHA-256), so writing the answer to a
file it has just read does not import it again.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import signal
import sys
import tempfile
import traceback

import numpy as np

from motion.errors import MotionError

FBX_MAGIC = b"Kaydara FBX Binary  \x00"


class _State:
    digest: str | None = None
    armature = None  # the bpy object
    action = None  # its action as imported
    fps: tuple[int, float] = (24, 1.0)
    frame_range: tuple[int, int] = (1, 1)
    styled = None  # the action last written


def _bpy():
    import bpy

    return bpy


def _clear() -> None:
    bpy = _bpy()
    data = bpy.data
    ids = [
        item
        for collection in (
            data.objects,
            data.meshes,
            data.armatures,
            data.materials,
            data.actions,
            data.images,
            data.textures,
            data.node_groups,
            data.collections,
            data.cameras,
            data.lights,
            data.curves,
            data.lattices,
            data.shape_keys,
        )  # fmt: skip
        for item in collection
    ]
    data.batch_remove(ids)
    _State.digest = _State.armature = _State.action = _State.styled = None


def _import(data: bytes) -> None:
    """Import ``data`` unless it is the file already in the scene; either way, leave the
    armature with its own action, the scene at the file's frame rate."""
    bpy = _bpy()
    digest = hashlib.sha256(data).hexdigest()
    if digest != _State.digest:
        if not data.startswith(FBX_MAGIC):
            raise MotionError(
                "not a binary FBX file (Blender reads binary FBX 7.1 and later; an ASCII "
                "FBX must be saved as binary first)"
            )
        _clear()
        scene = bpy.context.scene
        scene.render.fps, scene.render.fps_base = 24, 1.0
        with tempfile.TemporaryDirectory(prefix="motion-fbx-") as folder:
            path = os.path.join(folder, "upload.fbx")
            with open(path, "wb") as f:
                f.write(data)
            try:
                result = bpy.ops.import_scene.fbx(filepath=path, use_image_search=False)
            except Exception as exc:  # the importer raises whatever it meets
                reason = _reason(exc).replace(f"{path!r}", "").replace(path, "").strip()
                raise MotionError(f"Blender could not read the FBX file: {reason}") from None
        if "FINISHED" not in result:
            raise MotionError("Blender could not read the FBX file")
        armatures = [o for o in scene.objects if o.type == "ARMATURE" and o.data.bones]
        if not armatures:
            raise MotionError("the FBX file has no armature (skeleton) with bones", kind="unusable")
        _State.armature = max(armatures, key=lambda o: (_action(o) is not None, len(o.data.bones)))
        _State.action = _action(_State.armature)
        _State.fps = (scene.render.fps, scene.render.fps_base)
        _State.digest = digest
        if _State.action is not None:
            start, end = _State.action.frame_range
            _State.frame_range = (round(start), max(round(end), round(start)))
    scene = bpy.context.scene
    scene.render.fps, scene.render.fps_base = _State.fps
    if _State.armature.animation_data is not None:
        _State.armature.animation_data.action = _State.action
    if _State.styled is not None:
        bpy.data.actions.remove(_State.styled)
        _State.styled = None


def _action(obj):
    return obj.animation_data.action if obj.animation_data is not None else None


def _reason(exc: Exception) -> str:
    text = str(exc).strip().splitlines()
    return (text[-1] if text else type(exc).__name__)[:200]


def _bones_parents_first(arm) -> list:
    bones = list(arm.data.bones)
    order: list = []
    stack = [b for b in reversed(bones) if b.parent is None]
    while stack:
        bone = stack.pop()
        order.append(bone)
        stack.extend(reversed(bone.children))
    return order


def _matrix(m) -> np.ndarray:
    return np.array([list(row) for row in m], dtype=np.float64)


def read(data: bytes, max_frames: int, rest_if_unanimated: bool = False) -> dict:
    bpy = _bpy()
    _import(data)
    arm = _State.armature
    scene = bpy.context.scene
    bones = _bones_parents_first(arm)
    index = {b.name: k for k, b in enumerate(bones)}
    armature = {
        "name": arm.name,
        "names": tuple(b.name for b in bones),
        "parents": [index[b.parent.name] if b.parent else -1 for b in bones],
        "rest": np.array([_matrix(b.matrix_local) for b in bones]),
        "tails": np.array([list(b.tail_local) for b in bones]),
    }
    fps = scene.render.fps / scene.render.fps_base
    if _State.action is None:
        if not rest_if_unanimated:
            raise MotionError("the FBX file has no animation of its armature", kind="unusable")
        armature["matrix_world"] = _matrix(arm.matrix_world)
        rest = armature["rest"][None].astype(np.float32)
        return {"armature": armature, "bones": rest, "objects": None, "fps": fps, "animated": False}
    start, end = _State.frame_range
    frames = end - start + 1
    if frames > max_frames:
        raise MotionError(
            f"the FBX animation has {frames} frames, over the limit of {max_frames}",
            kind="too-large",
        )
    pose = arm.pose.bones
    order = np.array([pose.find(b.name) for b in bones])
    # the other objects need not deform while the armature's frames are sampled
    hidden = [o for o in scene.objects if o is not arm and not o.hide_viewport]
    for o in hidden:
        o.hide_viewport = True
    matrices = np.empty((frames, len(pose), 16), dtype=np.float32)
    objects = np.empty((frames, 16), dtype=np.float32)
    try:
        for k in range(frames):
            scene.frame_set(start + k)
            pose.foreach_get("matrix", matrices[k].ravel())
            objects[k] = np.array(arm.matrix_world, dtype=np.float32).T.ravel()
    finally:
        for o in hidden:
            o.hide_viewport = False
    # foreach_get gives each matrix column by column
    matrices = matrices.reshape(frames, len(pose), 4, 4).transpose(0, 1, 3, 2)[:, order]
    objects = objects.reshape(frames, 4, 4).transpose(0, 2, 1)
    armature["matrix_world"] = objects[0].astype(np.float64)
    moved = np.abs(objects - objects[:1]).max() > 1e-6 * max(np.abs(objects[0]).max(), 1.0)
    return {
        "armature": armature,
        "bones": matrices,
        "objects": objects if moved else None,
        "fps": fps,
        "animated": True,
    }


def write(data: bytes, location: np.ndarray, rotation: np.ndarray, fps: float) -> bytes:
    """``data`` with the armature keyed to ``location`` (F, J, 3) and ``rotation`` (F, J, 4,
    w first), one key a frame from the file's first frame, at ``fps``."""
    bpy = _bpy()
    _import(data)
    arm = _State.armature
    scene = bpy.context.scene
    bones = _bones_parents_first(arm)
    frames = int(location.shape[0])
    start = _State.frame_range[0] if _State.action is not None else 1
    if abs(fps - scene.render.fps / scene.render.fps_base) > 1e-6:
        scene.render.fps = max(1, round(fps))
        scene.render.fps_base = scene.render.fps / fps
    action = bpy.data.actions.new(name=(_State.action.name if _State.action else arm.name))
    _State.styled = action
    times = start + np.arange(frames, dtype=np.float32)
    for k, bone in enumerate(bones):
        pose_bone = arm.pose.bones[bone.name]
        pose_bone.rotation_mode = "QUATERNION"
        pose_bone.scale = (1.0, 1.0, 1.0)
        for path, values in (("location", location[:, k]), ("rotation_quaternion", rotation[:, k])):
            for i in range(values.shape[1]):
                curve = action.fcurves.new(
                    f'pose.bones["{_escape(bone.name)}"].{path}', index=i, action_group=bone.name
                )
                curve.keyframe_points.add(frames)
                co = np.empty(2 * frames, dtype=np.float32)
                co[0::2], co[1::2] = times, values[:, i]
                curve.keyframe_points.foreach_set("co", co)
                curve.keyframe_points.foreach_set(
                    "interpolation", np.full(frames, _LINEAR, dtype=np.int32)
                )
                curve.update()
    if arm.animation_data is None:
        arm.animation_data_create()
    matrix_world = arm.matrix_world.copy()
    arm.animation_data.action = action
    arm.matrix_world = matrix_world  # the object's own keys (if any) are now in the bones'
    scene.frame_start, scene.frame_end = start, start + frames - 1
    # the exporter samples every frame: meshes need not be deformed meanwhile (their skin is
    # exported from the armature modifier all the same)
    modifiers = [
        m
        for o in scene.objects
        for m in getattr(o, "modifiers", ())
        if m.type == "ARMATURE" and m.show_viewport
    ]
    for m in modifiers:
        m.show_viewport = False
    try:
        with (
            tempfile.TemporaryDirectory(prefix="motion-fbx-") as folder,
            _bones_baked_from(arm, _fbx_locals(bones, location, rotation), start),
        ):
            path = os.path.join(folder, "answer.fbx")
            bpy.ops.export_scene.fbx(
                filepath=path,
                add_leaf_bones=False,  # the file's own leaf bones are bones already
                bake_anim=True,
                bake_anim_use_all_actions=False,
                bake_anim_use_nla_strips=False,
                bake_anim_force_startend_keying=True,
                path_mode="COPY",
                embed_textures=True,
            )
            with open(path, "rb") as f:
                return f.read()
    finally:
        for m in modifiers:
            m.show_viewport = True


_LINEAR = 1  # KeyframePoint.interpolation: CONSTANT, LINEAR, BEZIER, ...


def _fbx_locals(bones, location: np.ndarray, rotation: np.ndarray) -> dict[str, tuple]:
    """Each bone's transform in its FBX parent's space, frame by frame, as Blender's exporter
    computes it (``parent_pose^-1 @ pose``, with the bone axes it keeps by default), from the
    keyed ``matrix_basis``: ``parent_rest^-1 @ rest @ basis``. Name -> (location (F, 3),
    XYZ Euler angles in radians, continuous from frame to frame (F, 3))."""
    from scipy.spatial.transform import Rotation

    rest = np.array([_matrix(b.matrix_local) for b in bones])
    index = {b.name: k for k, b in enumerate(bones)}
    relative = rest.copy()
    for k, bone in enumerate(bones):
        if bone.parent is not None:
            relative[k] = np.linalg.inv(rest[index[bone.parent.name]]) @ rest[k]
    frames = location.shape[0]
    basis = np.zeros((frames, len(bones), 4, 4))
    basis[..., :3, :3] = (
        Rotation.from_quat(rotation[..., [1, 2, 3, 0]].reshape(-1, 4))
        .as_matrix()
        .reshape(frames, len(bones), 3, 3)
    )
    basis[..., :3, 3] = location
    basis[..., 3, 3] = 1.0
    local = relative[None] @ basis
    euler = Rotation.from_matrix(local[..., :3, :3].reshape(-1, 3, 3)).as_euler("xyz")
    euler = np.unwrap(euler.reshape(frames, len(bones), 3), axis=0)
    return {b.name: (local[:, k, :3, 3], euler[:, k]) for k, b in enumerate(bones)}


@contextlib.contextmanager
def _bones_baked_from(arm, values: dict[str, tuple], start: int):
    """While the exporter bakes the animation, it takes the armature's bone transforms from
    ``values`` (frames from ``start``) instead of evaluating each bone of each frame in
    Python: the same numbers (the action keyed from them is what Blender would evaluate),
    a fraction of the time. Other objects, and bones of other frames, go the exporter's
    own way; with a bone axis correction (not this exporter's default) nothing is replaced."""
    from io_scene_fbx import export_fbx_bin, fbx_utils
    from mathutils import Euler, Vector

    bpy = _bpy()
    scene = bpy.context.scene
    wrapper = fbx_utils.ObjectWrapper
    own_tx, own_bake = wrapper.fbx_object_tx, export_fbx_bin.fbx_animations_do
    baking = [False]

    def fbx_object_tx(self, scene_data, rest=False, rot_euler_compat=None):
        frame = scene.frame_current - start
        name = self.bdata.name if self._tag == "BO" and self._ref == arm else None
        if (
            not baking[0]
            or rest
            or name not in values
            or scene_data.settings.bone_correction_matrix is not None
            or not 0 <= frame < len(values[name][0])
        ):
            return own_tx(self, scene_data, rest=rest, rot_euler_compat=rot_euler_compat)
        loc, euler = values[name]
        rot = Euler(euler[frame], "XYZ")
        return Vector(loc[frame]), rot, Vector((1.0, 1.0, 1.0)), None, None

    def fbx_animations_do(*args, **kwargs):
        baking[0] = True
        try:
            return own_bake(*args, **kwargs)
        finally:
            baking[0] = False

    wrapper.fbx_object_tx, export_fbx_bin.fbx_animations_do = fbx_object_tx, fbx_animations_do
    try:
        yield
    finally:
        wrapper.fbx_object_tx, export_fbx_bin.fbx_animations_do = own_tx, own_bake


def _escape(name: str) -> str:
    return name.replace("\\", "\\\\").replace('"', '\\"')


OPERATIONS = {"read": read, "write": write}


def serve(connection) -> None:
    """Answer requests on ``connection`` until it closes. Blender's own output (its
    importer's and exporter's progress lines) goes to /dev/null."""
    # Ctrl-C in a terminal reaches the whole process group: the worker ends when the service
    # closes its connection instead, so a request in flight during a shutdown still finishes
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 1)
    os.dup2(devnull, 2)
    import bpy  # noqa: F401  (loaded before the first request)
    import io_scene_fbx.export_fbx_bin  # noqa: F401
    import io_scene_fbx.import_fbx  # noqa: F401

    connection.send(("ready",))
    while True:
        try:
            op, kwargs = connection.recv()
        except (EOFError, OSError):
            return
        try:
            connection.send(("ok", OPERATIONS[op](**kwargs)))
        except MotionError as exc:
            connection.send(("error", exc.kind, exc.message))
        except Exception as exc:  # a file the importer or exporter cannot handle
            _clear()
            connection.send(
                ("error", "invalid", f"Blender could not process the FBX file: {_reason(exc)}")
            )
            traceback.clear_frames(exc.__traceback__)


def main() -> None:
    """``python -m service.fbx_worker FD``: serve on the socket inherited as file ``FD``."""
    from multiprocessing.connection import Connection

    serve(Connection(int(sys.argv[1])))
    os._exit(0)  # not bpy's teardown, which can crash (nothing is left to save)


if __name__ == "__main__":
    main()

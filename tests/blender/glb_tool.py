"""Run inside Blender (``blender -b --factory-startup --python glb_tool.py -- COMMAND ...``):

    export IN.bvh OUT.glb [IN.bvh OUT.glb ...]   a skinned character (one triangle per bone,
                                                 a material) animated by each BVH, as GLB
    inspect IN.glb OUT.json [IN.glb OUT.json ...] what Blender's glTF importer reads: object
                                                 and bone names, actions and their frame ranges

Tests use it to make real GLB files and to check that Blender reads what we write.
"""

import builtins
import json
import sys

import bpy


def reset():
    bpy.ops.wm.read_factory_settings(use_empty=True)


def skinned_mesh(armature):
    """A mesh with one triangle per bone, each weighted fully to its bone, and a material."""
    verts, faces, groups = [], [], []
    for bone in armature.data.bones:
        head = armature.matrix_world @ bone.head_local
        tail = armature.matrix_world @ bone.tail_local
        side = (tail - head).orthogonal().normalized() * max((tail - head).length * 0.1, 1e-3)
        base = len(verts)
        verts += [head, tail, head + side]
        faces.append((base, base + 1, base + 2))
        groups.append(bone.name)
    mesh = bpy.data.meshes.new("Body")
    mesh.from_pydata([tuple(v) for v in verts], [], faces)
    body = bpy.data.objects.new("Body", mesh)
    bpy.context.scene.collection.objects.link(body)
    for k, name in enumerate(groups):
        group = body.vertex_groups.new(name=name)
        group.add([3 * k, 3 * k + 1, 3 * k + 2], 1.0, "REPLACE")
    modifier = body.modifiers.new("Armature", "ARMATURE")
    modifier.object = armature
    body.parent = armature
    material = bpy.data.materials.new("Skin")
    material.diffuse_color = (0.8, 0.5, 0.4, 1.0)
    mesh.materials.append(material)


def readable_bvh_importer():
    """Blender 3.4's BVH importer opens files with mode 'rU', which Python 3.11 (Debian's
    Blender) refuses; drop the 'U' (universal newlines are the default anyway)."""
    from io_anim_bvh import import_bvh

    def open_without_u(file, mode="r", *args, **kwargs):
        return builtins.open(file, mode.replace("U", ""), *args, **kwargs)

    import_bvh.open = open_without_u


def export(pairs):
    readable_bvh_importer()
    for bvh_path, glb_path in pairs:
        reset()
        bpy.ops.import_anim.bvh(
            filepath=bvh_path, update_scene_fps=True, update_scene_duration=True
        )
        armature = next(o for o in bpy.context.scene.objects if o.type == "ARMATURE")
        skinned_mesh(armature)
        bpy.ops.export_scene.gltf(filepath=glb_path, export_format="GLB", export_animations=True)


def importable_meshes():
    """Blender 3.4's glTF mesh importer uses ``np.bool``, which numpy 1.24 (Debian's)
    removed; give the alias back."""
    import numpy

    if not hasattr(numpy, "bool"):
        numpy.bool = bool


def inspect(pairs):
    importable_meshes()
    for glb_path, json_path in pairs:
        reset()
        bpy.ops.import_scene.gltf(filepath=glb_path)
        scene = bpy.context.scene
        armatures = [o for o in scene.objects if o.type == "ARMATURE"]
        report = {
            "objects": sorted(o.name for o in scene.objects),
            "meshes": sorted(o.name for o in scene.objects if o.type == "MESH"),
            "materials": sorted(m.name for m in bpy.data.materials),
            "bones": sorted(b.name for a in armatures for b in a.data.bones),
            "fps": scene.render.fps / scene.render.fps_base,
            "actions": {
                a.name: {"frame_range": list(a.frame_range), "curves": len(a.fcurves)}
                for a in bpy.data.actions
            },
        }
        with open(json_path, "w") as f:
            json.dump(report, f)


def main():
    args = sys.argv[sys.argv.index("--") + 1 :]
    command, rest = args[0], args[1:]
    pairs = list(zip(rest[::2], rest[1::2], strict=True))
    {"export": export, "inspect": inspect}[command](pairs)


main()

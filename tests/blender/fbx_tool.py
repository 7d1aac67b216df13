"""Run with Blender as a Python module (the ``fbx`` extra): ``python fbx_tool.py COMMAND ...``

    make IN.bvh FOLDER [SEGMENTS]   FOLDER/bare.fbx: the armature Blender imports from the
                                    BVH; FOLDER/character.fbx and FOLDER/character.glb: the
                                    same armature with a skinned body (a tube of SEGMENTS x
                                    SEGMENTS vertices around each bone, weighted to it) and a
                                    material, its animation kept; all exported by Blender
    inspect OUT.json IN.fbx ...     what Blender's FBX importer reads of each file: objects,
                                    meshes and their vertex counts, materials, armatures'
                                    bone names, frame rate, each action's frame range

Tests make their FBX files with it and read every answer back with it.
"""

import json
import math
import os
import sys

import bpy


def reset():
    bpy.ops.wm.read_factory_settings(use_empty=True)


def body(armature, segments):
    """A mesh of one tube per bone (``segments`` rings of ``segments`` vertices), each tube
    weighted fully to its bone, parented to the armature with an Armature modifier, and a
    material "Skin"."""
    verts, faces, groups = [], [], []
    for bone in armature.data.bones:
        head = armature.matrix_world @ bone.head_local
        tail = armature.matrix_world @ bone.tail_local
        axis = tail - head
        radius = max(axis.length * 0.15, 1e-2)
        side = axis.orthogonal().normalized() * radius
        other = axis.normalized().cross(side)
        base = len(verts)
        for ring in range(segments):
            centre = head + axis * (ring / max(segments - 1, 1))
            for k in range(segments):
                a = 2 * math.pi * k / segments
                verts.append(centre + side * math.cos(a) + other * math.sin(a))
        for ring in range(segments - 1):
            for k in range(segments):
                a = base + ring * segments + k
                b = base + ring * segments + (k + 1) % segments
                faces.append((a, b, b + segments, a + segments))
        groups.append((bone.name, range(base, len(verts))))
    mesh = bpy.data.meshes.new("Body")
    mesh.from_pydata([tuple(v) for v in verts], [], faces)
    obj = bpy.data.objects.new("Body", mesh)
    bpy.context.scene.collection.objects.link(obj)
    for name, indices in groups:
        obj.vertex_groups.new(name=name).add(list(indices), 1.0, "REPLACE")
    modifier = obj.modifiers.new("Armature", "ARMATURE")
    modifier.object = armature
    obj.parent = armature
    material = bpy.data.materials.new("Skin")
    material.diffuse_color = (0.8, 0.5, 0.4, 1.0)
    mesh.materials.append(material)


def make(bvh_path, folder, segments="4"):
    reset()
    bpy.ops.import_anim.bvh(filepath=bvh_path, update_scene_fps=True, update_scene_duration=True)
    armature = next(o for o in bpy.context.scene.objects if o.type == "ARMATURE")
    bpy.ops.export_scene.fbx(filepath=f"{folder}/bare.fbx", bake_anim=True)
    body(armature, int(segments))
    bpy.ops.export_scene.fbx(filepath=f"{folder}/character.fbx", bake_anim=True)
    bpy.ops.export_scene.gltf(
        filepath=f"{folder}/character.glb", export_format="GLB", export_animations=True
    )


def inspect(out_path, *paths):
    reports = []
    for path in paths:
        reset()
        bpy.ops.import_scene.fbx(filepath=path)
        scene = bpy.context.scene
        armatures = [o for o in scene.objects if o.type == "ARMATURE"]
        reports.append(
            {
                "objects": sorted(o.name for o in scene.objects),
                "meshes": {o.name: len(o.data.vertices) for o in scene.objects if o.type == "MESH"},
                "skinned": sorted(
                    o.name
                    for o in scene.objects
                    if o.type == "MESH" and any(m.type == "ARMATURE" for m in o.modifiers)
                ),
                "materials": sorted(m.name for m in bpy.data.materials),
                "bones": [b.name for a in armatures for b in a.data.bones],
                "fps": scene.render.fps / scene.render.fps_base,
                "actions": {
                    o.name: list(o.animation_data.action.frame_range)
                    for o in armatures
                    if o.animation_data and o.animation_data.action
                },
            }
        )
    with open(out_path, "w") as f:
        json.dump(reports, f)


def main():
    command, *args = sys.argv[1:]
    {"make": make, "inspect": inspect}[command](*args)


if __name__ == "__main__":
    main()
    sys.stdout.flush()
    os._exit(0)  # bpy 4.2 can crash while the interpreter tears down after a glTF export

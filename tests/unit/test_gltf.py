"""motion.gltf: glTF binary in and out.

Files made by code with pygltflib (rest rotations, frames above the rig, every
interpolation, broken files), and real GLBs that Blender exports from BVH clips: read,
they must move like the BVH did; written, three.js's GLTFLoader and Blender's importer
must read them with the same node names and the right duration.
"""

from __future__ import annotations

import dataclasses
import json
import subprocess
from pathlib import Path

import numpy as np
import pygltflib
import pytest

from motion import bvh, gltf, retarget
from motion import kinematics as K
from motion import rotations as R
from motion.errors import MotionError
from tests.conftest import DATA_DIR
from tests.gltf_files import (
    NODE_SCRIPT,
    blender_run,
    embedded_gltf_bytes,
    glb_bytes,
    rig_gltf,
    three_js_folder,
    three_js_name,
)
from tests.rigs import CMU_TO_MIXAMO, load_fixture, renamed


def quat_about(axis: str, degrees: float) -> np.ndarray:
    return R.from_euler(
        np.array(["XYZ".index(axis) == i and degrees or 0.0 for i in range(3)]), "XYZ"
    )


def walk_tracks(times: np.ndarray) -> dict:
    """Hips moving forward and turning, the head nodding (LINEAR)."""
    angles = np.linspace(0, 60, len(times))
    return {
        ("hips", "translation"): (times, np.stack([0 * times, 1 + 0 * times, times], 1), "LINEAR"),
        ("hips", "rotation"): (times, [quat_about("Y", a) for a in angles], "LINEAR"),
        ("head", "rotation"): (times, [quat_about("X", a / 3) for a in angles], "LINEAR"),
    }


def node_positions(doc: pygltflib.GLTF2, tracks: dict, time_index: int) -> dict[str, np.ndarray]:
    """World positions of the rig's nodes with ``tracks``' keys at one index, by plain
    matrices over the glTF node tree (independent of motion.gltf)."""

    def local(i):
        node = doc.nodes[i]
        t = np.array(node.translation or [0, 0, 0], float)
        q = np.array(node.rotation or [0, 0, 0, 1], float)
        s = np.array(node.scale or [1, 1, 1], float)
        for (joint, path), (_, values, _) in tracks.items():
            if joint == node.name:
                if path == "translation":
                    t = np.asarray(values[time_index], float)
                else:
                    q = np.asarray(values[time_index], float)
        m = np.eye(4)
        m[:3, :3] = R.to_matrix(q) * s
        m[:3, 3] = t
        return m

    out = {}

    def walk(i, parent):
        world = parent @ local(i)
        out[doc.nodes[i].name] = world[:3, 3]
        for c in doc.nodes[i].children or []:
            walk(c, world)

    walk(0, np.eye(4))
    return out


# --- files made by code ------------------------------------------------------------------


def test_rest_pose_reads_as_identity_rotations_with_world_offsets():
    times = np.arange(5) / 30
    m = gltf.loads(glb_bytes(rig_gltf(walk_tracks(times))))
    assert m.skeleton.names == ("hips", "spine", "head")
    assert list(m.skeleton.parents) == [-1, 0, 1]
    # the head hangs 0.4 along the spine node's -Z, which the spine's rest turns to +Y
    np.testing.assert_allclose(m.skeleton.offsets, [[0, 1, 0], [0, 0.3, 0], [0, 0.4, 0]], atol=1e-6)
    np.testing.assert_allclose(m.lrot[:, 1], np.tile([0, 0, 0, 1.0], (5, 1)), atol=1e-6)


@pytest.mark.parametrize(
    "rotation, scale",
    [
        ((0, 0, 0, 1), (1, 1, 1)),
        (tuple(R.from_euler(np.array([-90.0, 0, 0]), "XYZ")), (0.01, 0.01, 0.01)),  # Z-up, cm
        (tuple(R.from_euler(np.array([10.0, 70, -20]), "XYZ")), (2.0, 2.0, 2.0)),
    ],
)
def test_joint_positions_match_the_node_tree(rotation, scale):
    times = np.arange(7) / 30
    tracks = walk_tracks(times)
    doc = rig_gltf(tracks, armature_rotation=rotation, armature_scale=scale)
    m = gltf.loads(glb_bytes(doc))
    gpos = K.global_positions(m)
    for k in (0, 3, 6):
        expected = node_positions(doc, tracks, k)
        for j, name in enumerate(m.skeleton.names):
            np.testing.assert_allclose(gpos[k, j], expected[name], atol=1e-5, err_msg=name)


def test_rigid_frame_above_the_rig_round_trips():
    times = np.arange(9) / 30
    tracks = walk_tracks(times)
    z_up = tuple(R.from_euler(np.array([-90.0, 0, 0]), "XYZ"))
    data = glb_bytes(rig_gltf(tracks, armature_rotation=z_up, armature_scale=(0.01,) * 3))
    m = gltf.loads(data)
    out = gltf.dumps(data, m)
    doc = pygltflib.GLTF2.load_from_bytes(out)
    anim = doc.animations[0]
    by_target = {(doc.nodes[c.target.node].name, c.target.path): c.sampler for c in anim.channels}
    from motion.gltf_container import GltfDocument

    reader = GltfDocument(out)
    for key, (_, values, _) in tracks.items():
        written = reader.accessor(anim.samplers[by_target[key]].output, "test")
        if key[1] == "rotation":  # q and -q are one rotation
            written = written * np.sign(np.sum(written * np.asarray(values), axis=1))[:, None]
        np.testing.assert_allclose(written, values, atol=1e-5, err_msg=str(key))


def test_interpolations_are_sampled_as_the_spec_says():
    q0, q1 = quat_about("Y", 0), quat_about("Y", 90)
    tangent = np.array([0.0, 0.0, 3.0])
    # two keys 1 s apart at 10 fps; CUBICSPLINE values are (in-tangent, value, out-tangent)
    cubic = [tangent * 0, [0, 1, 0], tangent, tangent, [0, 1, 1], tangent * 0]
    doc = rig_gltf(
        {
            ("hips", "translation"): ([0.0, 1.0], cubic, "CUBICSPLINE"),
            ("hips", "rotation"): ([0.0, 0.5, 1.0], [q0, q1, q0], "LINEAR"),
            ("head", "rotation"): ([0.0, 0.6], [q0, q1], "STEP"),
            ("spine", "translation"): (np.arange(11) / 10, np.tile([0, 0.3, 0], (11, 1)), "LINEAR"),
        }
    )
    m = gltf.loads(glb_bytes(doc))
    assert m.fps == 10 and m.num_frames == 11
    u = np.arange(11) / 10
    hermite_z = (u**3 - 2 * u**2 + u) * 3 + (-2 * u**3 + 3 * u**2) * 1 + (u**3 - u**2) * 3
    np.testing.assert_allclose(m.lpos[:, 0, 2], hermite_z, atol=1e-6)
    yaw = np.degrees(R.to_euler(m.lrot[:, 0], "YXZ")[:, 0] * np.pi / 180)
    np.testing.assert_allclose(yaw[[0, 2, 5, 8, 10]], [0, 36, 90, 36, 0], atol=1e-4)
    # STEP holds each key until the next: the head turns 90 degrees at 0.6 s, not before
    grot = K.global_rotations(m)
    turned = R.angle(R.mul(R.inv(grot[:, 1]), grot[:, 2]))
    np.testing.assert_allclose(turned[:6], 0, atol=1e-5)
    np.testing.assert_allclose(turned[6:], np.pi / 2, atol=1e-5)


@pytest.mark.parametrize(
    "times, fps",
    [
        (np.arange(0, 49) / 24, 24.0),
        (np.array([0, 2, 3, 10]) / 30, 30.0),  # sparse keys on a 30 fps grid
        (np.array([0.0, 0.5, 0.54]), 50.0),
        (np.array([0.0, 0.1, 0.3337]), 30.0),  # no usual rate fits: the default
    ],
)
def test_frame_rate_comes_from_the_keyframe_times(times, fps):
    values = np.stack([0 * times, 1 + 0 * times, times], 1)
    m = gltf.loads(glb_bytes(rig_gltf({("hips", "translation"): (times, values, "LINEAR")})))
    assert m.fps == pytest.approx(fps)
    assert m.num_frames == round((times[-1] - times[0]) * fps) + 1


def test_embedded_gltf_reads_like_the_glb():
    doc = rig_gltf(walk_tracks(np.arange(6) / 30))
    a, b = gltf.loads(glb_bytes(doc)), gltf.loads(embedded_gltf_bytes(doc))
    np.testing.assert_array_equal(a.lrot, b.lrot)
    np.testing.assert_array_equal(a.lpos, b.lpos)
    assert gltf.is_gltf(embedded_gltf_bytes(doc)) and gltf.is_gltf(glb_bytes(doc))
    assert not gltf.is_gltf(load_fixture_bytes())


def load_fixture_bytes() -> bytes:
    from tests.rigs import FIXTURE

    return FIXTURE.read_bytes()


def test_writing_keeps_the_file_and_replaces_only_the_animation():
    doc = rig_gltf(walk_tracks(np.arange(6) / 30), extra_animation=True)
    data = glb_bytes(doc)
    m = gltf.loads(data)
    slower = K.resample(m, 12.0)
    out = gltf.dumps(data, slower)
    new = json.loads(pygltflib.GLTF2.load_from_bytes(out).gltf_to_json())
    old = json.loads(pygltflib.GLTF2.load_from_bytes(data).gltf_to_json())
    for field in ("nodes", "meshes", "skins", "materials", "scenes"):
        assert new[field] == old[field], field
    assert [a["name"] for a in new["animations"]] == ["Take", "Other"]
    assert new["animations"][1] == old["animations"][1]
    back = gltf.loads(out)
    assert back.fps == 12.0 and back.num_frames == slower.num_frames
    np.testing.assert_allclose(K.global_positions(back), K.global_positions(slower), atol=1e-5)
    # restyling the result again reuses the replaced animation's accessors: no growth
    again = gltf.dumps(out, back)
    assert len(pygltflib.GLTF2.load_from_bytes(again).accessors) == len(new["accessors"])
    assert len(again) == len(out)


def test_a_file_read_once_writes_like_dumps_any_number_of_times():
    data = glb_bytes(rig_gltf(walk_tracks(np.arange(8) / 30), extra_animation=True))
    parsed = gltf.read(data)
    np.testing.assert_array_equal(parsed.motion.lrot, gltf.loads(data).lrot)
    faster = parsed.motion.replace(fps=60.0)
    first = parsed.write(faster)
    assert first == gltf.dumps(data, faster)
    assert parsed.write(faster) == first  # writing left the parsed file as it was
    assert parsed.write(parsed.motion) == gltf.dumps(data, parsed.motion)


def test_a_rig_without_animation_reads_as_its_rest_pose_and_gets_one_written():
    data = glb_bytes(rig_gltf())
    with pytest.raises(MotionError, match="no animation"):
        gltf.loads(data)
    rest = gltf.loads(data, rest_if_unanimated=True)
    assert rest.num_frames == 1
    moving = rest.replace(
        lrot=np.repeat(rest.lrot, 30, axis=0), lpos=np.repeat(rest.lpos, 30, axis=0)
    )
    moving.lpos[:, 0, 2] = np.linspace(0, 1, 30)
    out = gltf.loads(gltf.dumps(data, moving))
    assert out.num_frames == 30 and out.fps == 30
    np.testing.assert_allclose(out.lpos[:, 0, 2], np.linspace(0, 1, 30), atol=1e-6)


def broken(kind: str) -> bytes:
    times = np.arange(4) / 30
    if kind == "no skin":
        return glb_bytes(rig_gltf(walk_tracks(times), skin=False))
    if kind == "interpolation":
        tracks = walk_tracks(times)
        t, v, _ = tracks["hips", "rotation"]
        tracks["hips", "rotation"] = (t, v, "SMOOTH")
        return glb_bytes(rig_gltf(tracks))
    if kind == "uneven scale":
        return glb_bytes(rig_gltf(walk_tracks(times), armature_scale=(1, 2, 1)))
    doc = rig_gltf(walk_tracks(times))
    if kind == "external buffer":
        doc.buffers[0].uri = "../../etc/passwd"
        return doc.gltf_to_json().encode()
    if kind == "accessor past its view":
        doc.accessors[-1].count = 1000
        return glb_bytes(doc)
    if kind == "missing sampler":
        doc.animations[0].channels[0].sampler = 7
        return glb_bytes(doc)
    if kind == "backwards times":
        tracks = walk_tracks(times[::-1].copy())
        return glb_bytes(rig_gltf(tracks))
    if kind == "truncated":
        return glb_bytes(doc)[:300]
    if kind == "not glTF":
        return b"glTF\x02\x00\x00\x00garbage" + bytes(range(256))
    if kind == "json garbage":
        return b'{"asset": {"version": "2.0"}, "nodes": 5}'
    if kind == "version 1":
        return b'{"asset": {"version": "1.0"}}'
    raise AssertionError(kind)


@pytest.mark.parametrize(
    "kind, message",
    [
        ("no skin", "no skin"),
        ("interpolation", "interpolation 'SMOOTH'"),
        ("uneven scale", "scaled unevenly"),
        ("external buffer", "external file"),
        ("accessor past its view", "runs past buffer view"),
        ("missing sampler", "sampler 7"),
        ("backwards times", "go backwards"),
        ("truncated", "not a readable glTF file"),
        ("not glTF", "not a readable glTF file"),
        ("json garbage", "not a readable glTF file"),
        ("version 1", "version 1.0"),
    ],
)
def test_broken_files_raise_one_error_naming_the_problem(kind, message):
    with pytest.raises(MotionError, match=message):
        gltf.loads(broken(kind))


def test_an_animation_over_the_frame_limit_is_refused_before_sampling():
    times = np.array([0.0, 1 / 30, 3600.0])  # an hour at 30 fps
    values = np.stack([0 * times, 1 + 0 * times, times], 1)
    data = glb_bytes(rig_gltf({("hips", "translation"): (times, values, "LINEAR")}))
    with pytest.raises(MotionError, match="over the limit of 20000") as info:
        gltf.loads(data, max_frames=20_000)
    assert info.value.kind == "too-large" and info.value.limit == 20_000


def test_writing_a_motion_of_another_rig_is_refused():
    data = glb_bytes(rig_gltf(walk_tracks(np.arange(4) / 30)))
    with pytest.raises(MotionError, match="not on the glTF file's rig"):
        gltf.dumps(data, load_fixture())


# --- real files exported by Blender ------------------------------------------------------


SHARED_CLIPS = {  # rotated joint frames and positions on every joint; DAZ; mixed orders
    "bandai": ("bandai", "dataset-1", "dataset-1_walk_normal_001.bvh"),
    "daz": ("cmu-dance-43", "05_11_pirouette.bvh"),
    "3dsmax": ("cmu-dance-3dsmax", "94_01_indian_dance.bvh"),
}


@pytest.fixture(scope="module")
def blender_files(tmp_path_factory) -> dict[str, tuple[Path, Path]]:
    """name -> (BVH, the GLB Blender exported from it): the CMU walk fixture, its Mixamo
    renaming and, where the shared data is there, :data:`SHARED_CLIPS`. One Blender run."""
    folder = tmp_path_factory.mktemp("blender-glb")
    walk = load_fixture().slice(0, 45)
    clips = {"cmu": walk, "mixamo": renamed(walk, CMU_TO_MIXAMO)}
    for name, parts in SHARED_CLIPS.items():
        if DATA_DIR.joinpath(*parts).exists():
            clips[name] = bvh.load(DATA_DIR.joinpath(*parts)).slice(0, 45)
    args, out = [], {}
    for name, clip in clips.items():
        bvh.save(clip, folder / f"{name}.bvh")
        args += [str(folder / f"{name}.bvh"), str(folder / f"{name}.glb")]
        out[name] = (folder / f"{name}.bvh", folder / f"{name}.glb")
    blender_run("export", *args)
    return out


@pytest.mark.parametrize("name", ["cmu", "mixamo", *SHARED_CLIPS])
def test_blender_glb_moves_like_its_bvh(blender_files, name):
    if name not in blender_files:
        pytest.skip(f"shared data not available at {DATA_DIR} (set MOTION_DATA_DIR)")
    bvh_path, glb_path = blender_files[name]
    source = bvh.load(bvh_path)
    m = gltf.load(glb_path)
    assert m.num_frames == source.num_frames and m.fps == pytest.approx(source.fps, rel=1e-3)
    assert set(source.skeleton.names) <= set(m.skeleton.names)
    idx = [m.skeleton.names.index(n) for n in source.skeleton.names]
    height = source.skeleton.height()
    err = np.abs(K.global_positions(m)[:, idx] - K.global_positions(source)).max()
    assert err < 1e-4 * height, err
    # the retargeting reads it as it reads the BVH less its End Sites (glTF has none: a
    # leaf joint ends at its node), giving the same canonical motion
    a = retarget.to_canonical(m)
    no_ends = source.replace(skeleton=dataclasses.replace(source.skeleton, end_sites={}))
    b = retarget.to_canonical(no_ends)
    assert np.abs(K.global_positions(a) - K.global_positions(b)).max() < 1e-3 * height


@pytest.fixture(scope="module")
def restyled(blender_files, tmp_path_factory) -> dict[str, tuple[Path, Path, gltf.Motion]]:
    """name -> (GLB from Blender, that GLB with a new motion written in, the motion): the
    clip resampled to 24 fps and shortened (a different length and rate from the file's)."""
    folder = tmp_path_factory.mktemp("written-glb")
    out = {}
    for name, (_, glb_path) in blender_files.items():
        m = gltf.load(glb_path)
        new = K.resample(m, 24.0).slice(0, 30)
        path = folder / f"{name}.glb"
        path.write_bytes(gltf.dumps(glb_path.read_bytes(), new))
        out[name] = (glb_path, path, new)
    return out


def test_three_js_reads_what_we_write(restyled):
    folder = three_js_folder()
    for name, (original, written, motion) in restyled.items():
        summaries = []
        for path in (original, written):
            result = subprocess.run(
                ["node", str(folder / NODE_SCRIPT.name), str(path)],
                capture_output=True, text=True, timeout=60, cwd=folder,
            )  # fmt: skip
            assert result.returncode == 0, result.stderr
            summaries.append(json.loads(result.stdout))
        before, after = summaries
        assert after["nodes"] == before["nodes"], name
        assert after["skinned"] == before["skinned"] and after["materials"] == before["materials"]
        assert [a["name"] for a in after["animations"]] == [a["name"] for a in before["animations"]]
        clip = after["animations"][0]
        start = _start_time(original)
        assert clip["duration"] == pytest.approx(start + (motion.num_frames - 1) / 24.0, abs=1e-4)
        assert clip["keys"] == motion.num_frames
        joints = {t.rsplit(".", 1)[0] for t in clip["tracks"]}
        assert joints == {three_js_name(n) for n in motion.skeleton.names}
        assert joints <= set(after["nodes"])


def _start_time(path: Path) -> float:
    doc = pygltflib.GLTF2.load_from_bytes(path.read_bytes())
    return min(doc.accessors[s.input].min[0] for s in doc.animations[0].samplers)


def test_blender_reads_what_we_write(restyled, tmp_path):
    args = []
    for name, (original, written, _) in restyled.items():
        args += [str(original), str(tmp_path / f"{name}.in.json")]
        args += [str(written), str(tmp_path / f"{name}.out.json")]
    blender_run("inspect", *args)
    for name, (_, _, motion) in restyled.items():
        before = json.loads((tmp_path / f"{name}.in.json").read_text())
        after = json.loads((tmp_path / f"{name}.out.json").read_text())
        for field in ("objects", "meshes", "materials", "bones"):
            assert after[field] == before[field], (name, field)
        assert set(motion.skeleton.names) <= set(after["bones"])
        (action,) = after["actions"].values()
        first, last = action["frame_range"]
        assert (last - first) / after["fps"] == pytest.approx(
            (motion.num_frames - 1) / 24, abs=1e-3
        )

"""BVH reading and writing: real files, exporter-style variants, a malformed corpus."""

from __future__ import annotations

import io
import tarfile

import numpy as np
import pytest

from motion import bvh, bvh_kernels
from motion import rotations as rot
from motion.errors import MotionError
from tests import rigs
from tests.conftest import DATA_DIR, data_path


def shared_bvh_files() -> list:
    if not DATA_DIR.exists():
        return []
    return sorted(DATA_DIR.rglob("*.bvh"))


def assert_same_motion(a, b, pos_tol: float = 1e-4) -> None:
    assert a.skeleton.names == b.skeleton.names
    np.testing.assert_array_equal(a.skeleton.parents, b.skeleton.parents)
    np.testing.assert_allclose(a.skeleton.offsets, b.skeleton.offsets, atol=1e-5)
    assert a.skeleton.channels == b.skeleton.channels
    assert set(a.skeleton.end_sites) == set(b.skeleton.end_sites)
    for j, offs in a.skeleton.end_sites.items():
        np.testing.assert_allclose(offs, b.skeleton.end_sites[j], atol=1e-5)
    assert a.num_frames == b.num_frames
    assert abs(1 / a.fps - 1 / b.fps) < 1e-7
    # same rotation: |<qa, qb>| == 1 (q and -q are one rotation)
    dot = np.abs(np.sum(a.lrot * b.lrot, axis=-1))
    assert np.all(dot > 1 - 1e-8), (
        f"rotation differs by {rot.angle(rot.mul(rot.inv(a.lrot), b.lrot)).max()} rad"
    )
    np.testing.assert_allclose(a.lpos, b.lpos, atol=pos_tol)


@pytest.mark.parametrize("path", shared_bvh_files(), ids=lambda p: p.name)
def test_every_shared_bvh_round_trips(path):
    m = bvh.load(path)
    assert m.num_frames > 0 and m.fps > 0
    assert_same_motion(m, bvh.loads(bvh.dumps(m)))


def test_bandai_dataset2_archive_round_trips():
    archive = data_path("bandai", "dataset-2", "dataset-2-subset.tar.xz")
    count = 0
    with tarfile.open(archive) as tar:
        for member in tar:
            if not member.name.endswith(".bvh"):
                continue
            m = bvh.loads(tar.extractfile(member).read())
            assert m.skeleton.num_joints == 22 and round(m.fps) == 30
            if count % 20 == 0:  # writing all 280 adds little over the plain files
                assert_same_motion(m, bvh.loads(bvh.dumps(m)))
            count += 1
    assert count == 280


def test_header_facts_of_shared_layouts():
    bandai = bvh.load(data_path("bandai", "dataset-1", "dataset-1_walk_normal_001.bvh"))
    assert bandai.skeleton.num_joints == 22
    assert all(len(c) == 6 for c in bandai.skeleton.channels)
    assert bandai.skeleton.rotation_order(5) == "ZXY"
    daz = bvh.load(data_path("cmu-dance-43", "05_20.bvh"))
    assert daz.skeleton.num_joints == 43
    assert daz.skeleton.rotation_order(0) == "ZYX" and daz.skeleton.rotation_order(1) == "ZXY"
    mixed = bvh.load(data_path("cmu-dance-3dsmax", "94_01_indian_dance.bvh"))
    orders = {mixed.skeleton.rotation_order(j) for j in range(mixed.skeleton.num_joints)}
    assert orders == {"ZYX", "ZXY"}
    assert round(mixed.fps) == 120 and mixed.num_frames == 3602


def test_position_channels_replace_offsets_on_bandai_root_travel():
    m = bvh.load(data_path("bandai", "dataset-1", "dataset-1_dash_normal_001.bvh"))
    root = m.lpos[:, 0]
    assert np.ptp(root[:, 2]) > 100  # joint_Root carries the forward travel in this clip


@pytest.mark.parametrize("name", list(rigs.variants(rigs.load_fixture())))
def test_exporter_variants_round_trip(name):
    m = rigs.variants(rigs.load_fixture())[name]
    text = bvh.dumps(m)
    assert_same_motion(m, bvh.loads(text))
    # tools send CRLF and tabs; some send spaces only
    assert_same_motion(m, bvh.loads(text.replace("\n", "\r\n").encode()))
    assert_same_motion(m, bvh.loads(text.replace("\t", "  ")))


def test_three_channel_and_six_channel_joints_mix():
    m = rigs.load_fixture()
    text = bvh.dumps(rigs.with_channels(m, "YXZ", positions_everywhere=True))
    six = bvh.loads(text)
    assert all(len(c) == 6 for c in six.skeleton.channels)
    three = bvh.loads(bvh.dumps(m))
    assert {len(c) for c in three.skeleton.channels} == {3, 6}


def test_names_with_spaces_and_colons_survive():
    m = rigs.renamed(rigs.load_fixture(), rigs.CMU_TO_BIPED)
    back = bvh.loads(bvh.dumps(m))
    assert "Bip01 L Thigh" in back.skeleton.names
    m = rigs.renamed(rigs.load_fixture(), rigs.CMU_TO_MIXAMO)
    assert "mixamorig:Hips" in bvh.loads(bvh.dumps(m)).skeleton.names


def test_save_and_load_files(tmp_path):
    m = rigs.load_fixture()
    bvh.save(m, tmp_path / "out.bvh")
    assert_same_motion(m, bvh.load(tmp_path / "out.bvh"))


GOOD = rigs.FIXTURE.read_text() if rigs.FIXTURE.exists() else ""


def _corrupt(old: str, new: str, count: int = 1) -> str:
    assert old in GOOD
    return GOOD.replace(old, new, count)


def _motion_line(i: int) -> int:
    lines = GOOD.splitlines()
    return lines.index("MOTION") + 4 + i  # 1-based line of frame i


MALFORMED = {
    "empty": ("", "HIERARCHY", None),
    "binary": ("\x00\x01\x02garbage", "binary", None),
    "not bvh": ("hello world\n", "HIERARCHY", 1),
    "no root name": ("HIERARCHY\nROOT\n{\n", "ROOT <name>", 2),
    "missing brace": (_corrupt("ROOT Hips\n{", "ROOT Hips\nOFFSET 0 0 0"), "expected '{'", 3),
    "bad offset": (_corrupt("OFFSET", "OFFSET 1 x", 1), "OFFSET", 4),
    "offset two numbers": (_corrupt("\tOFFSET ", "\tOFFSET 1 ", 1), "needs 3 numbers", 4),
    "bad channel": (_corrupt("Xrotation", "Wrotation", 1), "unknown channel", 5),
    "channel count": (_corrupt("CHANNELS 3", "CHANNELS 4", 1), "CHANNELS says 4", None),
    "truncated hierarchy": (GOOD[: GOOD.index("MOTION") - 40], "unexpected end of file", None),
    "no frames line": (_corrupt("Frames:", "Framez:"), "Frames", None),
    "frame time zero": (_corrupt("Frame Time:", "Frame Time: 0\nX:"), "frame time", None),
    "truncated data": (GOOD[: GOOD.rindex("\n", 0, len(GOOD) - 10)], None, None),
    "nan value": (None, "not finite", None),
    "word in data": (None, "not a number", None),
    "short row": (None, "values", None),
    "two roots": (
        GOOD.replace("MOTION", "ROOT Extra\n{\n}\nMOTION", 1),
        "more than one ROOT",
        None,
    ),
}


def _row_corrupted(kind: str) -> tuple[str, int]:
    lines = GOOD.splitlines()
    i = _motion_line(5) - 1
    vals = lines[i].split()
    if kind == "nan value":
        vals[7] = "nan"
    elif kind == "word in data":
        vals[7] = "abc"
    else:
        vals = vals[:-2]
    lines[i] = " ".join(vals)
    return "\n".join(lines) + "\n", i + 1


@pytest.mark.parametrize("case", list(MALFORMED))
def test_malformed_bvh_gets_a_clear_error(case):
    if not GOOD:
        pytest.skip("fixture missing")
    text, needle, line = MALFORMED[case]
    if text is None:
        text, line = _row_corrupted(case)
    with pytest.raises(MotionError) as err:
        bvh.loads(text)
    e = err.value
    assert e.kind == "invalid"
    if needle:
        assert needle.lower() in str(e).lower(), str(e)
    if line is not None:
        assert e.line == line, str(e)
        assert f"line {line}" in str(e)


def test_fewer_frames_than_declared_names_the_line():
    lines = GOOD.splitlines()
    text = "\n".join(lines[:-3]) + "\n"
    with pytest.raises(MotionError, match="header says 60"):
        bvh.loads(text)


def test_absurd_frame_count_in_header_is_not_trusted():
    text = GOOD.replace("Frames: 60", "Frames: 999999999")
    with pytest.raises(MotionError, match="header says 999999999"):
        bvh.loads(text)


def test_latin1_names_and_bom():
    text = GOOD.replace("Head", "Tête", 1)
    m = bvh.loads(b"\xef\xbb\xbf" + text.encode("latin-1"))
    assert "Tête" in m.skeleton.names


def test_writer_never_puts_offsets_into_position_channels_of_3ch_joints():
    m = rigs.load_fixture()
    out = bvh.loads(bvh.dumps(m))
    # only the root had positions; nothing else gained them
    assert [len(c) for c in out.skeleton.channels] == [len(c) for c in m.skeleton.channels]


def test_text_io_accepts_str_and_bytes():
    assert bvh.loads(GOOD).num_frames == bvh.loads(io.BytesIO(GOOD.encode()).read()).num_frames


def test_a_short_line_and_a_long_line_cannot_cancel_out():
    lines = GOOD.splitlines()
    i = _motion_line(5) - 1
    moved = lines[i].split()
    lines[i] = " ".join(moved[:-1])
    lines[i + 1] = lines[i + 1] + " " + moved[-1]
    with pytest.raises(MotionError) as err:
        bvh.loads("\n".join(lines) + "\n")
    assert err.value.line == i + 1 and "values" in str(err.value)


def test_numbers_glued_together_are_refused():
    lines = GOOD.splitlines()
    i = _motion_line(3) - 1
    vals = lines[i].split()
    lines[i] = " ".join(vals[:2]) + " 1.0-2.0 " + " ".join(vals[3:])
    with pytest.raises(MotionError) as err:
        bvh.loads("\n".join(lines) + "\n")
    assert err.value.line == i + 1


def test_fixed_point_writer_matches_printf():
    rng = np.random.default_rng(3)
    scale = rng.choice([1e-7, 1e-3, 1.0, 50.0, 1e4, 9e7], (200, 31))
    values = rng.standard_normal((200, 31)) * scale
    values[0, :8] = [0.0, -4e-7, 123456.5, 1000.0, 999.9999999, -100.0, -98765432109.25, 1e8]
    buf = io.StringIO()
    np.savetxt(buf, values, fmt="%.6f", delimiter=" ")
    want, got = buf.getvalue(), bvh.format_fixed(values)
    assert got.count("\n") == want.count("\n") == 200
    assert [len(line.split()) for line in got.splitlines()] == [31] * 200
    differ = [(a, b) for a, b in zip(want.split(), got.split(), strict=True) if a != b]
    # printf writes -0.000000 for tiny negatives; beyond 1e7 the scaled product may round
    # one unit of the sixth decimal the other way
    assert all(a == "-0.000000" and b == "0.000000" or abs(float(a) - float(b)) < 1.1e-6
               for a, b in differ)  # fmt: skip
    assert sum(a != "-0.000000" for a, _ in differ) < 0.01 * values.size


@pytest.mark.parametrize("order", ["XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX"])
def test_euler_conversions_agree_with_scipy(order):
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(4)
    e = rng.uniform(-180, 180, (500, 3))
    e[:20, 1] = 90.0  # gimbal lock
    e[20:40, 1] = -90.0
    q = rot.from_euler(e, order)
    np.testing.assert_allclose(q, Rotation.from_euler(order, e, degrees=True).as_quat(), atol=1e-12)
    back = rot.from_euler(rot.to_euler(q, order), order)
    assert np.all(np.abs(np.sum(back * q, axis=-1)) > 1 - 1e-12)
    np.testing.assert_allclose(
        rot.to_euler(q[40:], order), Rotation.from_quat(q[40:]).as_euler(order, degrees=True),
        atol=1e-8,
    )  # fmt: skip


def test_matrix_to_quaternion_agrees_with_scipy_near_every_axis():
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(5)
    q = rot.normalize(rng.standard_normal((2000, 4)))
    q[:4] = np.eye(4)  # 180-degree turns about x, y, z and the identity
    m = Rotation.from_quat(q).as_matrix()
    got = rot.from_matrix(m)
    assert np.all(np.abs(np.sum(got * q, axis=-1)) > 1 - 1e-12)
    np.testing.assert_allclose(rot.to_matrix(got), m, atol=1e-12)


def test_block_reader_equals_float_of_each_token():
    rng = np.random.default_rng(6)
    tokens = [f"{v:.6f}" for v in rng.standard_normal(3000) * rng.choice([1e-3, 1, 1e3], 3000)]
    tokens += [f"{v:g}" for v in rng.standard_normal(40) * 1e-5]  # Bandai writes 1.87007e-05
    tokens += ["0", "-0.000000", "+3.25", "1.", ".5", "-.5", "12345.6789012345", "123456789.123456789",
               "1E3", "007.50", "1_0", "0.1e-22", "3e8", "12345678901234567e-30"]  # fmt: skip
    block = (" ".join(tokens) + "\n").encode()
    got = bvh._read_block(block, len(tokens), first_line=1)[0]
    want = np.array([float(t) for t in tokens])
    assert got.tobytes() == want.tobytes()  # bit for bit, -0.0 included
    assert np.signbit(got[tokens.index("-0.000000")])


def test_block_reader_with_many_odd_tokens_equals_float():
    """Past bvh_kernels.MAX_SLOW tokens it leaves to float(), numpy's reader reads the block."""
    rng = np.random.default_rng(7)
    values = rng.standard_normal((bvh_kernels.MAX_SLOW // 3 + 10, 3))
    block = "".join(" ".join(repr(float(v)) for v in row) + "\n" for row in values).encode()
    got = bvh._read_block(block, 3, first_line=1)
    assert got.tobytes() == values.tobytes()


@pytest.mark.parametrize(
    ("block", "want"),
    [
        # CRLF, tabs, blank lines, exponents
        (b"1.5 -0 2e-06\r\n\n\t3 +4.25 -.5 \n", [[1.5, -0.0, 2e-06], [3, 4.25, -0.5]]),
        # a control byte separates numbers, as white space does
        (b"1.5 -0 2e-06\n3\x1c4.25 -.5\n", [[1.5, -0.0, 2e-06], [3, 4.25, -0.5]]),
        (b"1.5 -0 2e-06\n3 4.25\n", "line 10: frame has 2 values, the hierarchy needs 3"),
        (b"1.5 -0 2e-06 7\n3 4.25 1\n", "line 9: frame has 4 values, the hierarchy needs 3"),
        (b"1.5 -0 nan\n3 4.25 1\n", "line 9: a value is not finite"),
        (b"1.5 -0 1\n3 4.25.1 1\n", "line 10: a value is not a number"),
        (b"1.5 -0 1_0\n3 4.25 1\n", [[1.5, -0.0, 10.0], [3, 4.25, 1]]),  # as float() reads it
        (b"1.5 -0 1\n\n3 4.25 2e10\n", "line 11: a value is absurdly large"),
    ],
)
def test_block_reader_reads_or_names_the_line(block, want):
    try:
        got = bvh._read_block(block, 3, first_line=9)
    except MotionError as e:
        got = str(e)
    if isinstance(want, str):
        assert got == want
    else:
        assert got.tobytes() == np.array(want, dtype=np.float64).tobytes()

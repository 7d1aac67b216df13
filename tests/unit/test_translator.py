"""The translator's networks, its paired training data and its ONNX export (small networks
with random weights; the shipped model is tested through the API)."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from motion import canonical as C  # noqa: E402
from motion import features as Fe  # noqa: E402
from motion import kinematics as K  # noqa: E402
from motion.skeleton import Motion  # noqa: E402
from training.translator import pairs as P  # noqa: E402
from training.translator.networks import (  # noqa: E402
    RESTYLER_IN,
    NetworkConfig,
    Translator,
)

TINY = NetworkConfig(channels=16, dilations=[1, 2, 4], style_dim=8, style_channels=[8, 8, 8])


def stepping(frames: int = 120, period: float = 30.0, arm: float = 0.6) -> Motion:
    """A canonical clip whose legs and arms swing with ``period`` frames."""
    from motion import rotations as rot

    t = np.arange(frames)
    lrot = rot.identity((frames, len(C.JOINTS)))
    swing = 0.5 * np.sin(2 * np.pi * t / period)
    x_axis = np.array([1.0, 0.0, 0.0])
    for name, sign in (("UpperLeg_L", 1), ("UpperLeg_R", -1)):
        lrot[:, C.INDEX[name]] = rot.from_rotvec(sign * swing[:, None] * x_axis)
    for name, sign in (("UpperArm_L", -1), ("UpperArm_R", 1)):
        lrot[:, C.INDEX[name]] = rot.from_rotvec(sign * arm * swing[:, None] * x_axis)
    lpos = np.repeat(C.OFFSETS[None], frames, axis=0)
    lpos[:, 0] = 0.0
    lpos[:, 1] = [0.0, C.OFFSETS[1, 1], 0.0]
    lpos[:, 1, 2] = 0.03 * t
    return Motion(C.SKELETON, C.FPS, lrot, lpos)


def take_of(motion: Motion, name: str, style: int = 0, label: str = "walk") -> P.Take:
    enc = Fe.encode(motion)
    views = P.project_views(enc.gpos, np.random.default_rng(0), 1)
    return P.Take(name, enc.content, enc.style3d, views, style, label, False)


def test_alignment_finds_the_same_moment_in_a_slower_performance() -> None:
    fast = take_of(stepping(120, period=30.0), "fast")
    slow = take_of(stepping(200, period=45.0, arm=0.9), "slow", style=1)
    frames = P.align(fast, slow)
    assert frames is not None and frames.shape == (120,)
    assert np.all(np.diff(frames) >= 0)
    # the slow take is at phase t / 45 when the fast one is at t / 30, up to whole cycles
    phase_fast = (np.arange(120) / 30.0) % 1.0
    phase_slow = (frames / 45.0) % 1.0
    gap = np.abs((phase_fast - phase_slow + 0.5) % 1.0 - 0.5)
    assert np.median(gap[10:-10]) < 0.06


def test_alignment_refuses_a_target_too_short_to_cover_the_content() -> None:
    long = take_of(stepping(200), "long")
    short = take_of(stepping(60), "short")
    assert P.align(long, short) is None


def test_values_at_fractional_frames_are_interpolated() -> None:
    x = np.arange(10, dtype=np.float32)[:, None] * np.array([[1.0, 2.0]], dtype=np.float32)
    got = P.at_frames(x, np.array([0.0, 2.5, 9.0, 12.0]))
    np.testing.assert_allclose(got, [[0, 0], [2.5, 5.0], [9, 18], [9, 18]])


def test_a_mirrored_clip_swaps_sides_and_names_the_other_sided_action():
    from scipy.spatial.transform import Rotation

    from motion import canonical as C
    from motion import kinematics as K
    from training.data import Clip
    from training.translator.pairs import mirrored_clip

    frames = 5
    lrot = Rotation.random(frames * len(C.JOINTS), random_state=1).as_quat()
    root = np.random.default_rng(2).normal(scale=20.0, size=(frames, 3))
    wave = Clip(
        name="d_wave-left-hand_proud_001", dataset="d", take="d_wave-left-hand_proud_001",
        lrot=lrot.reshape(frames, -1, 4).astype(np.float32), root=root.astype(np.float32),
        style="proud", content="wave-left-hand",
    )  # fmt: skip
    mirror = mirrored_clip(wave)
    assert (mirror.style, mirror.content) == ("proud", "wave-right-hand")
    assert mirror.take == "d_wave-left-hand_proud_001~mirrored" != wave.take
    want = K.global_positions(wave.motion)[:, C.MIRROR_INDEX] * np.array([-1.0, 1.0, 1.0])
    np.testing.assert_allclose(K.global_positions(mirror.motion), want, atol=1e-3)
    bow = mirrored_clip(Clip(**{**wave.__dict__, "content": "bow"}))
    assert bow.content == "bow"  # an action without a side keeps its name


def test_pairs_draw_a_target_of_the_requested_action_in_another_take() -> None:
    rng = np.random.default_rng(0)
    takes = [
        take_of(stepping(120, period=30.0 + 3 * i), f"t{i}", style=i % 3, label=label)
        for i, label in enumerate(["walk", "walk", "walk", "run", "run", "run"])
    ]
    pairs = P.Pairs(takes, 64, rng)
    for _ in range(30):
        content, start, target, frames = pairs.draw_pair()
        assert content.label == target.label
        assert 0 <= start <= content.frames - 64 and frames.shape == (64,)
        assert frames.min() >= 0 and frames.max() <= target.frames - 1


def test_every_pair_lists_each_pair_draw_pair_can_draw_and_no_more() -> None:
    rng = np.random.default_rng(0)
    takes = [
        take_of(stepping(120, period=30.0 + 3 * i), f"t{i}", style=i % 3, label=label)
        for i, label in enumerate(["walk", "walk", "walk", "run", "run"])
    ]
    pairs = P.Pairs(takes, 64, rng)
    listed = {(a.name, b.name) for a, b in pairs.every_pair()}
    assert len(listed) == 3 * 2 + 2 * 1  # each take with every other take of its action
    drawn = set()
    for _ in range(200):
        content, _, target, _ = pairs.draw_pair()
        if content is not target:
            drawn.add((content.name, target.name))
    assert drawn == listed


def test_alignments_come_back_from_their_cache_file_as_saved(tmp_path) -> None:
    path = tmp_path / "alignments.npz"
    saved = {("a", "b"): np.array([0.0, 0.5, 2.0]), ("b", "a"): None, ("a", "c"): np.arange(4.0)}
    P.save_alignments(path, saved)
    loaded = P.load_alignments(path)
    assert loaded.keys() == saved.keys() and loaded["b", "a"] is None
    for key in (("a", "b"), ("a", "c")):
        np.testing.assert_array_equal(loaded[key], saved[key])
    assert [p.name for p in tmp_path.iterdir()] == ["alignments.npz"]  # no temporary file left


def test_the_restyler_starts_at_the_mean_pose() -> None:
    torch.manual_seed(0)
    net = Translator(TINY)
    out = net.restyler(torch.randn(2, RESTYLER_IN, 40), torch.randn(2, TINY.style_dim))
    assert out.shape == (2, Fe.OUTPUT_CHANNELS, 40)
    torch.testing.assert_close(out, torch.zeros_like(out))  # standardised: the data's mean


def test_a_restyled_frame_depends_only_on_frames_within_the_receptive_field() -> None:
    torch.manual_seed(0)
    net = Translator(TINY)
    torch.nn.init.normal_(net.restyler.last.weight, std=0.1)
    x = torch.randn(1, RESTYLER_IN, 120)
    code = torch.randn(1, TINY.style_dim)
    y = x.clone()
    y[..., 60] += 1.0
    changed = (net.restyler(y, code) - net.restyler(x, code)).abs().amax(dim=1)[0] > 0
    radius = TINY.receptive_field // 2
    assert changed[60]
    assert not changed[: 60 - radius].any() and not changed[60 + radius + 1 :].any()
    assert changed[60 - radius] or changed[60 + radius]


def test_style_codes_have_one_size_whatever_the_clip_length() -> None:
    net = Translator(TINY)
    for frames in (17, 64, 301):
        assert net.style3d(torch.randn(2, Fe.STYLE3D_CHANNELS, frames)).shape == (2, 8)
        assert net.style2d(torch.randn(1, Fe.STYLE2D_CHANNELS, frames)).shape == (1, 8)


def test_hips_relative_positions_match_numpy_forward_kinematics() -> None:
    from training.fk import RootLocalFK
    from training.translator.fit import hips_relative

    motion = stepping(20)
    enc = Fe.encode(motion)
    rot6 = torch.tensor(enc.content[:, : Fe.OUTPUT_CHANNELS].T[None])
    norm = {"out_mean": torch.zeros(Fe.OUTPUT_CHANNELS), "out_std": torch.ones(Fe.OUTPUT_CHANNELS)}
    got = hips_relative(rot6, norm, RootLocalFK())[0].numpy()
    gpos = K.global_positions(motion)
    face = Fe.facing(gpos)
    want = K.root_local(gpos[:, Fe.BODY], gpos[:, Fe.HIPS], face) / Fe.LEG
    want = want - want[:, :1]
    np.testing.assert_allclose(got, want, atol=1e-4)


def test_export_matches_torch(tmp_path) -> None:
    pytest.importorskip("onnxruntime")
    from model_export import translator as X

    torch.manual_seed(0)
    net = Translator(TINY)
    torch.nn.init.normal_(net.restyler.last.weight, std=0.1)
    paths = X.export_graphs(net, tmp_path)
    assert sorted(paths) == sorted(X.GRAPH_NAMES)
    figures = X.parity(net, paths, lengths=(31, 64), batches=(1, 2))
    assert all(f["max_abs"] < 1e-4 for f in figures.values())
    shapes = X.onnx_shapes(paths["restyler"])
    assert shapes["content"] == ["batch", RESTYLER_IN, "time"]
    assert shapes["output"] == ["batch", Fe.OUTPUT_CHANNELS, "time"]


def test_style_speeds_compare_styles_on_the_same_action() -> None:
    from model_export.translator import style_speeds

    speeds = style_speeds(
        {
            ("run", "slow"): [1.0],
            ("run", "quick"): [4.0],
            ("bow", "slow"): [0.25],
            ("bow", "quick"): [1.0],
            ("kick", "quick"): [9.0],
        }  # fmt: skip
    )
    assert speeds["quick"] == pytest.approx(2.0) and speeds["slow"] == pytest.approx(0.5)


def test_every_flag_of_the_committed_schedule_is_one_fit_reads() -> None:
    from training.translator import fit, schedule

    for stage in schedule.load_schedule():
        args, cfg = fit.parse_args(schedule.stage_argv(stage))
        for flag, value in stage["flags"].items():
            name = flag.replace("-", "_")
            read = args.channels if name == "channels" else getattr(cfg, name)
            assert read == value, (stage["name"], flag)

"""The translator's training draws: content-matched pairs of style windows."""

from __future__ import annotations

import numpy as np

from training.translator.data import EncodedClip, Sampler


def clip(style: int, label: str, frames: int = 40) -> EncodedClip:
    z = np.zeros((frames, 1), dtype=np.float32)
    return EncodedClip(z, z, z[None], style, f"{style}-{label}", label)


def sampler() -> Sampler:
    # style 0 walks and waves, style 1 walks and waves, style 2 only walks
    clips = [clip(0, "walk"), clip(0, "wave"), clip(1, "walk"), clip(1, "wave"), clip(2, "walk")]
    return Sampler(clips, length=32, rng=np.random.default_rng(0))


def test_other_style_performs_the_same_content_where_one_does():
    s = sampler()
    styles = np.array([0, 1] * 200)
    others = s.other_styles_performing(styles, ["wave", "wave"] * 200)
    assert (others == np.array([1, 0] * 200)).all()  # style 2 never waves
    walkers = s.other_styles_performing(np.zeros(400, dtype=int), ["walk"] * 400)
    assert set(walkers.tolist()) == {1, 2}
    # a content no other style performs: any other style
    lonely = s.other_styles_performing(np.full(400, 2), ["jump"] * 400)
    assert set(lonely.tolist()) == {0, 1}


def test_pick_takes_a_clip_of_the_label_and_falls_back_to_any_of_the_style():
    s = sampler()
    picked = s.pick(np.array([0, 1] * 100), ["wave"] * 200)
    assert {c.label for c, _ in picked} == {"wave"}
    assert all(0 <= start <= 40 - 32 for _, start in picked)
    fallback = s.pick(np.full(200, 2), ["wave"] * 200)
    assert {c.label for c, _ in fallback} == {"walk"}
    unmatched = s.pick(np.full(400, 0))
    assert {c.label for c, _ in unmatched} == {"walk", "wave"}


def test_style_that_never_performs_the_content_where_one_does_not():
    s = sampler()
    wavers = s.other_styles_not_performing(np.array([0, 1] * 200), ["wave", "wave"] * 200)
    assert set(wavers.tolist()) == {2}  # only style 2 never waves
    # every style walks: any other style
    walkers = s.other_styles_not_performing(np.zeros(400, dtype=int), ["walk"] * 400)
    assert set(walkers.tolist()) == {1, 2}
    # a content nobody performs: any other style
    jumpers = s.other_styles_not_performing(np.full(400, 2), ["jump"] * 400)
    assert set(jumpers.tolist()) == {0, 1}


def test_a_mirrored_clip_swaps_sides_and_names_the_other_sided_action():
    from scipy.spatial.transform import Rotation

    from motion import canonical as C
    from motion import kinematics as K
    from training.data import Clip
    from training.translator.data import mirrored_clip

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

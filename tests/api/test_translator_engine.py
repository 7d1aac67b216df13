"""The translator's engine without HTTP, on the SHIPPED translator (``models/translator``):
windows, padding and blending, the core's output, and how far out each code plays."""

from __future__ import annotations

import numpy as np
import pytest

from motion import bvh, retarget
from motion import features as Fe
from motion import kinematics as K
from service.config import Settings
from service.engines.restyling import BUCKET, pad_mirrored, padded_length
from service.engines.translator import (
    StyleCodeJob,
    TransferJob,
    TranslatorEngine,
    window_starts,
)
from service.errors import InvalidRequest
from service.metrics import StageTimer
from service.requests import StyleCode
from service.routes.fields import parse_mix
from tests.api.translator_helpers import (
    ENTRY,
    STYLES,
    needs_model,
)


def restyle(engine, content, style, **options):
    """The translator's core on canonical ``content`` in ``style`` (a code, a clip or
    keypoints): the canonical motion it returns."""
    return engine.predict(TransferJob(content, style, **options), StageTimer(engine.name)).motion


def test_padding_buckets_and_mirroring():
    assert padded_length(1, 65) == 2 * BUCKET
    assert padded_length(60, 65) == 2 * BUCKET and padded_length(129, 65) == 3 * BUCKET
    assert padded_length(3 * BUCKET, 65) == 3 * BUCKET
    x = np.arange(10, dtype=np.float32)[:, None]
    padded, offset = pad_mirrored(x, 64)
    assert padded.shape == (64, 1)
    np.testing.assert_array_equal(padded[offset : offset + 10], x)
    short, offset = pad_mirrored(x[:3], 128)  # far shorter than the pad: still mirrored
    assert short.shape == (128, 1) and set(short[:, 0]) == {0.0, 1.0, 2.0}
    np.testing.assert_array_equal(short[offset : offset + 3], x[:3])


WINDOW = 64  # the shipped restyler's training length (its bundle's extra.window)


@pytest.mark.parametrize("frames", [WINDOW, WINDOW + 1, 2 * WINDOW, 5 * WINDOW + 7])
def test_windows_cover_every_frame(frames):
    starts = window_starts(frames, WINDOW)
    assert starts[0] == 0 and starts[-1] == frames - WINDOW
    assert all(0 < b - a <= WINDOW // 2 for a, b in zip(starts, starts[1:], strict=False))
    covered = np.zeros(frames, dtype=int)
    for s in starts:
        covered[s : s + WINDOW] += 1
    assert covered.min() >= 1


@pytest.mark.parametrize("window", [32, WINDOW])
def test_blending_windows_of_one_signal_gives_it_back(window):
    frames = 3 * window + 5
    signal = np.random.default_rng(0).normal(size=(frames, 4)).astype(np.float32)
    windows, offset, length = TranslatorEngine._windows(signal, window)
    assert offset == 0 and length == frames and windows.shape[1:] == (4, window)
    assert len(windows) == len(window_starts(frames, window, window // 2))
    np.testing.assert_allclose(TranslatorEngine._blend(windows, length), signal, atol=1e-6)
    short, offset, length = TranslatorEngine._windows(signal[:5], window)  # mirrored to one
    assert short.shape == (1, 4, window) and length == window
    np.testing.assert_array_equal(short[0, :, offset : offset + 5], signal[:5].T)


def test_velocity_factor_from_an_encoding_is_the_features_one(walk):
    canon = retarget.to_canonical(bvh.loads(walk))
    assert Fe.encoded_velocity_factor(Fe.encode(canon)) == pytest.approx(
        Fe.velocity_factor(canon), 1e-12
    )


def test_parse_mix():
    assert parse_mix('{"happy": 2, "old": 0}') == {"happy": 2.0, "old": 0.0}
    for bad in ("{not json", "[1]", "{}", '{"a": -1}', '{"a": "x"}', '{"a": true}',
                '{"a": 0, "b": 0}', '{"a": NaN}', '{"a": 1e999}'):  # fmt: skip
        with pytest.raises(InvalidRequest):
            parse_mix(bad)


@pytest.fixture(scope="module")
def engine() -> TranslatorEngine:
    """The shipped translator's engine, loaded as the service loads it."""
    from service.manifest import load_manifest

    settings = Settings()
    entry = next(m for m in load_manifest(settings.models_dir[0]).models if m.name == ENTRY["name"])
    engine = TranslatorEngine(entry, settings.models_dir[0], settings)
    engine.load()
    return engine


@needs_model
def test_decoder_jitter_is_smoothed_away(engine, walk):
    """The decoder adds frame-to-frame jitter (2.9x the content's unsmoothed on this walk,
    4.7x when whole clips ran through it); the output smoothing brings it near real
    motion's (0.8x)."""
    content = retarget.to_canonical(bvh.loads(walk))

    def jitter(motion) -> float:  # cm per frame^2 of the joints around the hips
        g = K.global_positions(motion)
        return float(np.linalg.norm(np.diff(g[:, 1:] - g[:, 1:2], 2, axis=0), axis=-1).mean())

    ratios = []
    for name in STYLES:
        out = restyle(engine, content, engine.code_of_name(name), time_warp=False)
        ratios.append(jitter(out) / jitter(content))
    assert np.mean(ratios) < 2.0, np.round(ratios, 2)


@needs_model
def test_a_frame_depends_on_nearby_frames_only(engine, walk):
    """The networks run on training-length windows: frames appended far after a frame
    leave it as it was (a whole clip at once renormalised every frame by all the others)."""

    def there_and_back(x: np.ndarray) -> np.ndarray:  # the walk, then backwards, then again
        return np.concatenate([x, x[::-1], x])

    walk = retarget.to_canonical(bvh.loads(walk))
    content = walk.replace(lrot=there_and_back(walk.lrot), lpos=there_and_back(walk.lpos))
    longer = content.replace(lrot=there_and_back(content.lrot), lpos=there_and_back(content.lpos))
    code = engine.code_of_name(STYLES[0])
    # frames before the clip's last window, less the output smoothing's reach (4 sigma)
    kept = window_starts(content.num_frames, WINDOW)[-1] - int(4 * engine.output_smoothing)
    assert kept >= WINDOW // 2
    a = restyle(engine, content, code, time_warp=False, foot_cleanup=False)
    b = restyle(engine, longer, code, time_warp=False, foot_cleanup=False)
    np.testing.assert_allclose(b.lrot[:kept], a.lrot[:kept], atol=1e-4)


@needs_model
@pytest.mark.parametrize("example", ["clip", "video"])
def test_a_style_clip_or_video_plays_its_code_taken_out_as_names_are(engine, walk, example):
    """A style clip's or video's code as the encoder gives it (what ``/v1/style-code``
    reports) plays the manifest's ``clip_style_gain`` or ``video_style_gain`` times as far
    from the centre of the learned codes, as a name's is taken out: the restyler decodes
    that code, not the encoded one."""
    content = retarget.to_canonical(bvh.loads(walk))
    style = content.replace(lrot=content.lrot[::-1].copy(), lpos=content.lpos[::-1].copy())
    kp = Fe.keypoints_of_positions(K.global_positions(style), yaw=0.6)
    example, source, gain_name = {
        "clip": (style, "style", "clip"),
        "video": (kp, "keypoints", "video"),
    }[example]
    gain = engine.example_gains[source]
    assert gain == ENTRY["extra"][f"{gain_name}_style_gain"]
    encoded = engine.predict(StyleCodeJob(example), StageTimer(engine.name))
    assert encoded.source == source and gain > 1
    centre = engine.codes.mean(axis=0)
    taken_out = (centre + gain * (encoded.code - centre)).astype(np.float32)
    options = {"time_warp": False, "foot_cleanup": False}
    played = restyle(engine, content, example, **options)
    as_taken_out = restyle(engine, content, StyleCode(taken_out, None, "code"), **options)
    as_encoded = restyle(engine, content, StyleCode(encoded.code, None, "code"), **options)
    np.testing.assert_allclose(played.lrot, as_taken_out.lrot, atol=1e-4)
    assert np.abs(played.lrot - as_encoded.lrot).max() > 1e-2


@needs_model
def test_strength_zero_gives_the_content_back(engine, walk):
    """Strength 0 keeps the content's pose (rotations and hips height) frame for frame; half
    way lands between it and the full style."""
    content = retarget.to_canonical(bvh.loads(walk))
    code = engine.code_of_name("elderly")

    def restyled(strength: float):
        out = restyle(engine, content, code, strength=strength, time_warp=False, foot_cleanup=False)
        return Fe.encode(out).style3d.reshape(content.num_frames, -1, 3) * Fe.LEG

    own = Fe.encode(content).style3d.reshape(content.num_frames, -1, 3) * Fe.LEG
    assert np.abs(restyled(0.0) - own).max() < 0.05  # cm
    full, half = restyled(1.0), restyled(0.5)
    gap = np.linalg.norm(full - own, axis=-1).mean()
    assert gap > 1.0
    assert np.linalg.norm(half - own, axis=-1).mean() < 0.75 * gap


@needs_model
def test_named_codes_are_taken_from_the_centre_by_their_gains(engine):
    """A named style's code lies its ``named_style_gains`` times as far from the centre of
    the learned codes as the learned one, on the same line; the codes clips are compared
    with for their nearest styles stay as learned."""
    gains = engine.entry.extra["named_style_gains"]
    assert set(gains) == set(engine.style_names) and min(gains.values()) > 1.0
    learned = engine.codes
    centre = learned.mean(axis=0)
    for name in ("active", "angry", "elderly", "normal"):
        code = engine.code_of_name(name).code
        expected = centre + gains[name] * (learned[engine.index[name]] - centre)
        np.testing.assert_allclose(code, expected, atol=1e-5)
    assert engine.nearest(learned[engine.index["angry"]])[0]["style"] == "angry"

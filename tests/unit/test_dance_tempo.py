"""training.dance_tempo: the reference tempo of a shared song and the genre centres."""

from __future__ import annotations

import pytest

from training import dance_tempo as T


def test_reference_tempo_is_the_danced_beat():
    # a waltz whose locked step cycle counted six tracked beats: the tracker had the halves
    waltz = {"genre": "waltz", "tempo_bpm": 170.0, "cycle_beats": 6, "verdict": "verified"}
    assert T.reference_tempo(waltz) == (pytest.approx(85.0), "danced")
    rumba = {"genre": "rumba", "tempo_bpm": 95.0, "cycle_beats": 2, "verdict": "unverified"}
    assert T.reference_tempo(rumba) == (pytest.approx(95.0), "tracked")


def test_genre_centres_leave_the_song_out():
    refs = {"a": ("waltz", 80.0), "b": ("waltz", 90.0), "c": ("waltz", 180.0)}
    assert T.genre_centres(refs)["waltz"] == pytest.approx((80.0 * 90.0 * 180.0) ** (1 / 3))
    assert T.genre_centres(refs, leave_out=("c",))["waltz"] == pytest.approx((80.0 * 90.0) ** 0.5)
    # a genre with no song left: the competition tempo, not one fitted on the song itself
    assert T.genre_centres(refs)["tango"] == T.BALLROOM_TEMPO["tango"]
    assert T.right(87.0, 86.0) and not T.right(174.0, 87.0)


def _envelope(beat_bpm: float, hits: list[tuple[int, float]], seconds: float = 60.0):
    """An onset envelope of ``hits`` (sixteenth of the 4/4 bar, strength) every bar over a
    little noise."""
    import numpy as np

    from motion import spectral

    rate = spectral.ONSET_FRAME_RATE
    envelope = 0.05 * np.random.default_rng(0).random(int(seconds * rate))
    sixteenth = 60.0 / beat_bpm / 4
    for bar in range(int(seconds / (16 * sixteenth)) + 1):
        for s, strength in hits:
            i = int(round((bar * 16 + s) * sixteenth * rate))
            if i < len(envelope):
                envelope[i] += strength
    return envelope


# 3-3-2 twice a bar, the beats soft under it: the pulse heard is the dotted eighth
TRESILLO = [(0, 1.0), (3, 0.8), (6, 0.8), (8, 1.0), (11, 0.8), (14, 0.8), (4, 0.4), (12, 0.4)]
STRAIGHT = [(0, 1.0), (4, 0.8), (8, 1.0), (12, 0.8), (2, 0.3), (6, 0.3), (10, 0.3), (14, 0.3)]


def test_a_tresillo_rumba_is_danced_on_its_beat_not_its_dotted_eighths(monkeypatch):
    from motion import beat_tracking as BT

    tempo = BT.tempo_curve(_envelope(93.0, TRESILLO))
    assert abs(tempo.bpm / 124.0 - 1) < 0.02  # the tracked pulse: 4/3 of the beat
    assert abs(BT.at_level(tempo, BT.GENRE_TEMPO["rumba"]).bpm / 93.0 - 1) < T.TOLERANCE
    monkeypatch.setattr(BT, "TRESILLO_RATIO", float("inf"))  # without the tresillo levels
    assert abs(BT.at_level(tempo, BT.GENRE_TEMPO["rumba"]).bpm / 124.0 - 1) < 0.02


@pytest.mark.parametrize("pattern", ["straight", "triplet"])
def test_a_song_without_a_tresillo_keeps_its_pulse(pattern):
    from motion import beat_tracking as BT
    from motion import spectral
    from training.songs import beat_song

    if pattern == "straight":
        envelope = _envelope(124.0, STRAIGHT)
    else:  # triplet hi-hats: their 4/3 of the beat is periodic too
        song = beat_song("triplet", 150.0, 30.0)
        envelope = spectral.beat_onset_strength(song.samples, song.sr)
    tempo = BT.tempo_curve(envelope)
    lag = 60.0 * spectral.ONSET_FRAME_RATE / tempo.bpm
    ratio = BT.tresillo_ratio(tempo.autocorrelation.sum(axis=0) / len(tempo.period), lag)
    assert ratio < BT.TRESILLO_RATIO
    for genre, centre in BT.GENRE_TEMPO.items():
        assert BT.at_level(tempo, centre).bpm >= 0.95 * tempo.bpm / 2, genre

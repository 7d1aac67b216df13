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

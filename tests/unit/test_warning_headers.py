"""``X-Warnings``: the warnings of an answer as one ASCII header, bounded in length."""

from __future__ import annotations

import json

from service.routes.answers import WARNINGS_HEADER_CHARS, warning_headers


def test_no_warnings_no_header():
    assert warning_headers([]) == {}


def test_warnings_round_trip_as_ascii_json():
    said = [
        "the style clip lasts 0.17 s — under 0.5 s",
        'a "quoted" name, with a comma',
        "clip 2 (walk\r\nX-Injected: 1.bvh): a file name with a line break",
    ]
    value = warning_headers(said)["X-Warnings"]
    assert value.isascii() and "\r" not in value and "\n" not in value
    value.encode("latin-1")  # an HTTP header value
    assert json.loads(value) == said


def test_too_many_warnings_are_counted_not_cut_midway():
    said = [f"warning {i}: " + "x" * 300 for i in range(40)]
    kept = json.loads(warning_headers(said)["X-Warnings"])
    assert len(json.dumps(kept)) <= WARNINGS_HEADER_CHARS
    assert kept[:-1] == said[: len(kept) - 1]
    assert kept[-1] == f"{len(said) - len(kept) + 1} more warnings: ?format=json"

"""GET /v1/styles: one list per model family."""

from __future__ import annotations


def test_styles_has_one_list_per_family(client):
    response = client.get("/v1/styles")
    assert response.status_code == 200
    body = response.json()
    assert set(body) == {"translator", "fast", "dance"}
    for styles in body.values():
        assert isinstance(styles, list)
        for style in styles:
            assert isinstance(style["name"], str) and isinstance(style["model"], str)

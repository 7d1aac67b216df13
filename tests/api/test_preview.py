"""``GET /`` serves the preview page and ``/static`` its files, all from this server: no CDN,
vendored three.js with its licence, module imports that resolve to our own files."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from service.routes.preview import STATIC_DIR
from tests.api.helpers import assert_problem

VENDOR = STATIC_DIR / "vendor" / "three"


def test_page_is_served_with_a_strict_policy(client):
    response = client.get("/")
    assert response.status_code == 200
    assert response.headers["content-type"].startswith("text/html")
    policy = response.headers["content-security-policy"]
    assert "default-src 'self'" in policy and "script-src 'self'" in policy
    assert response.headers["x-content-type-options"] == "nosniff"
    assert '<script type="module" src="/static/app.js">' in response.text
    for element_id in ("content-file", "style-name", "style-file", "keypoints-file", "mix-rows",
                       "audio-file", "strength", "run", "download", "input-view", "result-view",
                       "play", "timeline", "time"):  # fmt: skip
        assert f'id="{element_id}"' in response.text


@pytest.mark.parametrize(
    "path",
    [
        "/static/app.js",
        "/static/style.css",
        "/static/vendor/three/three.module.min.js",
        "/static/vendor/three/BVHLoader.js",
        "/static/vendor/three/OrbitControls.js",
        "/static/vendor/three/GLTFLoader.js",
        "/static/vendor/three/BufferGeometryUtils.js",
        "/static/vendor/three/LICENSE",
    ],  # fmt: skip
)
def test_static_files_are_served(client, path):
    response = client.get(path)
    assert response.status_code == 200
    if path.endswith(".js"):
        assert "javascript" in response.headers["content-type"]


def test_static_errors_are_problems(client):
    assert_problem(client.get("/static/nope.js"), 404, "not-found")
    assert_problem(client.get("/static/../service/main.py"), 404)
    assert_problem(client.post("/static/app.js"), 405)


def test_a_malformed_range_is_ignored_not_a_plain_text_error(client):
    for path in ("/", "/static/app.js"):
        for value in ("bytes=junk", "bytes=999999999-", "lines=1-2"):
            response = client.get(path, headers={"Range": value})
            assert response.status_code == 200, (path, value, response.text[:100])


def _local_sources() -> list[Path]:
    return [STATIC_DIR / "index.html", STATIC_DIR / "app.js", STATIC_DIR / "style.css",
            *sorted(VENDOR.glob("*.js"))]  # fmt: skip


def test_no_cdn_every_import_is_a_file_we_serve():
    # module specifiers of import/export statements (not words in comments)
    imports = re.compile(r"""^\s*(?:import|export)\b[^;'"]*?['"]([^'"]+)['"]""", re.MULTILINE)
    for source in _local_sources():
        text = source.read_text()
        if source.suffix == ".js" and not source.name.endswith(".min.js"):
            for target in imports.findall(text):
                assert target.startswith("./"), (source.name, target)
                assert (source.parent / target).resolve().is_file(), (source.name, target)
        if source.suffix in (".html", ".css") or source.name == "app.js":
            assert not re.search(r"(src|href)=\"https?://", text), source.name
            assert "cdn" not in text.lower(), source.name


def test_vendored_three_is_pinned_and_licensed():
    bundle = (VENDOR / "three.module.min.js").read_text()
    assert 'const t="170"' in bundle[:400]  # REVISION of three@0.170.0
    assert "import" not in bundle[:2000]  # a standalone module: no further files to fetch
    assert "MIT License" in (VENDOR / "LICENSE").read_text()
    assert "three@0.170.0" in (VENDOR / "README.md").read_text()

"""Several model folders (``MOTION_MODELS_DIR=models:STUDIO``): a studio's models served beside
the shipped ones, each style listed with its model, library and licence, ``library:style``
wherever a style name goes, and a 400 listing the choices for a bare name two models share.

The studio's folder is the shipped translator and fast networks copied, their manifest
entries renamed to the library ``studio`` under another licence: the same weights, so
``studio:happy`` must give exactly what the shipped ``happy`` gives.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from service.config import REPO_MODELS_DIR, Settings
from service.main import create_app
from tests.api.helpers import assert_problem, write_tiny_model

STUDIO_LICENCE = "CC BY 4.0 (a studio's own mocap, test copy)"
SHIPPED = json.loads((REPO_MODELS_DIR / "manifest.json").read_text())
FAMILIES = {m["family"] for m in SHIPPED["models"]}
pytestmark = pytest.mark.skipif(
    not {"translator", "fast"} <= FAMILIES, reason="needs the shipped translator and fast models"
)


def studio_folder(root: Path) -> Path:
    """A model folder holding copies of the shipped translator and fast models, as a studio's
    library ``studio`` (names, library and licence rewritten; files and hashes the same)."""
    folder = root / "studio"
    models = []
    for entry in SHIPPED["models"]:
        if entry["family"] not in ("translator", "fast"):
            continue
        shutil.copytree(REPO_MODELS_DIR / entry["family"], folder / entry["family"])
        models.append(
            {
                **entry,
                "name": f"{entry['family']}-studio",
                "licence": STUDIO_LICENCE,
                "training_data": ["library studio (test copy of the shipped weights)"],
                "extra": {**entry["extra"], "library": "studio"},
            }
        )
    manifest = {"schema_version": 1, "models": models}
    (folder / "manifest.json").write_text(json.dumps(manifest, indent=1))
    return folder


@pytest.fixture(scope="module")
def studio(tmp_path_factory) -> Path:
    return studio_folder(tmp_path_factory.mktemp("models"))


@pytest.fixture(scope="module")
def both(studio, tmp_path_factory):
    """The app over the shipped folder and the studio's, in that order."""
    from fastapi.testclient import TestClient

    settings = Settings(
        models_dir=f"{REPO_MODELS_DIR}:{studio}", styles_dir=tmp_path_factory.mktemp("styles")
    )
    app = create_app(settings)
    with TestClient(app) as client:
        assert app.state.registry.wait(240), "models did not finish loading"
        assert app.state.registry.ready, app.state.registry.reasons()
        yield client


def transfer(client, walk: bytes, **style):
    return client.post(
        "/v1/transfer",
        files={"content": ("walk.bvh", walk, "text/plain")},
        data={**style, "time_warp": "false"},
    )


def stylize(client, walk: bytes, style: str):
    return client.post(
        "/v1/stylize",
        files={"content": ("walk.bvh", walk, "text/plain")},
        data={"style_name": style, "time_warp": "false"},
    )


def model_of(response) -> str:
    return response.headers["x-model-version"].split("/")[0]


def test_models_list_every_folder_with_library_and_licence(both):
    body = both.get("/v1/models").json()
    assert body["state"] == "ready"
    shipped = [(m["name"], m["licence"]) for m in SHIPPED["models"]]
    served = {m["name"]: m for m in body["models"]}
    assert [m["name"] for m in body["models"]] == [name for name, _ in shipped] + [
        "translator-studio",
        "fast-studio",
    ]
    for name, licence in shipped:
        assert served[name]["licence"] == licence
        assert served[name]["loaded"] is True
    assert served["translator-bandai"]["library"] == served["fast-bandai"]["library"] == "bandai"
    assert served["translator-studio"]["library"] == served["fast-studio"]["library"] == "studio"
    assert served["fast-studio"]["licence"] == STUDIO_LICENCE
    assert "CC BY-NC 4.0" in served["translator-bandai"]["licence"]


def test_styles_say_which_model_and_licence_they_come_from(both, shared_client):
    listing = both.get("/v1/styles").json()
    alone = shared_client.get("/v1/styles").json()
    for family in ("translator", "fast"):
        shipped = sorted(s["name"] for s in alone[family] if not s.get("registered"))
        by_library: dict[str, list[str]] = {"bandai": [], "studio": []}
        for style in listing[family]:
            library = style["library"]
            assert style["model"] == f"{family}-{library}"
            assert style["qualified_name"] == f"{library}:{style['name']}"
            licence = STUDIO_LICENCE if library == "studio" else None
            assert style["licence"] == (licence or shipped_licence(family))
            by_library[library].append(style["name"])
        assert sorted(by_library["bandai"]) == sorted(by_library["studio"]) == shipped
    # one model's listing keeps today's fields, the new ones added
    happy = next(s for s in alone["translator"] if s["name"] == "happy")
    assert happy["model"] == "translator-bandai" and happy["qualified_name"] == "bandai:happy"
    assert "CC BY-NC 4.0" in happy["licence"]


def shipped_licence(family: str) -> str:
    return next(m["licence"] for m in SHIPPED["models"] if m["family"] == family)


def test_library_style_gives_that_models_result(both, shared_client, walk):
    alone = transfer(shared_client, walk, style_name="happy")
    assert alone.status_code == 200, alone.text
    for library in ("bandai", "studio"):
        r = transfer(both, walk, style_name=f"{library}:happy")
        assert r.status_code == 200, r.text
        assert model_of(r) == f"translator-{library}"
        assert r.content == alone.content  # the same weights, the same clip
    by_model_name = transfer(both, walk, style_name="translator-studio:old")  # an alias too
    assert model_of(by_model_name) == "translator-studio"
    assert by_model_name.content == transfer(shared_client, walk, style_name="old").content


def test_library_style_in_a_mix_and_in_stylize(both, shared_client, walk):
    mix = {"studio:happy": 0.7, "studio:elderly": 0.3}
    r = transfer(both, walk, style_mix=json.dumps(mix))
    assert r.status_code == 200, r.text
    assert model_of(r) == "translator-studio"
    expected = transfer(shared_client, walk, style_mix=json.dumps({"happy": 0.7, "elderly": 0.3}))
    assert r.content == expected.content

    fast = stylize(both, walk, "studio:sad")
    assert fast.status_code == 200, fast.text
    assert model_of(fast) == "fast-studio"
    assert fast.content == stylize(shared_client, walk, "sad").content

    code = both.post("/v1/style-code", data={"style_name": "studio:happy"})
    assert code.status_code == 200, code.text
    assert code.json()["model"]["name"] == "translator-studio"


@pytest.mark.parametrize(
    ("route", "fields"),
    [
        ("transfer", {"style_name": "happy"}),
        ("transfer", {"style_mix": json.dumps({"happy": 0.5, "studio:sad": 0.5})}),
        ("stylize", {"style_name": "happy"}),
        ("style-code", {"style_name": "old"}),  # another name of elderly, in both
    ],
)
def test_a_bare_name_two_models_offer_is_a_400_listing_the_choices(both, walk, route, fields):
    files = {} if route == "style-code" else {"content": ("walk.bvh", walk, "text/plain")}
    body = assert_problem(
        both.post(f"/v1/{route}", files=files, data=fields), 400, "invalid-request"
    )
    bare = "old" if "old" in str(fields) else "happy"
    assert body["choices"] == {bare: [f"bandai:{bare}", f"studio:{bare}"]}
    assert f"bandai:{bare}" in body["detail"] and f"studio:{bare}" in body["detail"]


def test_an_unknown_library_and_a_mix_of_two_models_are_400s(both, walk):
    body = assert_problem(transfer(both, walk, style_name="nope:happy"), 400, "invalid-request")
    assert body["library"] == "nope"
    assert body["libraries"] == ["bandai", "studio"]
    body = assert_problem(stylize(both, walk, "translator-bandai:happy"), 400, "invalid-request")
    assert body["libraries"] == ["bandai", "studio"]  # a translator's name is no fast model

    mixed = {"bandai:happy": 0.5, "studio:sad": 0.5}
    body = assert_problem(transfer(both, walk, style_mix=json.dumps(mixed)), 400)
    assert body["field"] == "style_mix"
    assert body["libraries"] == {"bandai:happy": "bandai", "studio:sad": "studio"}


def test_an_unknown_style_is_a_404_naming_every_models_styles(both, walk):
    body = assert_problem(transfer(both, walk, style_name="sleepy"), 404, "not-found")
    assert "bandai:happy" in body["styles"] and "studio:happy" in body["styles"]
    body = assert_problem(transfer(both, walk, style_name="studio:sleepy"), 404, "not-found")
    assert body["model"] == "translator-studio"


def test_a_registered_style_belongs_to_the_model_that_coded_it(both, walk):
    r = both.post(
        "/v1/styles",
        data={"name": "my-walk"},
        files=[("clips", ("walk.bvh", walk, "text/plain"))],
    )
    assert r.status_code == 201, r.text
    assert r.json()["model"]["name"] == "translator-bandai"  # the first folder's translator
    try:
        listed = [s for s in both.get("/v1/styles").json()["translator"] if s.get("registered")]
        assert len(listed) == 1  # once, though two translators are served
        assert listed[0]["model"] == "translator-bandai"
        assert listed[0]["qualified_name"] == "bandai:my-walk"
        bare = transfer(both, walk, style_name="my-walk")  # no other model offers it
        assert bare.status_code == 200, bare.text
        assert model_of(bare) == "translator-bandai"
        assert transfer(both, walk, style_name="bandai:my-walk").content == bare.content
        assert_problem(transfer(both, walk, style_name="studio:my-walk"), 404)
        assert_problem(both.post("/v1/styles", data={"name": "happy"}, files=[
            ("clips", ("walk.bvh", walk, "text/plain"))]), 409)  # fmt: skip
    finally:
        assert both.delete("/v1/styles/my-walk").status_code == 204


def test_one_folder_serves_as_before(shared_client, walk):
    assert shared_client.app.state.registry.models_dirs == (REPO_MODELS_DIR,)
    bare = transfer(shared_client, walk, style_name="happy")
    assert bare.status_code == 200 and model_of(bare) == "translator-bandai"
    assert transfer(shared_client, walk, style_name="bandai:happy").content == bare.content
    assert stylize(shared_client, walk, "angry").status_code == 200
    body = assert_problem(transfer(shared_client, walk, style_name="sleepy"), 404, "not-found")
    assert body["model"] == "translator-bandai" and "happy" in body["styles"]


def test_the_same_model_in_two_folders_keeps_the_service_not_ready(make_client, tmp_path):
    for folder in ("a", "b"):
        write_tiny_model(tmp_path / folder, name="fast-tiny")
    client = make_client(Settings(models_dir=[tmp_path / "a", tmp_path / "b"], intra_op_threads=1))
    body = assert_problem(client.get("/readyz"), 503, "not-ready")
    assert any(
        "fast-tiny" in reason and "two model folders" in reason for reason in body["reasons"]
    )


def test_a_missing_folder_is_named_in_the_reasons(make_client, tmp_path):
    write_tiny_model(tmp_path / "a", name="fast-tiny")
    client = make_client(
        Settings(models_dir=[tmp_path / "a", tmp_path / "absent"], intra_op_threads=1)
    )
    body = assert_problem(client.get("/readyz"), 503, "not-ready")
    assert any(r.startswith("manifest 2:") and "absent" in r for r in body["reasons"])


def test_models_dir_takes_a_path_list(monkeypatch, tmp_path):
    monkeypatch.setenv("MOTION_MODELS_DIR", f"models:{tmp_path}/studio:")
    assert Settings().models_dir == (Path("models"), tmp_path / "studio")
    monkeypatch.setenv("MOTION_MODELS_DIR", str(tmp_path))
    assert Settings().models_dir == (tmp_path,)
    assert Settings(models_dir=[tmp_path, "models"]).models_dir == (tmp_path, Path("models"))
    monkeypatch.setenv("MOTION_MODELS_DIR", " : ")
    with pytest.raises(ValueError, match="at least one model folder"):
        Settings()

"""API keys against the real app (shipped models) with a keys file made by ``python -m
service keys``: 401 without a known key, 403 without the scope, the ``manage`` scope for
registering and deleting styles (which records the key's name), open health routes,
``/metrics`` open unless asked otherwise, a revoked key refused at once, 429 per key, the
OpenAPI schema, the start-up warning, and the keys file's format and command line.

The two-worker service (revocation and limits shared by the workers, and the search for
the key in a whole run's logs, problems and metrics) is ``test_api_keys_workers.py``."""

from __future__ import annotations

import asyncio
import json
import logging
import os
import subprocess
import sys
import threading
import warnings
from pathlib import Path

import pytest

from service import api_keys, keys_cli
from service.auth import log_startup
from service.config import Settings
from service.inference import InferenceRunner
from service.key_limits import KeyLimits
from service.log import RequestIdFilter, key_name_var
from service.main import create_app
from tests.api.helpers import assert_problem, blender_warm
from tests.rigs import FIXTURE
from tests.server import REPO

with warnings.catch_warnings():
    warnings.filterwarnings("ignore", message=".*starlette.testclient.*")
    from fastapi.testclient import TestClient


def add(path: Path, name: str, scopes: str, capsys) -> str:
    """``python -m service keys add`` (in this process): the key it printed."""
    capsys.readouterr()
    assert keys_cli.main(["--file", str(path), "add", name, "--scopes", scopes]) == 0
    out = capsys.readouterr().out
    return out.strip()


def bearer(key: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {key}"}


@pytest.fixture(scope="module")
def keyed(tmp_path_factory):
    """An app whose keys file holds ``user`` (use) and ``admin`` (use,manage)."""
    folder = tmp_path_factory.mktemp("keyed")
    keys_file = folder / "api-keys"
    keys = {
        name: api_keys.add_key(keys_file, name, frozenset(scopes))
        for name, scopes in (("user", {"use"}), ("admin", {"use", "manage"}))
    }
    settings = Settings(
        api_keys_file=keys_file, styles_dir=folder / "styles", key_state_dir=folder / "state"
    )
    app = create_app(settings)
    with TestClient(app) as client:
        assert app.state.registry.wait(120) and app.state.registry.ready and blender_warm(app)
        yield client, keys, keys_file


def transfer(client, headers):
    return client.post(
        "/v1/transfer",
        files={"content": ("walk.bvh", FIXTURE.read_bytes(), "text/plain")},
        data={"style_name": "elderly"},
        headers=headers,
    )


def register(client, name, headers):
    return client.post(
        "/v1/styles",
        data={"name": name},
        files=[("clips", ("walk.bvh", FIXTURE.read_bytes(), "text/plain"))],
        headers=headers,
    )


def test_no_key_and_an_unknown_key_get_401_with_www_authenticate(keyed):
    client, keys, _ = keyed
    for path in ("/v1/styles", "/v1/models", "/v1/nowhere", "/elsewhere"):
        body = assert_problem(client.get(path), 401, "unauthorized")
        assert "Authorization: Bearer" in body["detail"]
    r = client.get("/v1/styles", headers=bearer("msk_" + "x" * 43))
    assert_problem(r, 401, "unauthorized")
    assert r.headers["www-authenticate"] == 'Bearer realm="motion-style", error="invalid_token"'
    assert client.get("/v1/styles").headers["www-authenticate"].startswith("Bearer")
    # another scheme, a key cut short, a key with more after it: not the key
    user = keys["user"]
    for headers in (
        {"Authorization": f"Basic {user}"},
        bearer(user[:-1]),
        bearer(user + "x"),
        {"X-API-Key": user.upper()},
        bearer("x" * 10_000),
    ):
        assert_problem(client.get("/v1/styles", headers=headers), 401, "unauthorized")
    # refused before the body is read: an upload over the limit is still a 401
    big = client.post("/v1/transfer", content=b"x" * (30 * 1024 * 1024))
    assert_problem(big, 401, "unauthorized")


def test_a_use_key_restyles_but_gets_403_on_changing_styles(keyed):
    client, keys, _ = keyed
    for headers in (bearer(keys["user"]), {"X-API-Key": keys["user"]}):
        r = transfer(client, headers)
        assert r.status_code == 200, r.text
        assert r.text.startswith("HIERARCHY")
    assert client.get("/v1/styles", headers=bearer(keys["user"])).status_code == 200
    for r in (
        register(client, "by-user", bearer(keys["user"])),
        client.delete("/v1/styles/anything", headers=bearer(keys["user"])),
    ):
        body = assert_problem(r, 403, "forbidden")
        assert body["required_scope"] == "manage" and body["key_name"] == "user"
        assert 'error="insufficient_scope"' in r.headers["www-authenticate"]
    listed = client.get("/v1/styles", headers=bearer(keys["user"])).json()["translator"]
    assert "by-user" not in {s["name"] for s in listed}


def test_a_manage_key_registers_and_deletes_and_the_style_records_the_keys_name(keyed):
    client, keys, keys_file = keyed
    admin = bearer(keys["admin"])
    r = register(client, "studio-walk", admin)
    assert r.status_code == 201, r.text
    assert r.json()["registered_by"] == "admin"
    listed = client.get("/v1/styles", headers=bearer(keys["user"])).json()["translator"]
    entry = next(s for s in listed if s["name"] == "studio-walk")
    assert entry["registered"] and entry["registered_by"] == "admin"
    styles_dir = client.app.state.settings.styles_dir
    stored = json.loads((styles_dir / "studio-walk.json").read_text())
    assert stored["registered_by"] == "admin"
    # a use key may restyle with it; the manage key deletes it
    r = client.post(
        "/v1/transfer",
        files={"content": ("walk.bvh", FIXTURE.read_bytes(), "text/plain")},
        data={"style_name": "studio-walk"},
        headers=bearer(keys["user"]),
    )
    assert r.status_code == 200, r.text
    assert client.delete("/v1/styles/studio-walk", headers=admin).status_code == 204
    assert_problem(client.delete("/v1/styles/studio-walk", headers=admin), 404, "not-found")


def test_health_preview_docs_and_metrics_answer_without_a_key(keyed):
    client, _, _ = keyed
    for path in ("/healthz", "/readyz", "/v2/health/live", "/v2/health/ready", "/metrics",
                 "/", "/static/app.js", "/openapi.json", "/docs"):  # fmt: skip
        assert client.get(path).status_code == 200, path


def test_metrics_need_a_key_when_asked_and_count_requests_by_key_name(make_client, tmp_path):
    keys_file = tmp_path / "keys"
    key = api_keys.add_key(keys_file, "scraper", frozenset({"use"}))
    settings = Settings(api_keys_file=keys_file, metrics_key_required=True)
    client = make_client(settings, wait=False)
    assert_problem(client.get("/metrics"), 401, "unauthorized")
    assert client.get("/healthz").status_code == 200
    exposition = client.get("/metrics", headers=bearer(key)).text
    client.get("/metrics", headers=bearer(key))
    exposition = client.get("/metrics", headers=bearer(key)).text
    line = 'motion_key_requests_total{endpoint="/metrics",key="scraper",status="200"} 2.0'
    assert line in exposition


def test_a_revoked_key_is_refused_at_once_without_a_restart(make_client, tmp_path, capsys):
    keys_file = tmp_path / "keys"
    first = add(keys_file, "first", "use", capsys)
    second = add(keys_file, "second", "use", capsys)
    client = make_client(Settings(api_keys_file=keys_file), wait=False)
    assert client.get("/healthz", headers=bearer(first)).status_code == 200
    assert client.get("/v1/nowhere", headers=bearer(first)).status_code == 404
    assert keys_cli.main(["--file", str(keys_file), "revoke", "first"]) == 0
    assert_problem(client.get("/v1/nowhere", headers=bearer(first)), 401, "unauthorized")
    assert client.get("/v1/nowhere", headers=bearer(second)).status_code == 404
    # a key added while it runs works at once; a deleted file refuses every key
    third = add(keys_file, "third", "use", capsys)
    assert client.get("/v1/nowhere", headers=bearer(third)).status_code == 404
    keys_file.unlink()
    assert_problem(client.get("/v1/nowhere", headers=bearer(third)), 401, "unauthorized")


def test_a_secret_updated_the_way_the_kubelet_does_it_is_read_again(tmp_path, capsys):
    """The kubelet writes a Secret's files into a new timestamped folder and swaps the
    ``..data`` link to it; the file path goes through that link."""
    staging = tmp_path / "staging"
    first = add(staging, "first", "use", capsys)
    second = add(staging, "second", "use", capsys)
    mount = tmp_path / "mount"
    (mount / "..2026_11_28_01").mkdir(parents=True)
    (mount / "..2026_11_28_01" / "api-keys").write_bytes(staging.read_bytes())
    (mount / "..data").symlink_to("..2026_11_28_01")
    (mount / "api-keys").symlink_to("..data/api-keys")
    keys = api_keys.KeysFile(mount / "api-keys")
    assert keys.identify(first) and keys.identify(second)
    api_keys.revoke_key(staging, "first")
    (mount / "..2026_11_28_02").mkdir()
    (mount / "..2026_11_28_02" / "api-keys").write_bytes(staging.read_bytes())
    (mount / "..data_tmp").symlink_to("..2026_11_28_02")
    os.replace(mount / "..data_tmp", mount / "..data")
    assert keys.identify(first) is None and keys.identify(second)


def test_a_keys_file_that_cannot_be_read_refuses_every_key_and_says_so_once(tmp_path, caplog):
    keys_file = tmp_path / "keys"
    key = api_keys.add_key(keys_file, "only", frozenset({"use"}))
    keys = api_keys.KeysFile(keys_file)
    saved = keys_file.read_bytes()
    keys_file.unlink()
    keys_file.mkdir()  # there, but not a file that can be read
    with caplog.at_level(logging.ERROR, logger="service.api_keys"):
        assert keys.identify(key) is None and keys.identify(key) is None
    assert len(caplog.records) == 1 and "refusing every key" in caplog.text
    keys_file.rmdir()
    keys_file.write_bytes(saved)
    assert keys.identify(key).name == "only"


def test_a_key_over_its_rate_gets_429_with_retry_after_while_another_key_gets_through(
    make_client, tmp_path
):
    keys_file = tmp_path / "keys"
    busy = api_keys.add_key(keys_file, "busy", frozenset({"use"}))
    calm = api_keys.add_key(keys_file, "calm", frozenset({"use"}))
    settings = Settings(api_keys_file=keys_file, key_requests_per_minute=6, key_burst=3)
    client = make_client(settings, wait=False)
    answers = [client.get("/v1/nowhere", headers=bearer(busy)) for _ in range(5)]
    assert [r.status_code for r in answers] == [404, 404, 404, 429, 429]
    body = assert_problem(answers[3], 429, "too-many-requests")
    assert body["limit_name"] == "key_requests_per_minute" and body["key_name"] == "busy"
    assert 1 <= int(answers[3].headers["retry-after"]) <= 10  # one request every 10 s
    calm_answers = [client.get("/v1/nowhere", headers=bearer(calm)) for _ in range(3)]
    assert [r.status_code for r in calm_answers] == [404] * 3


def test_requests_in_progress_are_limited_per_key_across_processes(tmp_path):
    """Two limiters on one folder stand for two workers: together they hold at most
    ``max_concurrent`` slots of a key, a released slot is free for either, another key has
    its own, and a process that dies holding a slot does not keep it."""
    first, second = (KeyLimits(tmp_path, 0, 1, 2) for _ in range(2))
    held = [first.acquire("a"), second.acquire("a")]
    assert all(held) and first.acquire("a") is None and second.acquire("a") is None
    assert first.acquire("b") is not None
    held[0].release()
    again = second.acquire("a")
    assert again is not None and first.acquire("a") is None
    again.release()
    held[1].release()
    hold = (
        "import os, sys; from service.key_limits import KeyLimits; "
        f"s = KeyLimits({str(tmp_path)!r}, 0, 1, 2); a, b = s.acquire('a'), s.acquire('a'); "
        "assert a and b; os._exit(0)"
    )
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    assert subprocess.run([sys.executable, "-c", hold], env=env, timeout=60).returncode == 0
    assert first.acquire("a") is not None and second.acquire("a") is not None


def test_an_error_trace_holds_no_key(make_client, tmp_path, caplog):
    """A route that fails with a key in hand: the 500 problem and the logged traceback
    (the formatted exception, as the JSON log writes it) hold the key's name, not the key."""
    keys_file = tmp_path / "keys"
    key = api_keys.add_key(keys_file, "tracer", frozenset({"use"}))

    def failing_route(app):
        @app.get("/v1/_test/boom")
        async def boom():
            raise RuntimeError("boom")

    client = make_client(
        Settings(api_keys_file=keys_file), setup=failing_route, wait=False,
        raise_server_exceptions=False,
    )  # fmt: skip
    caplog.handler.addFilter(RequestIdFilter())
    with caplog.at_level(logging.DEBUG):
        r = client.get("/v1/_test/boom", headers={"X-API-Key": key})
    assert_problem(r, 500, "internal-error")
    (failure,) = [rec for rec in caplog.records if rec.exc_info]
    assert failure.key == "tracer"  # the failure's log line names the key
    logged = caplog.text + "".join(
        logging.Formatter().formatException(rec.exc_info) for rec in caplog.records if rec.exc_info
    )
    assert "RuntimeError: boom" in logged and "tracer" in logged
    assert key not in logged + r.text and key[4:16] not in logged + r.text


def test_routes_whose_scope_cannot_be_read_need_manage(make_client, tmp_path, caplog):
    keys_file = tmp_path / "keys"
    user = api_keys.add_key(keys_file, "user", frozenset({"use"}))
    admin = api_keys.add_key(keys_file, "admin", frozenset({"use", "manage"}))

    def broken_schema(app):
        def openapi():
            raise RuntimeError("no schema")

        app.openapi = openapi

    client = make_client(Settings(api_keys_file=keys_file), setup=broken_schema, wait=False)
    with caplog.at_level(logging.ERROR, logger="service.auth"):
        assert_problem(client.get("/v1/nowhere", headers=bearer(user)), 403, "forbidden")
    assert "every route needs 'manage'" in caplog.text
    assert client.get("/v1/nowhere", headers=bearer(admin)).status_code == 404


def test_a_freed_inference_slot_goes_to_the_key_that_waited_not_the_one_with_the_queue():
    """One slot: ``busy`` holds it with four more requests waiting when ``calm`` asks; the
    slot goes to ``calm`` next, not after ``busy``'s queue (which is served in order)."""
    runner = InferenceRunner(1, timeout_s=10, queue_wait_s=10, max_queued=16)
    runner.start()
    order: list[str] = []
    gate = threading.Event()

    async def call(key: str, label: str) -> None:
        key_name_var.set(key)  # in this task's own context, as the middleware does

        def work() -> None:
            if label == "busy-0":
                gate.wait(5)
            order.append(label)

        await runner.run(work)

    async def scenario() -> None:
        first = asyncio.ensure_future(call("busy", "busy-0"))
        await asyncio.sleep(0.05)
        tasks = [asyncio.ensure_future(call("busy", f"busy-{i}")) for i in range(1, 5)]
        await asyncio.sleep(0.05)
        tasks.append(asyncio.ensure_future(call("calm", "calm")))
        await asyncio.sleep(0.05)
        assert (runner.running, runner.queued) == (1, 5)
        gate.set()
        await asyncio.gather(first, *tasks)

    try:
        asyncio.run(scenario())
    finally:
        runner.close()
    assert order == ["busy-0", "calm", "busy-1", "busy-2", "busy-3", "busy-4"]
    assert (runner.running, runner.queued) == (0, 0)


def test_openapi_names_the_key_schemes_and_each_routes_scope(keyed):
    client, keys, _ = keyed
    schema = client.get("/openapi.json").json()
    schemes = schema["components"]["securitySchemes"]
    assert schemes["bearer"]["scheme"] == "bearer" and schemes["apiKey"]["name"] == "X-API-Key"
    paths = schema["paths"]
    manage = [{"bearer": ["manage"]}, {"apiKey": ["manage"]}]
    assert paths["/v1/styles"]["post"]["security"] == manage
    assert paths["/v1/styles/{name}"]["delete"]["security"][0] == {"bearer": ["manage"]}
    assert paths["/v1/transfer"]["post"]["security"][0] == {"bearer": ["use"]}
    assert {"401", "403", "429"} <= set(paths["/v1/transfer"]["post"]["responses"])
    assert "security" not in paths["/healthz"]["get"]
    text = json.dumps(schema)
    assert all(key not in text for key in keys.values()) and "msk_" not in text


def test_without_a_keys_file_the_service_is_open_and_warns_beyond_loopback(client, caplog):
    assert client.get("/v1/styles").status_code == 200
    with caplog.at_level(logging.WARNING, logger="service.auth"):
        log_startup(Settings(host="127.0.0.1"))
        log_startup(Settings(host="localhost"))
        log_startup(Settings(host="::1"))
        assert not caplog.records
        log_startup(Settings(host="0.0.0.0"))
    assert len(caplog.records) == 1 and "MOTION_API_KEYS_FILE" in caplog.records[0].message


def test_start_up_warns_when_one_key_could_fill_the_queue(tmp_path, caplog):
    keys_file = tmp_path / "keys"
    keys_file.write_text("")
    fits = Settings(api_keys_file=keys_file, max_concurrent_inferences=1, max_queued=8)
    with caplog.at_level(logging.WARNING, logger="service.auth"):
        log_startup(fits.model_copy(update={"key_max_concurrent": 8}))
        assert not caplog.records
        log_startup(fits.model_copy(update={"key_max_concurrent": 9}))
        log_startup(fits.model_copy(update={"key_max_concurrent": 0}))
    assert len(caplog.records) == 2 and "MOTION_KEY_MAX_CONCURRENT" in caplog.text


def test_a_keys_file_that_cannot_be_read_stops_the_start(tmp_path):
    missing = tmp_path / "no-such-file"
    with pytest.raises(api_keys.KeysFileError, match="MOTION_API_KEYS_FILE"):
        create_app(Settings(api_keys_file=missing))
    env = {**os.environ, "MOTION_API_KEYS_FILE": str(missing)}
    result = subprocess.run(
        [sys.executable, "-m", "service", "--port", "0"],
        cwd=REPO, env=env, capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert result.returncode == 1 and "cannot be read" in result.stderr


def test_the_keys_file_holds_digests_and_a_bad_line_is_skipped_without_its_text(
    tmp_path, capsys, caplog
):
    keys_file = tmp_path / "keys"
    key = add(keys_file, "studio-a", "manage,use", capsys)
    assert key.startswith("msk_") and len(key) == 47
    text = keys_file.read_text()
    assert key not in text and api_keys.digest_of(key).hex() in text
    assert oct(keys_file.stat().st_mode & 0o777) == "0o600"
    keys_file.chmod(0o644)  # readable by a container's user: kept when the file is rewritten
    add(keys_file, "studio-b", "use", capsys)
    assert oct(keys_file.stat().st_mode & 0o777) == "0o644"
    api_keys.revoke_key(keys_file, "studio-b")
    pasted = "msk_" + "p" * 43
    keys_file.write_text(text + f"pasted {pasted}\nbad-scope {pasted} " + "0" * 64 + "\n")
    with caplog.at_level(logging.WARNING, logger="service.api_keys"):
        keys = api_keys.KeysFile(keys_file)
    assert [k.name for k in keys.keys] == ["studio-a"]
    assert keys.identify(key).scopes == {"use", "manage"}
    assert keys.identify(pasted) is None
    assert "line 3" in caplog.text and "line 4" in caplog.text
    assert pasted not in caplog.text


def test_the_keys_command_line_adds_lists_and_revokes(tmp_path, capsys):
    keys_file = tmp_path / "deep" / "keys"
    key = add(keys_file, "ci", "use", capsys)
    assert keys_cli.main(["--file", str(keys_file), "add", "ci"]) == 1
    assert "exists already" in capsys.readouterr().err
    for bad in (["add", "Bad/Name"], ["add", "x", "--scopes", "admin"], ["revoke", "nobody"]):
        assert keys_cli.main(["--file", str(keys_file), *bad]) in (1, 2)
    capsys.readouterr()
    assert keys_cli.main(["--file", str(keys_file), "list"]) == 0
    listing = capsys.readouterr().out
    assert listing.startswith("ci\tuse\t") and key not in listing
    # the module entry point, with the file from the environment
    env = {**os.environ, "MOTION_API_KEYS_FILE": str(keys_file)}
    run = [sys.executable, "-m", "service", "keys"]
    result = subprocess.run([*run, "add", "farm", "--scopes", "use,manage"], cwd=REPO, env=env,
                            capture_output=True, text=True, timeout=60)  # fmt: skip
    assert result.returncode == 0 and result.stdout.startswith("msk_")
    assert result.stdout.strip() not in result.stderr and "not be shown again" in result.stderr
    result = subprocess.run([*run, "revoke", "ci"], cwd=REPO, env=env, capture_output=True,
                            text=True, timeout=60)  # fmt: skip
    assert result.returncode == 0
    assert [k.name for k in api_keys.read_keys(keys_file)] == ["farm"]

"""API keys in a real two-worker service (``python -m service --workers 2``) with keys made
and revoked by ``python -m service keys``: a revoked key is refused from the next request on
by both workers, with no restart; a key's rate and its requests in progress are counted across
both workers (429 with ``Retry-After``) while another key's requests succeed; the batch
command line works against it; and nothing of a key, in the logs, problem bodies or
``/metrics`` of the whole run, shows a character of it.

Which worker answered is read from the per-process files of ``PROMETHEUS_MULTIPROC_DIR``,
so each test checks that both workers took part in what it measures."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import httpx
import pytest
from prometheus_client.mmap_dict import MmapedDict

from motion import bvh
from service.api_keys import digest_of
from tests.rigs import FIXTURE, load_fixture
from tests.server import REPO, ServerProcess

BURST = 6
PER_MINUTE = 60.0
MAX_CONCURRENT = 3
COMMAND = Path(sys.executable).parent / "motion-style"


class Run:
    """The module's service, and every answer it gave (for the leak search)."""

    def __init__(self, server: ServerProcess, folder: Path) -> None:
        self.server = server
        self.folder = folder
        self.keys_file = folder / "api-keys"
        self.metrics_dir = folder / "metrics"
        self.answers: list[str] = []
        self.keys: dict[str, str] = {}
        self._lock = threading.Lock()

    def request(self, method: str, path: str, key: str | None = None, **kwargs) -> httpx.Response:
        """One request on a new connection (so the kernel may hand it to either worker)."""
        headers = kwargs.pop("headers", {})
        if key is not None:
            headers = {**headers, "Authorization": f"Bearer {key}"}
        r = httpx.request(method, self.server.url + path, headers=headers, timeout=60, **kwargs)
        with self._lock:
            self.answers.append(
                "\n".join(f"{k}: {v}" for k, v in r.headers.items()) + "\n" + r.text
            )
        return r

    def at_once(self, count: int, method: str, path: str, key: str | None = None, **kw):
        with ThreadPoolExecutor(count) as pool:
            return list(pool.map(lambda _: self.request(method, path, key, **kw), range(count)))

    def keys_command(self, *args: str) -> subprocess.CompletedProcess:
        env = {**os.environ, "MOTION_API_KEYS_FILE": str(self.keys_file)}
        result = subprocess.run([sys.executable, "-m", "service", "keys", *args], cwd=REPO,
                                env=env, capture_output=True, text=True, timeout=60)  # fmt: skip
        assert result.returncode == 0, result.stderr
        return result

    def add(self, name: str, scopes: str = "use") -> str:
        key = self.keys_command("add", name, "--scopes", scopes).stdout.strip()
        self.keys[name] = key
        return key

    def per_worker(self, metric: str, **labels: str) -> dict[int, float]:
        """``{pid: value}`` of a counter's samples with ``labels``, from each worker's file."""
        out: dict[int, float] = {}
        for path in self.metrics_dir.glob("counter_*.db"):
            pid = int(path.stem.split("_")[1])
            for key, value, *_ in MmapedDict.read_all_values_from_file(str(path)):
                _, sample, sample_labels, _ = json.loads(key)
                if sample == metric and all(sample_labels.get(k) == v for k, v in labels.items()):
                    out[pid] = out.get(pid, 0.0) + value
        return out


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    folder = tmp_path_factory.mktemp("keys-workers")
    (folder / "api-keys").write_text("")
    env = {
        "MOTION_API_KEYS_FILE": str(folder / "api-keys"),
        "MOTION_KEY_REQUESTS_PER_MINUTE": str(PER_MINUTE),
        "MOTION_KEY_BURST": str(BURST),
        "MOTION_KEY_MAX_CONCURRENT": str(MAX_CONCURRENT),
        "MOTION_STYLES_DIR": str(folder / "styles"),
        "MOTION_LOG_FORMAT": "json",
        "MOTION_LOG_LEVEL": "debug",
        "MOTION_DEBUG_ROUTES": "1",
        "MOTION_QUEUE_WAIT_S": "30",
        "MOTION_INTRA_OP_THREADS": "1",
        "PROMETHEUS_MULTIPROC_DIR": str(folder / "metrics"),
    }
    command = [sys.executable, "-m", "service", "--host", "127.0.0.1", "--port", "{port}",
               "--workers", "2"]  # fmt: skip
    with ServerProcess(
        command, env=env, log_path=folder / "server.log", start_timeout=240
    ) as server:
        server.wait_every_worker_ready(240)
        yield Run(server, folder)


def test_a_revoked_key_gets_401_from_the_next_request_on_from_both_workers(run):
    """Each worker checks the keys file at every request, so every request sent after the
    command returns is refused: no wait, and nothing here depends on the machine's load."""
    key = run.add("revokee")
    assert run.request("GET", "/v1/models", key).status_code == 200
    before = run.per_worker("motion_errors_total", type="unauthorized")
    run.keys_command("revoke", "revokee")
    for _ in range(40):  # until both workers have answered some of the requests
        statuses = [r.status_code for r in run.at_once(6, "GET", "/v1/models", key)]
        assert statuses == [401] * 6, statuses
        after = run.per_worker("motion_errors_total", type="unauthorized")
        if len([pid for pid in after if after[pid] > before.get(pid, 0)]) == 2:
            break
    else:
        pytest.fail("one worker answered every request after the revocation")


def test_a_keys_rate_is_shared_by_both_workers_while_another_key_gets_through(run):
    """Separate buckets would let each worker pass ``BURST`` requests; one shared bucket
    passes ``BURST`` plus what refills meanwhile, however the requests are spread."""
    key = run.add("busy")
    started = time.monotonic()
    statuses: list[int] = []
    for _ in range(12):
        statuses += [r.status_code for r in run.at_once(MAX_CONCURRENT, "GET", "/v1/models", key)]
        seen = run.per_worker("motion_key_requests_total", key="busy")
        if len(seen) == 2 and min(seen.values()) > BURST:
            break
    elapsed = time.monotonic() - started
    seen = run.per_worker("motion_key_requests_total", key="busy")
    assert len(seen) == 2 and min(seen.values()) > BURST, seen  # both workers took > BURST
    passed = statuses.count(200)
    assert set(statuses) == {200, 429}
    assert BURST <= passed <= BURST + elapsed * PER_MINUTE / 60 + 1, (passed, elapsed)
    refused = run.request("GET", "/v1/models", key)
    assert refused.status_code == 429 and int(refused.headers["retry-after"]) >= 1
    assert refused.json()["limit_name"] == "key_requests_per_minute"
    calm = run.add("calm")
    assert [r.status_code for r in run.at_once(3, "GET", "/v1/models", calm)] == [200] * 3


def test_a_keys_requests_in_progress_are_counted_across_both_workers(run):
    """A refusal proves the count is shared when the worker that refused held fewer than
    all the key's slots itself (known once the held requests are answered and counted)."""
    key, other = run.add("holder"), run.add("other")

    def counts():
        refusals = run.per_worker("motion_key_requests_total", key="holder", status="429")
        sleeps = run.per_worker("motion_key_requests_total", key="holder",
                                endpoint="/_debug/sleep")  # fmt: skip
        return refusals, sleeps

    for _ in range(3):
        refusals_before, sleeps_before = counts()
        with ThreadPoolExecutor(MAX_CONCURRENT) as sleepers:
            held = [sleepers.submit(run.request, "GET", "/_debug/sleep?seconds=3", key)
                    for _ in range(MAX_CONCURRENT)]  # fmt: skip
            time.sleep(1.0)  # all of them in progress (sleeping or waiting for a thread)
            refused = [r for _ in range(3) for r in run.at_once(2, "GET", "/v1/models", key)]
            assert run.request("GET", "/v1/models", other).status_code == 200
            assert [f.result().status_code for f in held] == [200] * MAX_CONCURRENT
        assert [r.status_code for r in refused] == [429] * len(refused)
        assert refused[0].json()["limit_name"] == "key_max_concurrent"
        assert refused[0].headers["retry-after"] == "1"
        refusals, sleeps = counts()
        refusing = [pid for pid in refusals if refusals[pid] > refusals_before.get(pid, 0)]
        held_by = {pid: sleeps.get(pid, 0) - sleeps_before.get(pid, 0) for pid in refusing}
        if any(count < MAX_CONCURRENT for count in held_by.values()):
            break
    else:
        pytest.fail("every refusal came from the worker that held every slot, three times")
    assert run.request("GET", "/v1/models", key).status_code == 200  # released


def test_the_command_line_works_against_a_keyed_service(run, tmp_path):
    assert COMMAND.exists(), f"{COMMAND} missing: `pip install -e .[client]` installs it"
    clips = tmp_path / "clips"
    clips.mkdir()
    bvh.save(load_fixture().slice(0, 60), clips / "walk.bvh")
    key = run.add("batch")
    command = [str(COMMAND), "transfer", str(clips), "--style", "elderly", "--url",
               run.server.url, "-q"]  # fmt: skip
    env = {k: v for k, v in os.environ.items() if k != "MOTION_API_KEY"}
    denied = subprocess.run([*command, "-o", str(tmp_path / "none")], env=env,
                            capture_output=True, text=True, timeout=120)  # fmt: skip
    assert denied.returncode == 1 and "401 Unauthorized" in denied.stderr
    assert "--api-key or MOTION_API_KEY" in denied.stderr
    by_flag = subprocess.run([*command, "-o", str(tmp_path / "flag"), "--api-key", key], env=env,
                             capture_output=True, text=True, timeout=120)  # fmt: skip
    by_env = subprocess.run([*command, "-o", str(tmp_path / "env")],
                            env={**env, "MOTION_API_KEY": key},
                            capture_output=True, text=True, timeout=120)  # fmt: skip
    for result, out in ((by_flag, "flag"), (by_env, "env")):
        assert result.returncode == 0, result.stderr
        assert key not in result.stderr + result.stdout
        written = bvh.load(tmp_path / out / "walk.bvh")
        assert written.skeleton.names == bvh.load(clips / "walk.bvh").skeleton.names
    assert run.per_worker("motion_key_requests_total", key="batch", status="200")


def test_no_character_of_a_key_in_the_logs_problems_or_metrics_of_the_whole_run(run):
    """The module's last test: after everything above, plus every kind of refusal and
    failure with keys in hand, the server's log, every answer and ``/metrics`` are searched
    for each key issued (and one never issued), whole and in any 12 characters of it."""
    manager, user = run.add("leaky", "use,manage"), run.add("leaky-use")
    stranger = "msk_" + "Zq9" * 14 + "x"
    clip = FIXTURE.read_bytes()
    files = {"content": ("walk.bvh", clip, "text/plain")}
    assert run.request("POST", "/v1/transfer", user, files=files,
                       data={"style_name": "elderly"}).status_code == 200  # fmt: skip
    assert run.request("POST", "/v1/transfer", user, files={"content": ("b.bvh", clip[:300])},
                       data={"style_name": "elderly"}).status_code == 400  # fmt: skip
    assert run.request("POST", "/v1/transfer", user, files=files,
                       data={"style_name": "nope"}).status_code == 404  # fmt: skip
    registered = run.request("POST", "/v1/styles", manager, data={"name": "leak-check"},
                             files=[("clips", ("walk.bvh", clip, "text/plain"))])  # fmt: skip
    assert registered.status_code == 201 and registered.json()["registered_by"] == "leaky"
    assert run.request("DELETE", "/v1/styles/leak-check", user).status_code == 403
    assert run.request("DELETE", "/v1/styles/leak-check", manager).status_code == 204
    assert run.request("GET", "/v1/models", stranger).status_code == 401
    assert run.request("GET", "/v1/models", headers={"X-API-Key": stranger}).status_code == 401
    assert run.request("GET", "/v1/models", headers={"Authorization": stranger}).status_code == 401
    statuses = [r.status_code for r in run.at_once(MAX_CONCURRENT, "GET", "/v1/models", user)]
    statuses += [run.request("GET", "/v1/models", user).status_code for _ in range(BURST)]
    assert 429 in statuses
    run.keys_command("revoke", "leaky-use")
    assert run.request("GET", "/v1/models", user).status_code == 401
    run.keys_command("list")
    metrics = run.request("GET", "/metrics").text
    time.sleep(0.5)  # the last access-log lines
    log = run.server.log_path.read_text(errors="replace")

    # the search reaches what it should: key names are in the log and the metric labels
    assert '"key": "leaky"' in log and 'key="leaky"' in metrics and 'key="busy"' in metrics
    sources = {"log": log, "metrics": metrics}
    sources.update((f"answer {k}", answer) for k, answer in enumerate(run.answers))
    issued = dict(run.keys, stranger=stranger)
    assert len(issued) >= 9
    for name, key in issued.items():
        secret = key.removeprefix("msk_")
        pieces = {secret[i : i + 12] for i in range(len(secret) - 11)}
        for where, text in sources.items():
            assert key not in text, f"the key {name!r} is in the {where}"
            found = [p for p in pieces if p in text]
            assert not found, f"12 characters of the key {name!r} are in the {where}: {found}"
            assert digest_of(key).hex() not in text, f"the digest of {name!r} is in the {where}"

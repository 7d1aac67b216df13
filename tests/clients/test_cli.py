"""The ``motion-style`` command against the real service in a subprocess: a folder of
mixed rigs with a broken file, the fast styles, dance, and 503 + Retry-After from a
load-shedding proxy in front of the service (as nginx's limit_req answers)."""

from __future__ import annotations

import subprocess
import sys
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import httpx
import numpy as np
import pytest
import soundfile

from motion import bvh
from motion import canonical as C
from motion import kinematics as K
from tests.rigs import load_fixture, variants
from tests.server import ServerProcess
from training.songs import SR, song

COMMAND = Path(sys.executable).parent / "motion-style"


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    log = tmp_path_factory.mktemp("cli-server") / "server.log"
    with ServerProcess(log_path=log) as running:
        yield running


@pytest.fixture(scope="module")
def mixed_rigs(tmp_path_factory) -> Path:
    """Seven presentations of one walk (names, channel orders, rest poses, frames, Z up),
    one in a subfolder, and a BVH cut off mid-hierarchy."""
    folder = tmp_path_factory.mktemp("rigs")
    walk = load_fixture().slice(0, 60)
    (folder / "more").mkdir()
    for k, (name, clip) in enumerate(variants(walk).items()):
        bvh.save(clip, folder / ("more" if k == 0 else ".") / f"{name}.bvh")
    (folder / "broken.bvh").write_text(bvh.dumps(walk)[:400])
    (folder / "notes.txt").write_text("not a clip: skipped by suffix")
    return folder


def motion_style(*args: str, timeout: float = 240) -> subprocess.CompletedProcess:
    assert COMMAND.exists(), f"{COMMAND} missing: `pip install -e .[client]` installs it"
    return subprocess.run([str(COMMAND), *args], capture_output=True, text=True, timeout=timeout)


def test_transfer_over_a_folder_of_mixed_rigs_names_the_broken_file(server, mixed_rigs, tmp_path):
    out = tmp_path / "out"
    result = motion_style(
        "transfer", str(mixed_rigs), "--style", "elderly", "--strength", "0.8",
        "--url", server.url, "-o", str(out), "--jobs", "3",
    )  # fmt: skip
    assert result.returncode == 1, result.stderr
    sources = sorted(p.relative_to(mixed_rigs) for p in mixed_rigs.rglob("*.bvh"))
    written = sorted(p.relative_to(out) for p in out.rglob("*.bvh"))
    assert written == [p for p in sources if p.name != "broken.bvh"]
    assert "7 of 8 files written" in result.stderr
    failed = [line for line in result.stderr.splitlines() if line.startswith("failed:")]
    assert len(failed) == 1 and "broken.bvh: 400" in failed[0], result.stderr
    for path in written:  # each result is on its input's rig, restyled
        source, result_clip = bvh.load(mixed_rigs / path), bvh.load(out / path)
        assert result_clip.skeleton.names == source.skeleton.names
        assert result_clip.fps == pytest.approx(source.fps, rel=1e-4)
        assert not np.allclose(result_clip.lrot[: min(source.num_frames, result_clip.num_frames)],
                               source.lrot[: min(source.num_frames, result_clip.num_frames)], atol=1e-3)  # fmt: skip


def test_stylize_and_dance_write_beside_each_name(server, mixed_rigs, tmp_path):
    clips = [str(mixed_rigs / "biped_xyz_6ch.bvh"), str(mixed_rigs / "more" / "cmu.bvh")]
    result = motion_style("stylize", *clips, "--style", "angry", "--url", server.url,
                          "-o", str(tmp_path / "fast"), "-q")  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert sorted(p.name for p in (tmp_path / "fast").iterdir()) == ["biped_xyz_6ch.bvh", "cmu.bvh"]

    songs = tmp_path / "songs"
    songs.mkdir()
    for k, seconds in enumerate((2.0, 3.0)):
        soundfile.write(songs / f"song{k}.wav", song(seconds, seed=k), SR)
    rig = mixed_rigs / "more" / "cmu.bvh"
    result = motion_style("dance", str(songs), "--skeleton", str(rig), "--fps", "24",
                          "--url", server.url, "-o", str(tmp_path / "dance"))  # fmt: skip
    assert result.returncode == 0, result.stderr
    for k, seconds in enumerate((2.0, 3.0)):
        dance = bvh.load(tmp_path / "dance" / f"song{k}.bvh")
        assert dance.fps == pytest.approx(24) and dance.num_frames == round(seconds * 24)
        assert dance.skeleton.names == bvh.load(rig).skeleton.names
    # no genre given: each song says what the service predicted and the tempo it danced to
    danced = [line for line in result.stderr.splitlines() if line.startswith("danced: ")]
    assert len(danced) == 2 and all(" bpm, beat alignment " in line for line in danced), danced
    assert sum("predicted" in line for line in result.stderr.splitlines()) == 2, result.stderr


def test_a_dance_in_place_reaches_the_service(server, tmp_path):
    songs = tmp_path / "songs"
    songs.mkdir()
    soundfile.write(songs / "song.wav", song(20.0, seed=4), SR)
    travel = {}
    for mode in ("keep", "in_place"):
        result = motion_style("dance", str(songs), "--root-motion", mode, "--seed", "2",
                              "--url", server.url, "-o", str(tmp_path / mode), "-q")  # fmt: skip
        assert result.returncode == 0, result.stderr
        dance = bvh.load(tmp_path / mode / "song.bvh")
        hips = K.global_positions(dance)[:, C.INDEX["Hips"]][:, [0, 2]]
        travel[mode] = np.ptp(hips, axis=0).max() / C.body_height()
    assert travel["in_place"] < 0.02 < 0.3 < travel["keep"], travel


def test_game_options_and_every_kind_of_style(server, tmp_path):
    """--keep-timing, --root-motion, --loop reach the service (no time warp, the hips held
    in place, the clip taken as a loop), and a style comes by --mix or --style-clip too."""
    from motion import kinematics as K
    from motion import retarget
    from tests.rigs import walk_cycle

    clip = tmp_path / "cycle.bvh"
    cycle = walk_cycle()
    bvh.save(cycle, clip)
    style_clip = tmp_path / "style.bvh"
    bvh.save(load_fixture().slice(0, 60), style_clip)
    rig = retarget.make_rig(cycle.skeleton, cycle)
    hips = rig.mapping["Hips"]
    for family, style in (("transfer", ["--mix", '{"happy": 0.5, "proud": 0.5}']),
                          ("transfer", ["--style-clip", str(style_clip)]),
                          ("stylize", ["--style", "active"])):  # fmt: skip
        out = tmp_path / f"{family}-{style[0][2:]}"
        result = motion_style(family, str(clip), *style, "--keep-timing", "--root-motion",
                              "in_place", "--loop", "true", "--url", server.url, "-o", str(out),
                              "-q")  # fmt: skip
        assert result.returncode == 0, result.stderr
        answer = bvh.load(out / "cycle.bvh")
        assert answer.num_frames == cycle.num_frames  # kept its timing
        travel = np.ptp(K.global_positions(answer)[:, hips, [0, 2]], axis=0).max()
        assert travel < 0.02 * rig.height  # in place
    result = motion_style("transfer", str(clip), "--style", "happy", "--mix", "{}",
                          "--url", server.url, "-o", str(tmp_path / "x"))  # fmt: skip
    assert result.returncode == 2 and "not allowed with" in result.stderr


def test_the_services_warnings_are_printed_for_each_file(server, tmp_path):
    """A BVH answer's warnings (``X-Warnings``) reach the user: a style clip of 5 frames is
    coded with a warning, which the command prints against the file it concerns."""
    clip = tmp_path / "walk.bvh"
    bvh.save(load_fixture().slice(0, 60), clip)
    style_clip = tmp_path / "short.bvh"
    bvh.save(load_fixture().slice(0, 5), style_clip)
    result = motion_style("transfer", str(clip), "--style-clip", str(style_clip),
                          "--url", server.url, "-o", str(tmp_path / "out"), "-q")  # fmt: skip
    assert result.returncode == 0, result.stderr
    warned = [line for line in result.stderr.splitlines() if line.startswith("warned: ")]
    assert any(str(clip) in w and "lasts 0.17 s" in w for w in warned), result.stderr


class SheddingProxy:
    """Forwards to the service, but answers 503 with Retry-After to the first ``shed``
    requests of every path it has not seen ``shed`` times (``shed=None``: every request)."""

    def __init__(self, upstream: str, shed: int | None, retry_after: str = "1") -> None:
        self.upstream, self.shed, self.retry_after = upstream, shed, retry_after
        self.shed_count = 0
        self.times: list[float] = []
        proxy = self

        class Handler(BaseHTTPRequestHandler):
            def do_POST(self):
                body = self.rfile.read(int(self.headers["Content-Length"]))
                proxy.times.append(time.monotonic())
                if proxy.shed is None or proxy.shed_count < proxy.shed:
                    proxy.shed_count += 1
                    self.send_response(503)
                    self.send_header("Retry-After", proxy.retry_after)
                    self.send_header("Content-Type", "application/problem+json")
                    payload = b'{"title": "Service Unavailable", "status": 503, "detail": "busy"}'
                    self.send_header("Content-Length", str(len(payload)))
                    self.end_headers()
                    self.wfile.write(payload)
                    return
                answer = httpx.post(
                    proxy.upstream + self.path, content=body, timeout=60,
                    headers={"Content-Type": self.headers["Content-Type"]},
                )  # fmt: skip
                self.send_response(answer.status_code)
                for key in ("Content-Type", "Content-Disposition"):
                    if key in answer.headers:
                        self.send_header(key, answer.headers[key])
                self.send_header("Content-Length", str(len(answer.content)))
                self.end_headers()
                self.wfile.write(answer.content)

            def log_message(self, *args):
                pass

        self.httpd = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.url = f"http://127.0.0.1:{self.httpd.server_address[1]}"
        self.thread = threading.Thread(target=self.httpd.serve_forever, daemon=True)

    def __enter__(self):
        self.thread.start()
        return self

    def __exit__(self, *exc):
        self.httpd.shutdown()
        self.httpd.server_close()


def test_503_with_retry_after_is_retried_after_the_delay(server, mixed_rigs, tmp_path):
    clips = [str(mixed_rigs / "more" / "cmu.bvh"), str(mixed_rigs / "mixamo_tpose_zxy.bvh")]
    with SheddingProxy(server.url, shed=2) as proxy:
        start = time.monotonic()
        result = motion_style("transfer", *clips, "--style", "angry", "--url", proxy.url,
                              "-o", str(tmp_path / "out"), "-j", "2")  # fmt: skip
        elapsed = time.monotonic() - start
    assert result.returncode == 0, result.stderr
    assert "2 of 2 files written" in result.stderr and "2 retries after 503" in result.stderr
    assert len(list((tmp_path / "out").iterdir())) == 2
    assert proxy.shed_count == 2 and len(proxy.times) == 4
    assert proxy.times[2] - proxy.times[0] >= 0.95  # waited the Retry-After second
    assert elapsed >= 1.0


def test_a_service_that_stays_busy_fails_each_file_after_bounded_retries(
    server, mixed_rigs, tmp_path
):
    clip = str(mixed_rigs / "more" / "cmu.bvh")
    with SheddingProxy(server.url, shed=None) as proxy:
        result = motion_style("transfer", clip, "--style", "angry", "--url", proxy.url,
                              "-o", str(tmp_path / "out"), "--retries", "2")  # fmt: skip
    assert result.returncode == 1
    assert "failed:" in result.stderr and "503" in result.stderr
    assert "gave up after 2 retries" in result.stderr
    assert len(proxy.times) == 3
    # a Retry-After longer than --max-wait is not waited for
    with SheddingProxy(server.url, shed=None, retry_after="3600") as proxy:
        start = time.monotonic()
        result = motion_style("transfer", clip, "--style", "angry", "--url", proxy.url,
                              "-o", str(tmp_path / "out"), "--max-wait", "10")  # fmt: skip
    assert result.returncode == 1 and time.monotonic() - start < 30
    assert len(proxy.times) == 1


def test_bad_arguments_and_missing_inputs(server, tmp_path):
    result = motion_style("transfer", str(tmp_path / "nothing.bvh"), "--style", "angry",
                          "--url", server.url, "-o", str(tmp_path / "out"))  # fmt: skip
    assert result.returncode == 1 and "no such file or folder" in result.stderr
    result = motion_style("transfer", str(tmp_path), "--style", "angry", "--strength", "3",
                          "--url", server.url, "-o", str(tmp_path / "out"))  # fmt: skip
    assert result.returncode == 2 and "--strength" in result.stderr
    clip = tmp_path / "walk.bvh"
    bvh.save(load_fixture().slice(0, 40), clip)
    result = motion_style("transfer", str(clip), "--style", "no-such-style",
                          "--url", server.url, "-o", str(tmp_path / "out"))  # fmt: skip
    assert result.returncode == 1 and "walk.bvh: 404" in result.stderr


def test_fbx_files_go_through_and_come_back_as_fbx(server, tmp_path):
    from tests.fbx_files import make_fbx_files
    from tests.rigs import FIXTURE

    made = make_fbx_files(FIXTURE, tmp_path)
    result = motion_style("stylize", str(made["character"]), "--style", "angry",
                          "--url", server.url, "-o", str(tmp_path / "fast"), "-q")  # fmt: skip
    assert result.returncode == 0, result.stderr
    answer = tmp_path / "fast" / "character.fbx"
    assert answer.read_bytes().startswith(b"Kaydara FBX Binary")

    songs = tmp_path / "songs"
    songs.mkdir()
    soundfile.write(songs / "song.wav", song(2.0), SR)
    result = motion_style("dance", str(songs), "--skeleton", str(made["bare"]),
                          "--url", server.url, "-o", str(tmp_path / "dance"))  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert (tmp_path / "dance" / "song.fbx").read_bytes().startswith(b"Kaydara FBX Binary")

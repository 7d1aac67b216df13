"""End-to-end HTTP latency of the real service on loopback, per model family: p50/p95 for
240, 960 and 3,840-frame inputs, how the cost grows with length, and throughput at 1, 2, 4
and 8 concurrent clients for the 960-frame case.

    python -m bench.bench_http [--repeats 10] [--json]
    python -m bench.bench_http --repeats 1 --lengths 240 --clients 1 2 --families fast
    python -m bench.bench_http --url http://127.0.0.1:8000   # a running server, e.g. a container

Starts ``python -m service`` on a free loopback port (``bench.load``'s helpers; the
``MOTION_*`` environment passes on to it, so ``MOTION_INTRA_OP_THREADS`` sets its threads)
and waits for ``/readyz``. Requests, one family at a time:

- fast: ``POST /v1/stylize``, a BVH content clip and the first fast style of ``/v1/styles``;
- translator: ``POST /v1/transfer``, the same clip and the first translator ``style_name``;
- dance: ``POST /v1/dance``, a synthetic song (``training/songs.py``, WAV) of 8, 32 or 128 s,
  i.e. 240, 960 or 3,840 frames at 30 fps.

The content clip is a Bandai walk (shared data) when present, else the CMU fixture, looped
to the length (each pass restarts at the frame most like the first, the travelling joint
carried on, so the walk goes on). A family without a model in the manifest is skipped with
a line saying so. Each case gets one warm-up request first (the server sees a new shape).
Latency: the client's wall time from sending the request to reading the whole response,
over ``--repeats`` sequential requests. Cost growth: milliseconds per 1,000 frames at each
length, and p50 at 3,840 over p50 at 240 (16 would be linear). Throughput: ``clients``
threads with one keep-alive connection each send ``max(repeats, 2 x clients)`` requests in
all; requests/s over the wall time, p95 over all of them. The client runs on the same
machine as the server and takes some of its CPU. Any response but 2xx is an error; the
script exits 1 when there was one. The server is stopped at the end, errors included.
"""

from __future__ import annotations

import argparse
import http.client
import json
import math
import os
import subprocess
import sys
import threading
import time
import uuid
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import urlsplit

import numpy as np

from bench.bench_translator import FIXTURE
from bench.load import _start_server, percentile, require_loopback, rss_mb
from motion import bvh
from motion.skeleton import Motion

LENGTHS = (240, 960, 3840)
CLIENTS = (1, 2, 4, 8)
THROUGHPUT_FRAMES = 960
FAMILIES = ("fast", "translator", "dance")
FPS = 30.0
TIMEOUT_S = 600.0
# Server-Timing stages that are the networks themselves (onnxruntime runs): the rest of a
# request's time is parsing, retargeting, features, clean-up, writing and HTTP
NETWORK_STAGES = frozenset(
    {"encode", "decode", "network", "step"}
)  # the client's socket timeout; the server answers 504 after its own limit


@dataclass
class Case:
    """One request, encoded once: the path, the multipart body and its content type."""

    family: str
    frames: int
    path: str
    body: bytes
    content_type: str
    what: str


def multipart(
    fields: dict[str, str], files: dict[str, tuple[str, bytes, str]]
) -> tuple[bytes, str]:
    """A ``multipart/form-data`` body of text ``fields`` and ``files`` (name -> (filename,
    bytes, media type)), and its content type."""
    boundary = f"bench-{uuid.uuid4().hex}"
    parts: list[bytes] = []
    for name, value in fields.items():
        parts.append(
            f'--{boundary}\r\nContent-Disposition: form-data; name="{name}"\r\n\r\n'.encode()
            + value.encode()
            + b"\r\n"
        )
    for name, (filename, data, media) in files.items():
        head = (
            f'--{boundary}\r\nContent-Disposition: form-data; name="{name}"; '
            f'filename="{filename}"\r\nContent-Type: {media}\r\n\r\n'
        )
        parts.append(head.encode() + data + b"\r\n")
    parts.append(f"--{boundary}--\r\n".encode())
    return b"".join(parts), f"multipart/form-data; boundary={boundary}"


def looped(motion: Motion, frames: int) -> Motion:
    """``frames`` frames of ``motion`` (a walk) played as a loop: each pass restarts at frame 0
    from the frame of the clip's second half whose pose is most like frame 0, and the joint
    that travels (largest horizontal range, Y up) is carried on by each pass's displacement,
    so the character keeps walking instead of jumping back."""
    if frames <= motion.num_frames:
        return motion.slice(0, frames)
    q = motion.lrot[:, 1:]
    distance = (1.0 - np.abs(np.sum(q * q[:1], axis=-1))).sum(axis=-1)  # (F,)
    half = max(1, motion.num_frames // 2)
    period = half + int(np.argmin(distance[half:])) if motion.num_frames > 1 else 1
    index = np.arange(frames) % period
    passes = np.arange(frames) // period
    horizontal = np.ptp(motion.lpos[:, :, [0, 2]], axis=0).max(axis=-1)  # (J,)
    joint = int(np.argmax(horizontal))
    lrot = motion.lrot[index]
    lpos = motion.lpos[index].copy()
    if period < motion.num_frames:
        step = motion.lpos[period, joint] - motion.lpos[0, joint]
        step[1] = 0.0
        lpos[:, joint] += passes[:, None] * step
    return motion.replace(lrot=lrot, lpos=lpos)


def content_clip(frames: int, data_dir: Path) -> tuple[str, bytes]:
    """``(description, BVH bytes)``: the Bandai walk (shared data) when present, else the CMU
    fixture, looped to ``frames`` frames; the same source for every length."""
    walk = data_dir / "bandai" / "dataset-1" / "dataset-1_walk_proud_001.bvh"
    source = walk if walk.exists() else FIXTURE
    name = f"Bandai {walk.stem}" if walk.exists() else "CMU fixture"
    motion = bvh.load(source)
    how = "cut" if frames <= motion.num_frames else "looped"
    return f"{name} ({motion.num_frames} frames) {how}", bvh.dumps(looped(motion, frames)).encode()


def song_clip(frames: int) -> tuple[str, bytes]:
    """``(description, WAV bytes)`` of a synthetic song that gives ``frames`` frames at 30 fps."""
    from training.songs import encoded, song

    seconds = frames / FPS
    return f"synthetic song {seconds:g} s WAV", encoded(song(seconds), "WAV")


def request(conn: http.client.HTTPConnection, case: Case, tag: str) -> tuple[int, bytes, dict]:
    """Send ``case`` on ``conn``; ``(status, body, headers)``."""
    headers = {"Content-Type": case.content_type, "X-Request-Id": tag}
    conn.request("POST", case.path, body=case.body, headers=headers)
    response = conn.getresponse()
    body = response.read()
    return response.status, body, {k.lower(): v for k, v in response.getheaders()}


class Client:
    """One keep-alive connection; records latencies and errors."""

    def __init__(self, host: str, port: int) -> None:
        self.host, self.port = host, port
        self.conn: http.client.HTTPConnection | None = None
        self.latencies_ms: list[float] = []
        self.stages_ms: list[dict[str, float]] = []  # Server-Timing of each recorded answer
        self.errors: list[str] = []
        self.frames_out: str | None = None

    def send(self, case: Case, tag: str, record: bool = True) -> None:
        began = time.perf_counter()
        try:
            if self.conn is None:
                self.conn = http.client.HTTPConnection(self.host, self.port, timeout=TIMEOUT_S)
            status, body, headers = request(self.conn, case, tag)
            if headers.get("connection", "").lower() == "close":
                self.close()
        except (OSError, http.client.HTTPException) as exc:
            self.close()
            status, body, headers = 0, f"{type(exc).__name__}: {exc}".encode(), {}
        elapsed = (time.perf_counter() - began) * 1000.0
        if not 200 <= status < 300:
            self.errors.append(
                f"{case.family} {case.frames} frames: "
                f"{'HTTP ' + str(status) if status else 'failed'}: {body[:300].decode(errors='replace')}"
            )
        elif record:
            self.latencies_ms.append(elapsed)
            self.stages_ms.append(server_timing(headers.get("server-timing", "")))
            self.frames_out = headers.get("x-frames", self.frames_out)

    def close(self) -> None:
        if self.conn is not None:
            self.conn.close()
            self.conn = None


def server_timing(header: str) -> dict[str, float]:
    """``{"decode": 12.3, ...}`` from a ``Server-Timing`` header (``name;dur=ms, ...``)."""
    out = {}
    for item in header.split(","):
        name, _, rest = item.strip().partition(";")
        if name and rest.startswith("dur="):
            out[name] = float(rest[4:])
    return out


def get_json(host: str, port: int, path: str) -> dict:
    conn = http.client.HTTPConnection(host, port, timeout=30)
    try:
        conn.request("GET", path)
        response = conn.getresponse()
        body = response.read()
        if response.status != 200:
            raise RuntimeError(f"GET {path}: HTTP {response.status}: {body[:300]!r}")
        return json.loads(body)
    finally:
        conn.close()


def build_cases(families: list[str], lengths: list[int], styles: dict, data_dir: Path) -> dict:
    """``{(family, frames): Case}`` for every family and length."""
    cases = {}
    for frames in lengths:
        clip = None
        for family in families:
            if family == "dance":
                what, data = song_clip(frames)
                body, ctype = multipart({"seed": "0"}, {"audio": ("song.wav", data, "audio/wav")})
                path = "/v1/dance"
            else:
                clip = clip or content_clip(frames, data_dir)
                what, data = clip
                name = styles[family]
                body, ctype = multipart(
                    {"style_name": name}, {"content": ("content.bvh", data, "text/plain")}
                )
                path = "/v1/stylize" if family == "fast" else "/v1/transfer"
                what = f"{what}, style {name!r}"
            cases[family, frames] = Case(family, frames, path, body, ctype, what)
    return cases


def latency(host: str, port: int, case: Case, repeats: int) -> tuple[dict, list[str]]:
    """One warm-up, then ``repeats`` sequential requests on one connection."""
    client = Client(host, port)
    try:
        client.send(case, f"bench-{case.family}-{case.frames}-warm", record=False)
        for i in range(repeats):
            client.send(case, f"bench-{case.family}-{case.frames}-{i}")
    finally:
        client.close()
    ms = sorted(client.latencies_ms)
    p50 = percentile(ms, 50)
    names = list(dict.fromkeys(k for stages in client.stages_ms for k in stages))
    stages = {k: float(np.median([s.get(k, 0.0) for s in client.stages_ms])) for k in names}
    network = sorted(sum(v for k, v in s.items() if k in NETWORK_STAGES) for s in client.stages_ms)
    network_p50 = percentile(network, 50) if network else None
    row = {
        "family": case.family,
        "frames": case.frames,
        "requests": len(ms),
        "errors": len(client.errors),
        "p50_ms": round(p50, 1) if ms else None,
        "p95_ms": round(percentile(ms, 95), 1) if ms else None,
        "ms_per_1000_frames": round(p50 / case.frames * 1000.0, 1) if ms else None,
        "network_ms": round(network_p50, 1) if network_p50 else None,
        "end_to_end_over_network": round(p50 / network_p50, 2) if ms and network_p50 else None,
        "stages_ms": {k: round(v, 1) for k, v in stages.items()},
        "frames_out": int(client.frames_out) if client.frames_out else None,
        "upload_bytes": len(case.body),
        "input": case.what,
    }
    return row, client.errors


def throughput(host: str, port: int, case: Case, clients: int, total: int) -> tuple[dict, list]:
    """``clients`` threads, one keep-alive connection each, ``total`` requests in all."""
    per_client = math.ceil(total / clients)
    pool = [Client(host, port) for _ in range(clients)]
    barrier = threading.Barrier(clients + 1)

    def work(k: int) -> None:
        barrier.wait()
        for i in range(per_client):
            pool[k].send(case, f"bench-{case.family}-c{clients}-{k}-{i}")
        pool[k].close()

    threads = [threading.Thread(target=work, args=(k,), daemon=True) for k in range(clients)]
    for thread in threads:
        thread.start()
    barrier.wait()
    began = time.perf_counter()
    for thread in threads:
        thread.join()
    elapsed = time.perf_counter() - began
    ms = sorted(x for c in pool for x in c.latencies_ms)
    errors = [e for c in pool for e in c.errors]
    row = {
        "family": case.family,
        "frames": case.frames,
        "clients": clients,
        "requests": len(ms),
        "errors": len(errors),
        "seconds": round(elapsed, 2),
        "requests_per_s": round(len(ms) / elapsed, 2) if elapsed > 0 else 0.0,
        "p50_ms": round(percentile(ms, 50), 1) if ms else None,
        "p95_ms": round(percentile(ms, 95), 1) if ms else None,
    }
    return row, errors


def growth(rows: list[dict]) -> dict:
    """Per family: p50 at the longest length over p50 at the shortest (and the frame ratio)."""
    out = {}
    for family in dict.fromkeys(r["family"] for r in rows):
        mine = [r for r in rows if r["family"] == family and r["p50_ms"]]
        mine.sort(key=lambda r: r["frames"])
        if len(mine) < 2:
            continue
        short, long = mine[0], mine[-1]
        out[family] = {
            "from_frames": short["frames"],
            "to_frames": long["frames"],
            "frames_ratio": round(long["frames"] / short["frames"], 2),
            "p50_ratio": round(long["p50_ms"] / short["p50_ms"], 2),
        }
    return out


def _ms(value: float | None) -> str:
    """A table cell: ``-`` where every request failed."""
    return "-" if value is None else f"{value:.1f}"


def main(argv: list[str] | None = None) -> dict:
    from service.config import Settings, available_cpus
    from service.manifest import load_manifest
    from training.data import data_dir

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--repeats", type=int, default=10, help="requests per latency case")
    p.add_argument("--lengths", type=int, nargs="+", default=list(LENGTHS), help="frames")
    p.add_argument("--clients", type=int, nargs="*", default=list(CLIENTS), help="none: skip")
    p.add_argument("--throughput-frames", type=int, default=THROUGHPUT_FRAMES)
    p.add_argument("--families", nargs="+", default=list(FAMILIES), choices=FAMILIES)
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    p.add_argument("--url", help="a running server (loopback only: a container's published port)")
    args = p.parse_args(argv)
    if args.repeats < 1 or any(n < 2 for n in args.lengths) or any(c < 1 for c in args.clients):
        p.error("--repeats and --clients must be >= 1, --lengths >= 2")

    note = sys.stderr if args.json else sys.stdout  # keep --json output pure JSON
    settings = Settings()
    entries = [m for folder in settings.models_dir for m in load_manifest(folder).models]
    shipped = {m.family for m in entries}
    skipped = {}
    families = []
    for family in args.families:
        if family in shipped:
            families.append(family)
        else:
            skipped[family] = (
                f"no {family} model in {os.pathsep.join(map(str, settings.models_dir))}"
            )
            print(f"{family}: skipped, {skipped[family]}", file=note)

    process, url = (None, args.url) if args.url else _start_server(1)
    try:
        parts = urlsplit(url)
        host, port = parts.hostname or "127.0.0.1", parts.port or 80
        require_loopback(host)
        styles_listed = get_json(host, port, "/v1/styles")
        styles = {}
        for family in list(families):
            if family == "dance":
                continue
            names = [s["name"] for s in styles_listed.get(family, [])]
            if not names:
                skipped[family] = f"the server lists no {family} style"
                print(f"{family}: skipped, {skipped[family]}", file=note)
                families.remove(family)
            else:
                styles[family] = names[0]
        lengths = list(dict.fromkeys(args.lengths))
        tp_lengths = [args.throughput_frames] if args.clients else []
        cases = build_cases(families, list(dict.fromkeys(lengths + tp_lengths)), styles, data_dir())
        errors: list[str] = []
        rows = []
        for family in families:
            for frames in lengths:
                row, errs = latency(host, port, cases[family, frames], args.repeats)
                rows.append(row)
                errors += errs
        tp_rows = []
        for family in families:
            if args.clients and args.throughput_frames not in lengths:  # warm its shape up
                warm = Client(host, port)
                warm.send(cases[family, args.throughput_frames], "bench-warm", record=False)
                warm.close()
                errors += warm.errors
            for clients in args.clients:
                total = max(args.repeats, 2 * clients)
                case = cases[family, args.throughput_frames]
                row, errs = throughput(host, port, case, clients, total)
                tp_rows.append(row)
                errors += errs
        server_rss = rss_mb(process.pid) if process else float("nan")
    finally:
        if process:
            process.terminate()
            try:
                process.wait(30)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait(10)

    report = {
        "url": url,
        "cores": available_cpus(),
        "intra_op_threads": settings.intra_op_threads,
        "max_concurrent_inferences": settings.max_concurrent_inferences,
        "repeats": args.repeats,
        "models": {m.family: f"{m.name}/{m.version}" for m in entries},
        "styles": styles,
        "latency": rows,
        "growth": growth(rows),
        "throughput": tp_rows,
        "server_rss_mb": round(server_rss, 1),
        "skipped": skipped,
        "errors": len(errors),
        "error_samples": errors[:10],
    }
    if args.json:
        print(json.dumps(report, indent=1))
    else:
        print(
            f"loopback server, {report['intra_op_threads']} intra-op threads, "
            f"{report['max_concurrent_inferences']} concurrent inferences ({report['cores']} "
            f"cores); {args.repeats} requests per case after one warm-up"
        )
        print("\n| family | frames | p50 ms | p95 ms | ms per 1000 frames |")
        print("|---|---:|---:|---:|---:|")
        for r in rows:
            print(
                f"| {r['family']} | {r['frames']} | {_ms(r['p50_ms'])} | {_ms(r['p95_ms'])} "
                f"| {_ms(r['ms_per_1000_frames'])} |"
            )
        print(
            "\nEnd to end (client p50) over the networks' own time (Server-Timing stages "
            f"{', '.join(sorted(NETWORK_STAGES))}, median), measured in this run:"
        )
        print("\n| family | frames | p50 ms | networks ms | ratio | other stages (median ms) |")
        print("|---|---:|---:|---:|---:|---|")
        for r in rows:
            other = ", ".join(
                f"{k} {v:.0f}" for k, v in r["stages_ms"].items() if k not in NETWORK_STAGES
            )
            ratio = r["end_to_end_over_network"]
            print(
                f"| {r['family']} | {r['frames']} | {_ms(r['p50_ms'])} | {_ms(r['network_ms'])} "
                f"| {'-' if ratio is None else f'{ratio:.2f}'} | {other} |"
            )
        for family, g in report["growth"].items():
            print(
                f"{family}: p50 at {g['to_frames']} / at {g['from_frames']} frames = "
                f"{g['p50_ratio']:.2f} (frames x{g['frames_ratio']:g})"
            )
        if tp_rows:
            print(f"\n| family | clients | req/s | p95 ms |  ({args.throughput_frames} frames)")
            print("|---|---:|---:|---:|")
            for r in tp_rows:
                print(
                    f"| {r['family']} | {r['clients']} | {r['requests_per_s']:.2f} "
                    f"| {_ms(r['p95_ms'])} |"
                )
        print(f"\nserver RSS at the end: {report['server_rss_mb']:.0f} MB")
        inputs = {f"{r['family']}/{r['frames']}": r["input"] for r in rows}
        for key, what in inputs.items():
            print(f"  {key}: {what}")
    for sample in errors[:10]:
        print("error:", sample, file=sys.stderr)
    if errors:
        sys.exit(1)
    return report


if __name__ == "__main__":
    main()

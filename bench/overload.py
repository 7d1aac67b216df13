"""Overload: many clients each send a long transfer at once to a fresh loopback server.

    python -m bench.overload [--clients 48] [--frames 3840]

Every answer must be 200, or 503 with ``Retry-After`` (the bounded queue shedding what
cannot start within ``MOTION_QUEUE_WAIT_S``); prints the answers by status, the slowest
answer of each kind, and the server's peak RSS (sampled every 50 ms while the clients
run). Exits 1 when an answer is anything else, a 503 lacks ``Retry-After``, or a client
waited more than ``--max-wait`` seconds. The ``MOTION_*`` environment passes on to the
server.
"""

from __future__ import annotations

import argparse
import http.client
import json
import sys
import threading
import time
from collections import Counter
from concurrent.futures import ThreadPoolExecutor
from urllib.parse import urlsplit

from bench.bench_http import content_clip, multipart
from bench.load import _start_server, require_loopback, rss_mb


def send(host: str, port: int, body: bytes, content_type: str) -> tuple[int, str, float]:
    """``(status, Retry-After, seconds)`` of one ``POST /v1/transfer``."""
    started = time.perf_counter()
    conn = http.client.HTTPConnection(host, port, timeout=600)
    try:
        conn.request("POST", "/v1/transfer", body=body, headers={"Content-Type": content_type})
        response = conn.getresponse()
        response.read()
        return (
            response.status,
            response.getheader("Retry-After") or "",
            time.perf_counter() - started,
        )
    except (OSError, http.client.HTTPException):
        return 0, "", time.perf_counter() - started
    finally:
        conn.close()


def main(argv: list[str] | None = None) -> int:
    from training.data import data_dir

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--clients", type=int, default=48)
    p.add_argument("--frames", type=int, default=3840)
    p.add_argument("--max-wait", type=float, default=30.0, help="seconds; longer fails")
    args = p.parse_args(argv)

    what, clip = content_clip(args.frames, data_dir())
    process, url = _start_server(1)
    try:
        parts = urlsplit(url)
        host, port = parts.hostname or "127.0.0.1", parts.port or 80
        require_loopback(host)
        conn = http.client.HTTPConnection(host, port, timeout=30)
        conn.request("GET", "/v1/styles")
        style = json.loads(conn.getresponse().read())["translator"][0]["name"]
        conn.close()
        body, ctype = multipart({"style_name": style}, {"content": ("c.bvh", clip, "text/plain")})
        send(host, port, body, ctype)  # warm-up: the shapes of this length
        idle_rss = rss_mb(process.pid)
        peak = [idle_rss]
        done = threading.Event()

        def sample() -> None:
            while not done.wait(0.05):
                peak[0] = max(peak[0], rss_mb(process.pid))

        sampler = threading.Thread(target=sample, daemon=True)
        sampler.start()
        started = time.perf_counter()
        with ThreadPoolExecutor(args.clients) as pool:
            answers = list(pool.map(lambda _: send(host, port, body, ctype), range(args.clients)))
        wall = time.perf_counter() - started
        done.set()
        sampler.join()
    finally:
        process.terminate()
        process.wait(30)

    statuses = Counter(status for status, _, _ in answers)
    print(
        f"{args.clients} clients at once, each POST /v1/transfer of {args.frames} frames "
        f"({what}, style {style!r}, {len(body) / 1e6:.1f} MB): all answered in {wall:.1f} s"
    )
    for status in sorted(statuses):
        waits = [s for code, _, s in answers if code == status]
        print(f"  {status or 'no answer'}: {statuses[status]}, slowest after {max(waits):.1f} s")
    print(f"server RSS: {idle_rss:.0f} MB idle after a warm-up, peak {peak[0]:.0f} MB")
    bad = [a for a in answers if a[0] not in (200, 503) or (a[0] == 503 and not a[1])]
    slow = [a for a in answers if a[2] > args.max_wait]
    if bad:
        print(f"FAIL: {len(bad)} answers neither 200 nor 503 with Retry-After", file=sys.stderr)
    if slow:
        print(f"FAIL: {len(slow)} clients waited over {args.max_wait:g} s", file=sys.stderr)
    return 1 if bad or slow else 0


if __name__ == "__main__":
    sys.exit(main())

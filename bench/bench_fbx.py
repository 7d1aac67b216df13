"""An FBX transfer against the same character's GLB transfer, end to end over HTTP, in one run.

    python -m bench.bench_fbx [--repeats 20] [--segments 12] [--path /v1/transfer]

Blender as a Python module (the ``fbx`` extra) exports one character twice from the CMU
fixture (``tests/blender/fbx_tool.py make``: the armature Blender imports from the BVH, a
skinned body of one tube of SEGMENTS x SEGMENTS vertices per bone, a material): as FBX and
as GLB. ``python -m service`` starts on a free loopback port; one warm-up request of each
(the Blender workers are warm before the first FBX is timed), then ``--repeats`` pairs of
``POST /v1/transfer`` (``style_name=elderly``), the GLB and the FBX alternating which goes
first. Each FBX sent is a new file (16 random bytes after its end, which readers skip), so
no Blender worker holds it already and every request imports it, as a new clip would be;
``--same-file`` sends the same bytes each time (the worker that read it last keeps it
imported). Latency is the client's wall time per request; the table gives p50 and p95 of each,
the ratio of the p50s, and the median of each Server-Timing stage. Needs bpy; exits 1 on
any answer but 200; says it skipped, and exits 0, without bpy.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx

from bench.load import _start_server, percentile

REPO = Path(__file__).resolve().parent.parent
FBX_TOOL = REPO / "tests" / "blender" / "fbx_tool.py"
FIXTURE = REPO / "tests" / "data" / "cmu_02_01_walk_30fps.bvh"


def make_character(folder: Path, segments: int) -> dict[str, bytes]:
    subprocess.run(
        [sys.executable, str(FBX_TOOL), "make", str(FIXTURE), str(folder), str(segments)],
        check=True, capture_output=True, timeout=600,
    )  # fmt: skip
    return {
        "glb": (folder / "character.glb").read_bytes(),
        "fbx": (folder / "character.fbx").read_bytes(),
    }


def stages(header: str) -> dict[str, float]:
    out = {}
    for part in header.split(","):
        name, _, rest = part.strip().partition(";dur=")
        if rest:
            out[name] = float(rest)
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=20)
    parser.add_argument("--segments", type=int, default=12)
    parser.add_argument("--path", default="/v1/transfer")
    parser.add_argument("--style", default="elderly")
    parser.add_argument("--same-file", action="store_true", help="the same FBX bytes each time")
    parser.add_argument("--json", action="store_true", help="print the table as JSON")
    args = parser.parse_args(argv)
    if importlib.util.find_spec("bpy") is None:
        print("bench_fbx: skipped, Blender as a Python module (the fbx extra) is not installed")
        return 0

    with tempfile.TemporaryDirectory(prefix="bench-fbx-") as folder:
        files = make_character(Path(folder), args.segments)
    process, url = _start_server(1)
    times: dict[str, list[float]] = {"glb": [], "fbx": []}
    timings: dict[str, list[dict[str, float]]] = {"glb": [], "fbx": []}
    try:
        with httpx.Client(base_url=url, timeout=600) as client:

            def send(kind: str) -> float:
                data = files[kind]
                if kind == "fbx" and not args.same_file:
                    data += os.urandom(16)
                start = time.perf_counter()
                r = client.post(
                    args.path,
                    files={"content": (f"character.{kind}", data)},
                    data={"style_name": args.style},
                )
                took = time.perf_counter() - start
                if r.status_code != 200:
                    raise SystemExit(f"{kind}: {r.status_code} {r.text[:300]}")
                timings[kind].append(stages(r.headers.get("server-timing", "")))
                return took

            send("glb"), send("fbx")  # warm-up: new shapes, the Blender pool started
            timings = {"glb": [], "fbx": []}
            for i in range(args.repeats):
                for kind in ("glb", "fbx") if i % 2 == 0 else ("fbx", "glb"):
                    times[kind].append(send(kind))
    finally:
        process.terminate()
        process.wait(30)

    table = {
        "path": args.path,
        "repeats": args.repeats,
        "same_file": args.same_file,
        "bytes": {k: len(v) for k, v in files.items()},
    }
    for kind in ("glb", "fbx"):
        ms = sorted(1000 * t for t in times[kind])
        names = {n for t in timings[kind] for n in t}
        table[kind] = {
            "p50_ms": round(percentile(ms, 50), 1),
            "p95_ms": round(percentile(ms, 95), 1),
            "stages_ms": {
                n: round(statistics.median(t.get(n, 0.0) for t in timings[kind]), 1)
                for n in sorted(names)
            },
        }
    table["fbx_over_glb_p50"] = round(table["fbx"]["p50_ms"] / table["glb"]["p50_ms"], 2)
    if args.json:
        print(json.dumps(table, indent=2))
    else:
        same = "the same FBX file" if args.same_file else "a new FBX file"
        print(f"{args.path}, {args.repeats} pairs, {same} each time, bytes {table['bytes']}")
        for kind in ("glb", "fbx"):
            row = table[kind]
            stage = ", ".join(f"{n} {v:g}" for n, v in row["stages_ms"].items())
            print(f"  {kind}: p50 {row['p50_ms']:.0f} ms, p95 {row['p95_ms']:.0f} ms ({stage})")
        print(f"  FBX p50 / GLB p50: {table['fbx_over_glb_p50']:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Command line for pipelines.

    python -m motion info FILE.bvh                      JSON: joints, frames, fps, mapping
                                                        (how it was found, a confidence)
    python -m motion canonical IN.bvh -o OUT.bvh        onto the canonical skeleton, 30 fps
    python -m motion retarget IN.bvh --onto T.bvh -o OUT.bvh

Errors go to stderr as one line and exit with status 2.
"""

from __future__ import annotations

import argparse
import json
import sys

from motion import bvh, retarget
from motion import canonical as C
from motion.errors import MotionError


def _mapping_arg(text: str | None) -> dict[str, str] | None:
    if not text:
        return None
    try:
        value = json.loads(text)
    except json.JSONDecodeError as e:
        raise MotionError(f"--mapping is not JSON: {e.msg}") from None
    if not isinstance(value, dict) or not all(isinstance(v, str) for v in value.values()):
        raise MotionError("--mapping must be a JSON object of joint name -> joint name")
    return value


def cmd_info(args: argparse.Namespace) -> dict:
    m = bvh.load(args.file)
    sk = m.skeleton
    out: dict = {
        "file": args.file,
        "joints": list(sk.names),
        "channels": {n: list(c) for n, c in zip(sk.names, sk.channels, strict=True)},
        "frames": m.num_frames,
        "fps": round(m.fps, 6),
        "duration_s": round(m.duration, 6),
        "height": round(sk.height(), 4),
    }
    try:
        rig = retarget.make_rig(sk, m, _mapping_arg(args.mapping))
    except MotionError as e:
        out.update(mappable=False, error=str(e), missing=e.unmapped or [])
        out.update({k: v for k, v in e.details().items() if k not in ("unmapped", "line")})
        return out
    report = rig.report()
    out.update(
        mappable=True,
        mapping=report["mapping"],
        method=report["method"],
        convention=report.get("convention", ""),
        confidence=report["confidence"],
        missing=[j for j in C.JOINTS[1:] if j not in rig.mapping],
        unmapped=rig.unmapped,
        reference_pose=rig.reference,
        up_axis=rig.up_axis,
        leg_length=round(rig.leg_length, 4),
    )
    return out


def cmd_canonical(args: argparse.Namespace) -> None:
    m = bvh.load(args.input)
    rig = retarget.make_rig(m.skeleton, m, _mapping_arg(args.mapping))
    canon = retarget.to_canonical(m, rig, fps=args.fps)
    bvh.save(canon, args.output)


def cmd_retarget(args: argparse.Namespace) -> None:
    m = bvh.load(args.input)
    onto = bvh.load(args.onto)
    out = retarget.retarget(m, onto, _mapping_arg(args.mapping), _mapping_arg(args.onto_mapping))
    bvh.save(out, args.output)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m motion", description=__doc__.split("\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("info", help="skeleton, timing and canonical mapping of a BVH, as JSON")
    p.add_argument("file")
    p.add_argument("--mapping", help="JSON object mapping joint names (either direction)")
    p = sub.add_parser("canonical", help="retarget a BVH onto the canonical skeleton")
    p.add_argument("input")
    p.add_argument("-o", "--output", required=True)
    p.add_argument("--fps", type=float, default=C.FPS, help="output frame rate (default 30)")
    p.add_argument("--mapping", help="JSON object mapping joint names (either direction)")
    p = sub.add_parser("retarget", help="perform a BVH's motion on another BVH's skeleton")
    p.add_argument("input")
    p.add_argument("--onto", required=True, help="BVH whose skeleton receives the motion")
    p.add_argument("-o", "--output", required=True)
    p.add_argument("--mapping", help="JSON joint-name mapping for the input")
    p.add_argument("--onto-mapping", help="JSON joint-name mapping for the target")
    args = parser.parse_args(argv)
    try:
        if args.command == "info":
            json.dump(cmd_info(args), sys.stdout, indent=2)
            sys.stdout.write("\n")
        elif args.command == "canonical":
            cmd_canonical(args)
        else:
            cmd_retarget(args)
    except MotionError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    except OSError as e:
        print(f"error: {e.strerror or e}: {e.filename}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""How short a style clip may be before its style is lost: the translator with one Bandai
take the encoders never saw as the style clip (``eval_foreign``'s
``translator-clip-unseen``), or as a video of it (``--source video``: the take's 2D
keypoints from one side, ``translator-video-unseen``), the take cut to its middle ``N``
frames, judged on a half of the foreign content (top-1 of the judge against the take's
style). The shortest length whose development-half top-1 keeps :data:`KEPT_SHARE` of the
whole takes' is where the service starts warning
(``service.engines.translator.SHORT_STYLE_SECONDS``).

    python -m training.short_style_clips OUT.json [--half dev|test] [--source clip|video]
        [--frames 1 2 4 ... 0]

``0`` frames: the whole take.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from training.reports import publish

FRAMES = (1, 2, 4, 8, 15, 30, 60, 0)
SOURCES = {"clip": "translator-clip-unseen", "video": "translator-video-unseen"}
KEPT_SHARE = 0.9  # of the whole takes' top-1: the style is still recognised


def main(argv: list[str] | None = None) -> int:
    from training import eval_foreign as EF

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("json", type=Path)
    p.add_argument("--half", choices=EF.HALVES, default="dev")
    p.add_argument("--source", choices=SOURCES, default="clip")
    p.add_argument("--frames", type=int, nargs="+", default=list(FRAMES))
    p.add_argument("--limit", type=int, default=None, help="only the first N items (a smoke run)")
    args = p.parse_args(argv)

    adapter = SOURCES[args.source]
    rows = []
    for frames in args.frames:
        report = EF.evaluate(
            (args.half,), (adapter,), limit=args.limit,
            pinned=EF.PINNED_JUDGE, log=lambda *_: None, style_clip_frames=frames,
        )[args.half]  # fmt: skip
        family = report["families"][adapter]
        rows.append({"frames": frames, "top1": family["top1"],
                     "intervals_90": family["intervals_90"].get("top1"),
                     "outputs": len(family["outputs"])})  # fmt: skip
        print(json.dumps(rows[-1]), flush=True)
    full = next((r["top1"] for r in rows if r["frames"] == 0), None)
    kept = [r["frames"] for r in rows if r["frames"] and full and r["top1"] >= KEPT_SHARE * full]
    result = {"half": args.half, "source": args.source, "kept_share": KEPT_SHARE, "rows": rows,
              "shortest_kept": min(kept) if kept else None, "chance": report["chance"]}  # fmt: skip
    publish(result, json.dumps(result, indent=1), args.json)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

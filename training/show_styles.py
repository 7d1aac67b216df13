"""A picture of what the styles do: one clip from outside Bandai sent through the shipped
engines to several styles, drawn as stick-figure film strips in one SVG.

    python -m training.show_styles [--clip cmu-31/02_01.bvh] [--styles elderly angry ...]
        [--out docs/styles.svg]

Rows: the clip unchanged, then each style through the translator and through the fast
networks; columns: poses at evenly spaced times over the same share of each clip (a
style's time warp makes its clip longer or shorter), each seen from the character's left
and from its front. Each figure is drawn relative to its own hips on the floor, so posture
and reach compare across a row. Left limbs blue, right limbs red. A first frame in T-pose
(cgspeed's CMU conversions start with one) is left out of the picture.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from motion import bvh, retarget
from motion import canonical as C
from motion import features as Fe
from motion import kinematics as K
from motion.skeleton import Motion

REPO = Path(__file__).resolve().parent.parent
STYLES = ("elderly", "angry", "proud", "childish", "feminine")
COLUMNS = 6
CELL = 120  # pixels: a figure's height, and the width of its two views
SCALE = CELL * 0.42 / Fe.LEG  # pixels per canonical unit: a leg is 42% of a cell
LABEL = 150  # pixels left of the first figure


def canonical_clip(path: Path) -> Motion:
    """A BVH onto the canonical skeleton at 30 fps, as the service reads it."""
    motion = bvh.load(path)
    return retarget.to_canonical(motion, retarget.make_rig(motion.skeleton, motion))


def views(motion: Motion, frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Joint positions ``(len(frames), 22, 2)`` seen from the character's left (x forward,
    y up) and from its front (x its left), relative to the hips on the floor, in canonical
    units."""
    gpos = K.global_positions(motion)
    face = Fe.facing(gpos)
    local = K.root_local(gpos, gpos[:, C.INDEX["Hips"]], face)[frames]
    side = np.stack([local[..., 2], local[..., 1]], axis=-1)
    front = np.stack([local[..., 0], local[..., 1]], axis=-1)
    return side, front


def is_t_pose(motion: Motion, frame: int = 0) -> bool:
    """Both arms straight out sideways at ``frame`` (hands level with the shoulders and
    farther apart than 1.2 leg lengths)."""
    gpos = K.global_positions(motion.slice(frame, frame + 1))[0]
    hands = gpos[C.INDEX["Hand_L"]], gpos[C.INDEX["Hand_R"]]
    shoulders = gpos[C.INDEX["UpperArm_L"]], gpos[C.INDEX["UpperArm_R"]]
    level = all(abs(h[1] - s[1]) < 0.15 * Fe.LEG for h, s in zip(hands, shoulders, strict=True))
    return level and np.linalg.norm(hands[0] - hands[1]) > 1.2 * Fe.LEG


def _limb_colour(joint: str) -> str:
    return "#2563eb" if joint.endswith("_L") else "#dc2626" if joint.endswith("_R") else "#111"


def figure(pose: np.ndarray, cx: float, floor: float) -> list[str]:
    """SVG lines of one stick figure ``(22, 2)`` standing at ``cx`` on ``floor``."""
    out = []
    pts = np.stack([cx + SCALE * pose[:, 0], floor - SCALE * pose[:, 1]], axis=-1)
    for j, p in enumerate(C.PARENTS):
        if p <= 0:
            continue
        (x1, y1), (x2, y2) = pts[p], pts[j]
        out.append(
            f'<line x1="{x1:.1f}" y1="{y1:.1f}" x2="{x2:.1f}" y2="{y2:.1f}" '
            f'stroke="{_limb_colour(C.JOINTS[j])}" stroke-width="2"/>'
        )
    return out


def strip(side: np.ndarray, front: np.ndarray, y0: float, label: str) -> list[str]:
    """SVG elements of one row: a label and, per pose, its side and front views."""
    out = [f'<text x="8" y="{y0 + CELL / 2:.0f}" font-size="13">{label}</text>']
    for k in range(len(side)):
        left, floor = LABEL + k * CELL, y0 + CELL - 6
        out += figure(side[k], left + CELL * 0.27, floor)
        out += figure(front[k], left + CELL * 0.7, floor)
        out.append(
            f'<line x1="{left + 4:.0f}" y1="{floor:.0f}" x2="{left + CELL - 4:.0f}" '
            f'y2="{floor:.0f}" stroke="#ccc"/>'
        )
    return out


def document(rows: list[tuple[str, Motion, np.ndarray]], title: str) -> str:
    """An SVG document of film strips, one per ``(label, canonical motion, frames)``, each
    showing the motion at those frames."""
    width = LABEL + CELL * max(len(frames) for _, _, frames in rows) + 10
    height = 40 + CELL * len(rows)
    body = [f'<text x="8" y="22" font-size="15" font-weight="bold">{title}</text>']
    for r, (label, motion, frames) in enumerate(rows):
        body += strip(*views(motion, frames), 30 + r * CELL, label)
    return (
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" '
        f'font-family="sans-serif"><rect width="100%" height="100%" fill="white"/>'
        + "".join(body)
        + "</svg>\n"
    )


def render(rows: list[tuple[str, Motion]], title: str) -> str:
    """An SVG document of film strips, one per ``(label, canonical motion)``, the content
    first."""
    first = 1 if is_t_pose(rows[0][1]) else 0  # the content's, for every row
    return document(
        [(label, motion, np.linspace(first, motion.num_frames - 1, COLUMNS).round().astype(int))
         for label, motion in rows],
        title,
    )  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    from training import judges as E
    from training.data import data_dir

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--clip", default="cmu-31/02_01.bvh", help="relative to the data folder")
    p.add_argument("--styles", nargs="+", default=list(STYLES))
    p.add_argument("--out", type=Path, default=REPO / "docs" / "styles.svg")
    args = p.parse_args(argv)
    content = canonical_clip(data_dir() / args.clip)
    rows = [("unchanged", content)]
    engines = {family: E.load_engine(family)[0] for family in ("translator", "fast")}
    for style in args.styles:
        for family, engine in engines.items():
            rows.append((f"{style} ({family})", E.transfer(family, engine, content, style)))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(
        render(rows, f"{args.clip}, restyled (each pose from the left and from the front)")
    )
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""The content of the foreign evaluation (``training.eval_foreign``): motion from outside Bandai,
as a user would send it, dealt into a development and a test half.

Content: the shared CMU 31-joint takes, Xia's clips and the CMU dance takes (43-joint and
3ds Max layouts; 05_20, in both CMU folders, once), canonical at 30 fps through
``training.data``'s loaders. cgspeed's synthetic T-pose first frame, which those loaders keep
for ``cmu-31``, is dropped (the body jumps 55-256 cm into it). Clips longer than 8 s are cut
into equal segments of at most 8 s; beyond four segments, four evenly spaced 8 s windows.
A few CMU-31 and Xia takes come again as other rigs send them: Mixamo names (``ZXY``
channels), and Unreal names with an extra root, Z up and in metres; each is written as BVH
text and read back through the service's own path (``service.clips.load_clip``).
They land within 0.001 cm of the original on the canonical skeleton, so they check the rig
path (``variants_agree``) and weigh their takes three times in the headline figures
(``top1_originals_only`` leaves them out; ``by_source`` shows each source apart).

Halves: by source take (a take's segments and variants stay together). Within each source
folder takes are ordered by a hash of their name and dealt alternately to dev and test,
the alternation running on across folders so that odd counts balance; variants are made of
the first two CMU-31 and two Xia takes of each half in that order. The report says its
half; nothing here reads the test half to choose anything.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path

from motion.skeleton import Motion
from service.metrics import StageTimer
from training.judges import segments

FOLDERS = ("cmu-31", "xia", "cmu-dance-43", "cmu-dance-3dsmax")
HALVES = ("dev", "test")
VARIANT_FOLDERS, VARIANT_TAKES = ("cmu-31", "xia"), 2  # takes per folder and half
T_POSE_FIRST = ("cmu-31",)  # folders whose files open with cgspeed's synthetic T-pose frame


@dataclass(frozen=True)
class Item:
    """One foreign clip sent to every style: ``take`` ("folder/stem") decides its half,
    ``source`` is its folder or ``folder@variant``."""

    name: str
    take: str
    source: str
    motion: Motion

    @property
    def original(self) -> str:
        """The name of the item a rig variant repeats (its own name otherwise)."""
        return self.name.split("@", 1)[0]


def foreign_takes(root: Path) -> dict[str, list[str]]:
    """The source takes of each folder of :data:`FOLDERS` under ``root`` ("folder/stem"),
    a take in two folders (CMU 05_20) only in the first."""
    seen, takes = set(), {}
    for folder in FOLDERS:
        stems = [p.stem for p in sorted((root / folder).glob("*.bvh")) if p.stem not in seen]
        seen.update(stems)
        takes[folder] = [f"{folder}/{s}" for s in stems]
    return takes


def _take_order(take: str) -> str:
    return hashlib.sha256(take.encode()).hexdigest()


def split_halves(takes: dict[str, list[str]]) -> dict[str, str]:
    """Each take's half: within a folder (folders in sorted order) takes ordered by a hash
    of their name are dealt to dev and test in turn, the turn carrying over between folders."""
    half_of, turn = {}, 0
    for folder in sorted(takes):
        for take in sorted(takes[folder], key=_take_order):
            half_of[take] = HALVES[turn % 2]
            turn += 1
    return half_of


def rig_variants(motion: Motion) -> dict[str, Motion]:
    """A CMU 31-joint ``motion`` as other tools export it: Mixamo names and ``ZXY``
    channels; Unreal names, an extra root, Z up and in metres."""
    from training import rig_variants as RV

    mixamo = RV.with_channels(RV.renamed(motion, RV.CMU_TO_MIXAMO), "ZXY")
    unreal = RV.renamed(motion, RV.CMU_TO_UNREAL)
    unreal = RV.with_extra_root(RV.scaled(RV.z_up(unreal), 0.01))
    return {"mixamo": mixamo, "unreal-z-up-m": unreal}


def through_service(motion: Motion) -> Motion:
    """``motion`` written as BVH text and read onto the canonical skeleton as a request is."""
    from motion import bvh
    from service.clips import Upload, load_clip
    from service.config import Settings

    upload = Upload("content", data=bvh.dumps(motion).encode())
    return load_clip(upload, Settings(), StageTimer("eval-foreign")).canonical


def load_items(halves: tuple[str, ...], root: Path | None = None) -> dict[str, list[Item]]:
    """The items of each of ``halves``: every take's segments, and its rig variants' where
    it is among the first :data:`VARIANT_TAKES` of its folder and half."""
    from motion import bvh
    from training.data import data_dir, load_bvh_folder, load_cmu_dance

    root = root or data_dir()
    takes = foreign_takes(root)
    half_of = split_halves(takes)
    clips = {f"{f}/{c.take}": c for f in ("cmu-31", "xia") for c in load_bvh_folder(f, root)}
    dance = {c.take: c for c in load_cmu_dance(root)}
    out: dict[str, list[Item]] = {h: [] for h in halves}
    for folder, names in takes.items():
        chosen = {h: sorted((t for t in names if half_of[t] == h), key=_take_order) for h in HALVES}
        for take in names:
            half = half_of[take]
            if half not in out:
                continue
            stem = take.split("/", 1)[1]
            clip = clips[take] if take in clips else dance[stem]
            skip = 1 if folder in T_POSE_FIRST else 0
            versions = {folder: clip.motion.slice(skip)}
            if folder in VARIANT_FOLDERS and take in chosen[half][:VARIANT_TAKES]:
                raw = bvh.load(root / folder / f"{stem}.bvh")
                for name, variant in rig_variants(raw).items():
                    versions[f"{folder}@{name}"] = through_service(variant).slice(skip)
            for source, motion in versions.items():
                parts = segments(motion)
                for k, part in enumerate(parts):
                    label = take + (f"#{k + 1}" if len(parts) > 1 else "")
                    label += source[len(folder) :]
                    out[half].append(Item(label, take, source, part))
    return out

"""The rig corpus (tests/rigs.py): every skeleton layout of the shared data (or the CMU
fixture without it) renamed, reordered, with helpers, Z-up, rescaled, in an A-pose, on a
root bone, and rigs of other tools' conventions, each mapped with no mapping given."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from motion import bvh
from motion import canonical as C
from motion import kinematics as K
from motion import retarget as RT
from motion.rig_mapping import REQUIRED
from tests import rigs
from tests.conftest import DATA_DIR

TOLERANCE = 0.02  # of body height: the corpus rig's canonical motion against its source's


@dataclass
class Mapped:
    name: str
    rig: RT.Rig
    corpus: rigs.CorpusRig
    source_rig: RT.Rig
    canonical: np.ndarray  # (F, 22, 3) the corpus rig's canonical positions
    source_canonical: np.ndarray


@pytest.fixture(scope="module")
def mapped() -> list[Mapped]:
    sources = {"fixture": rigs.load_fixture()}
    for key, parts in rigs.SHARED_LAYOUTS.items():
        path = DATA_DIR.joinpath(*parts)
        if path.exists():
            sources[key] = rigs.cut(bvh.load(path))
    out = []
    source_rigs: dict[int, tuple[RT.Rig, np.ndarray]] = {}
    for name, item in rigs.corpus(sources).items():
        if id(item.source) not in source_rigs:
            src_rig = RT.make_rig(item.source.skeleton, item.source)
            canon = K.global_positions(RT.to_canonical(item.source, src_rig, fps=None))
            source_rigs[id(item.source)] = (src_rig, canon)
        src_rig, src_canon = source_rigs[id(item.source)]
        rig = RT.make_rig(item.motion.skeleton, item.motion)
        canon = K.global_positions(RT.to_canonical(item.motion, rig, fps=None))
        out.append(Mapped(name, rig, item, src_rig, canon, src_canon))
    return out


def test_the_corpus_covers_what_the_issue_lists(mapped):
    names = {m.name for m in mapped}
    kinds = {n.split("/", 1)[1] for n in names}
    for kind in ("numbers", "words", "numbers_shuffled", "helpers", "z_up_numbers",
                 "scaled_0.01_numbers", "scaled_100_words", "a_pose_numbers",
                 "root_on_floor_numbers", "root_motion_words", "rotated_frames_numbers",
                 "everything", "Reallusion CC/iClone", "Maya _JNT"):  # fmt: skip
        assert kind in kinds, kind
    if DATA_DIR.exists():
        assert {n.split("/")[0] for n in names} >= set(rigs.SHARED_LAYOUTS)


def test_every_corpus_rig_maps_to_its_sources_canonical_motion(mapped):
    failures = []
    for m in mapped:
        err = np.linalg.norm(m.canonical - m.source_canonical, axis=-1).max() / C.body_height()
        if err > TOLERANCE or m.rig.method != m.corpus.method:
            failures.append((m.name, m.rig.method, round(float(err), 4)))
    assert not failures, failures


def test_corpus_rigs_map_the_joints_their_sources_map(mapped):
    """Where a corpus joint is a copy of a source joint, the limbs, head and hips map to the
    same joints the source's names do."""
    wrong = []
    for m in mapped:
        got, want = m.rig.mapping_by_name(), m.source_rig.mapping_by_name()
        for joint in REQUIRED:
            origin = m.corpus.origin.get(got[joint])
            if origin is not None and origin != want[joint]:
                wrong.append((m.name, joint, got[joint], origin, want[joint]))
    assert not wrong, wrong


def test_mapping_reports_how_and_how_sure(mapped):
    for m in mapped:
        report = m.rig.report()
        assert report["method"] in ("names", "structure")
        assert 0.0 < report["confidence"] <= 1.0, (m.name, report["confidence"])
        assert set(REQUIRED) <= set(report["mapping"])
        if m.rig.method == "names":
            assert report["convention"]


def test_corpus_rigs_come_back_on_their_own_joints_frames_and_rate(mapped):
    for m in mapped:
        motion = m.corpus.motion
        back = RT.from_canonical(RT.to_canonical(motion, m.rig, fps=None), m.rig, like=motion)
        assert back.skeleton.names == motion.skeleton.names, m.name
        assert back.num_frames == motion.num_frames and back.fps == motion.fps, m.name
        idx = [v for k, v in m.rig.mapping.items() if k != "joint_Root"]
        err = np.abs(K.global_positions(back)[:, idx] - K.global_positions(motion)[:, idx])
        assert err.max() < 1e-6 * m.rig.height, (m.name, err.max() / m.rig.height)


def test_without_the_clip_mapped_joints_still_land_where_the_source_puts_them(mapped):
    """``from_canonical`` without ``like`` (the command line's retarget, dance onto a
    skeleton): joints in between hold their usual pose, mapped joints land within 1%."""
    for m in mapped:
        motion = m.corpus.motion
        alone = RT.from_canonical(RT.to_canonical(motion, m.rig, fps=None), m.rig)
        idx = [v for k, v in m.rig.mapping.items() if k != "joint_Root"]
        err = np.linalg.norm(
            K.global_positions(alone)[:, idx] - K.global_positions(motion)[:, idx], axis=-1
        )
        assert np.percentile(err, 95) < 0.01 * m.rig.height, (m.name, err.max() / m.rig.height)


def test_rigs_with_animated_translations_come_back_within_a_percent(mapped):
    """Position channels on every joint that hold other values than the offsets, and move
    (Brekel's exports): canonical and back lands every mapped joint within 1% of body
    height, as rigs without them do."""
    animated = [m for m in mapped if m.name.endswith("/animated_translations_numbers")]
    assert animated
    for m in animated:
        motion = m.corpus.motion
        alone = RT.from_canonical(RT.to_canonical(motion, m.rig, fps=None), m.rig)
        idx = [v for k, v in m.rig.mapping.items() if k != "joint_Root"]
        err = np.linalg.norm(
            K.global_positions(alone)[:, idx] - K.global_positions(motion)[:, idx], axis=-1
        )
        assert err.max() < 0.01 * m.rig.height, (m.name, err.max() / m.rig.height)

"""Static int8 quantisation (QDQ, per-channel weights) of the fast and translator networks,
measured against the shipped fp32 graphs in one run. A study: nothing here is shipped.

    python -m model_export.quantize [--out DIR] [--json] [--calib-clips 20] [--eval-clips 6]

Reads the fp32 graphs listed in ``models/manifest.json`` (from a snapshot copied at the
start, so a re-export during the run cannot mix versions) and writes int8 graphs to
``--out`` (default ``runs/quantize/``, git-ignored), with a copy of the models folder whose
graphs are the int8 ones and whose manifest has their sha256 (``--out/models``, loadable
with ``MOTION_MODELS_DIR``), and ``report.json``.

Calibration (``onnxruntime.quantization.quantize_static``: QDQ, per-channel int8 weights,
int8 activations, MinMax ranges, after ``quant_pre_process``; only Conv, Gemm and MatMul
nodes, see ``OPS``) uses real inputs built as the engines build them
(``FastEngine.transform``, ``TranslatorEngine.transfer``: features, standardisation,
padding): the CMU fixture plus Bandai clips from takes that neither family held out. The
fast projection is calibrated on the fp32 style networks' outputs, the translator decoder
on the fp32 content encoder's latents with the style codes a transfer mixes (own code,
table codes, 2D codes), ``style2d`` on projections at random yaw and scale, as its
training made them.

Measured, per network: speed (frames/s, int8 vs fp32, one intra-op thread, the two timed
alternately, median), the output's relative RMS error vs fp32 on the held-out clips (and
for ``style2d`` the real video keypoints under ``data/keypoints``, which neither training
nor calibration saw), and the end result: each engine as the service runs it (IK, foot
clean-up, time warp), with that network's int8 graph substituted, against fp32: mean joint
position error in cm (``motion.kinematics.global_positions``) over held-out clip x style
pairs, beside the fp32 output's own distance from its input clip (time-warped by the same
factor) for scale. A family row substitutes all its graphs (that engine is loaded from the
int8 models copy, sha256 check included) and also gives the whole engine's frames/s.
Verdict per family: ship when that mean error is below ``SHIP_CM`` and the family's
networks are faster in int8 at both lengths.
"""

from __future__ import annotations

import argparse
import contextlib
import copy
import json
import logging
import shutil
import statistics
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from motion import bvh, retarget
from motion import canonical as C
from motion import fast_features as FF
from motion import features as Fe
from motion import kinematics as K
from motion.skeleton import Motion

REPO = Path(__file__).resolve().parent.parent
DEFAULT_OUT = REPO / "runs" / "quantize"
FIXTURE = REPO / "tests" / "data" / "cmu_02_01_walk_30fps.bvh"
LENGTHS = (240, 960)  # frames, for the speed columns
SHIP_CM = 0.5  # pipeline position error below which int8 may ship
FAMILIES = ("fast", "translator")
# Node types quantised: the ones with int8 kernels. onnxruntime's default list also takes
# the data-movement and comparison nodes, and the projection's max-unpooling (Equal/Where on
# pooled values) then breaks (output rel. RMS ~1.0).
OPS = ("Conv", "Gemm", "MatMul")
TOES = [C.INDEX["Toes_L"], C.INDEX["Toes_R"]]
FEET = [C.INDEX["Foot_L"], C.INDEX["Foot_R"]]


# --------------------------------------------------------------------------- helpers


class Feeds:
    """A ``CalibrationDataReader`` over a list of feeds."""

    def __init__(self, feeds: list[dict[str, np.ndarray]]) -> None:
        self.feeds = feeds
        self._next = 0

    def get_next(self) -> dict[str, np.ndarray] | None:
        if self._next >= len(self.feeds):
            return None
        self._next += 1
        return self.feeds[self._next - 1]

    def rewind(self) -> None:
        self._next = 0


def settings_for(models_dir: Path):
    from service.config import Settings

    return Settings(models_dir=models_dir, intra_op_threads=1, max_concurrent_inferences=1)


def load_engine(family: str, models_dir: Path):
    """The ``family`` engine of ``models_dir``, loaded as the service loads it (sha256
    check first), with one intra-op thread."""
    from service.engines.fast import FastEngine
    from service.engines.translator import TranslatorEngine
    from service.manifest import load_manifest, verify_files

    manifest = load_manifest(models_dir)
    entry = next(m for m in manifest.models if m.family == family)
    problems = verify_files(entry, models_dir)
    if problems:
        raise RuntimeError(f"{models_dir}: {'; '.join(problems)}")
    cls = {"fast": FastEngine, "translator": TranslatorEngine}[family]
    engine = cls(entry, models_dir, settings_for(models_dir))
    engine.load()
    return engine


def swapped(base, other, graphs: list[str]):
    """``base`` with the sessions of ``graphs`` taken from ``other`` (shallow copy)."""
    engine = copy.copy(base)
    engine.sessions = {**base.sessions, **{g: other.sessions[g] for g in graphs}}
    return engine


def rel_rms(pairs: list[tuple[np.ndarray, np.ndarray]]) -> float:
    """sqrt(sum (int8 - fp32)^2 / sum fp32^2) over all pairs ``(fp32, int8)``."""
    num = sum(float(np.sum((q.astype(np.float64) - f) ** 2)) for f, q in pairs)
    den = sum(float(np.sum(f.astype(np.float64) ** 2)) for f, _ in pairs)
    return float(np.sqrt(num / max(den, 1e-30)))


def position_error(a: Motion, b: Motion) -> float:
    """Mean joint position distance (cm) between two canonical motions of equal length."""
    pa, pb = K.global_positions(a), K.global_positions(b)
    if pa.shape != pb.shape:
        raise ValueError(f"motions differ in shape: {pa.shape} vs {pb.shape}")
    return float(np.linalg.norm(pa - pb, axis=-1).mean())


def timed_pair(fa, fb, repeats: int) -> tuple[float, float]:
    """Median seconds of ``fa()`` and ``fb()``, run alternately (so load from other
    processes hits both alike) after two warm-ups each."""
    for _ in range(2):
        fa()
        fb()
    ta, tb = [], []
    for _ in range(repeats):
        started = time.perf_counter()
        fa()
        ta.append(time.perf_counter() - started)
        started = time.perf_counter()
        fb()
        tb.append(time.perf_counter() - started)
    return statistics.median(ta), statistics.median(tb)


def tiled(x: np.ndarray, frames: int) -> np.ndarray:
    """``x (F, C)`` repeated along time to ``frames`` frames."""
    return np.resize(x, (frames, x.shape[1])) if len(x) < frames else x[:frames]


# --------------------------------------------------------------------------- clips


@dataclass
class Clips:
    calib: list[tuple[str, Motion]]
    held: dict[str, list[tuple[str, Motion]]]  # family -> held-out clips
    keypoints: list[tuple[str, Any]] = field(default_factory=list)  # real 2D keypoints
    note: str = ""


def fixture_clip() -> Motion:
    motion = bvh.load(FIXTURE)
    return retarget.to_canonical(motion, retarget.make_rig(motion.skeleton, motion))


def pick(clips: list, count: int, rng: np.random.Generator) -> list:
    """``count`` clips spread over styles: round-robin over styles, random within one."""
    by_style: dict[str, list] = {}
    for c in sorted(clips, key=lambda c: c.take):
        by_style.setdefault(c.style, []).append(c)
    for group in by_style.values():
        rng.shuffle(group)
    out: list = []
    while len(out) < count and any(by_style.values()):
        for style in sorted(by_style):
            if by_style[style] and len(out) < count:
                out.append(by_style[style].pop())
    return out


def load_clips(held_takes: dict[str, set[str]], args) -> Clips:
    from training.data import data_dir, load_bandai

    rng = np.random.default_rng(args.seed)
    cmu = ("cmu_02_01_walk", fixture_clip())
    crop = args.max_frames

    def cut(c) -> tuple[str, Motion]:
        m = c.motion
        return c.take, m.slice(0, min(m.num_frames, crop))

    keypoints = []
    root = data_dir() / "keypoints"
    if root.is_dir():
        from motion import keypoints as KP

        for folder in sorted(root.glob("openpose-treadmill-*")):
            keypoints.append((folder.name, KP.load(folder, fps=23.976)))

    if not (data_dir() / "bandai").is_dir():
        return Clips(
            calib=[cmu],
            held={f: [cmu] for f in FAMILIES},
            keypoints=keypoints,
            note="no Bandai data: calibrated and evaluated on the CMU fixture alone "
            "(the quality columns are NOT held out)",
        )
    clips = [c for c in load_bandai() if c.num_frames >= 30]
    unseen = set().union(*held_takes.values())
    calib = [
        cut(c) for c in pick([c for c in clips if c.take not in unseen], args.calib_clips, rng)
    ]
    held = {
        f: [cut(c) for c in pick([c for c in clips if c.take in takes], args.eval_clips, rng)]
        for f, takes in held_takes.items()
    }
    return Clips(calib=[cmu, *calib], held=held, keypoints=keypoints)


# --------------------------------------------------------------------------- fast family


def fast_input(engine, canon: Motion) -> np.ndarray:
    """The style networks' input ``(1, T, C)`` for ``canon``, as ``FastEngine.transform``
    builds it (standardised features, edge padding to the bucket)."""
    from service.engines import fast as F

    z = engine.stats.normalize(FF.encode(canon).features)
    total = F.padded_length(len(z))
    x = np.pad(z, ((F.MARGIN, total - len(z) - F.MARGIN), (0, 0)), mode="edge")
    return x[None].astype(np.float32)


def fast_feeds(engine, clips: list[tuple[str, Motion]]) -> dict[str, list[dict]]:
    """Feeds per graph: every style network gets every clip; the projection gets every
    style network's fp32 output of every clip."""
    xs = [fast_input(engine, m) for _, m in clips]
    graphs = sorted(info["graph"] for info in engine.style_info.values())
    feeds: dict[str, list[dict]] = {g: [{"motion": x} for x in xs] for g in graphs}
    feeds["projection"] = [
        {"motion": engine.run(g, {"motion": x})[0]} for x in xs for g in graphs
    ]  # fmt: skip
    return feeds


def fast_speed_inputs(engine, clips, frames: int) -> dict[str, dict]:
    z = np.concatenate([fast_input(engine, m)[0] for _, m in clips])
    x = tiled(z, frames)[None]
    first = sorted(info["graph"] for info in engine.style_info.values())[0]
    feeds = {info["graph"]: {"motion": x} for info in engine.style_info.values()}
    feeds["projection"] = {"motion": engine.run(first, {"motion": x})[0]}
    return feeds


def fast_pipeline(fp, q, held, styles: list[str], probe_styles: list[str], log) -> dict:
    """Position errors (cm) vs fp32 of ``stylize`` with one graph int8 (per graph) and all
    graphs int8 (``"family"``), and the fp32 output's distance from its input."""
    from service.metrics import StageTimer

    def run(engine, canon, style):
        return engine.stylize(canon, style, StageTimer(engine.name))

    errors: dict[str, list[float]] = {}
    scale: dict[str, list[float]] = {}
    clock = {"fp32": 0.0, "int8": 0.0, "frames": 0}
    only_proj = swapped(fp, q, ["projection"])
    for i, (take, canon) in enumerate(held):
        for style in styles:
            graph = fp.style_info[style]["graph"]
            t0 = time.perf_counter()
            ref = run(fp, canon, style)
            t1 = time.perf_counter()
            every = run(q, canon, style)
            clock["int8"] += time.perf_counter() - t1
            clock["fp32"] += t1 - t0
            clock["frames"] += canon.num_frames
            d = position_error(ref, canon)
            scale.setdefault(graph, []).append(d)
            scale.setdefault("family", []).append(d)
            errors.setdefault(graph, []).append(
                position_error(ref, run(swapped(fp, q, [graph]), canon, style))
            )
            errors.setdefault("family", []).append(position_error(ref, every))
            if style in probe_styles:
                scale.setdefault("projection", []).append(d)
                errors.setdefault("projection", []).append(
                    position_error(ref, run(only_proj, canon, style))
                )
        log(f"  fast pipeline {i + 1}/{len(held)} {take} ({canon.num_frames} frames)")
    result: dict = {
        k: (float(np.mean(v)), float(np.max(v)), float(np.mean(scale[k])), len(v))
        for k, v in errors.items()
    }
    result["engine"] = {k: clock["frames"] / clock[k] for k in ("fp32", "int8")}
    return result


# --------------------------------------------------------------------------- translator


def padded(engine, x: np.ndarray) -> np.ndarray:
    from service.engines.translator import pad_mirrored, padded_length

    out, _ = pad_mirrored(x, padded_length(len(x), engine.min_frames))
    return np.ascontiguousarray(out.T[None], dtype=np.float32)


def views_2d(gpos: np.ndarray, rng: np.random.Generator, count: int) -> list[np.ndarray]:
    """2D style features of ``count`` random views as the translator's training projects
    its clips: yaw +-90 degrees, scale 0.8-1.2, a quarter of the views with the toes on the
    ankles (keypoint layouts without toes)."""
    out = []
    for _ in range(count):
        g = gpos
        if rng.random() < 0.25:
            g = gpos.copy()
            g[:, TOES] = g[:, FEET]
        yaw = np.deg2rad(rng.uniform(-90, 90))
        out.append(Fe.style2d_from_positions(g, yaw, rng.uniform(0.8, 1.2)))
    return out


def translator_feeds(engine, clips, rng: np.random.Generator) -> dict[str, list[dict]]:
    """Feeds per graph, built as ``TranslatorEngine.transfer`` builds them; the decoder
    gets the fp32 latent with the codes a transfer mixes: own code, two table codes at
    strength 1, one at 0.5, and the code of a 2D view."""
    st = engine.stats
    feeds: dict[str, list[dict]] = {g: [] for g in ("content_encoder", "style3d", "style2d")}
    feeds["decoder"] = []
    n = len(engine.style_names)
    for i, (_, canon) in enumerate(clips):
        enc = Fe.encode(canon)
        xc = padded(engine, Fe.standardize(enc.content, st, "content"))
        xs = padded(engine, Fe.standardize(enc.style3d, st, "style3d"))
        x2 = [padded(engine, Fe.standardize(v, st, "style2d")) for v in views_2d(enc.gpos, rng, 2)]
        feeds["content_encoder"].append({"content": xc})
        feeds["style3d"].append({"motion3d": xs})
        feeds["style2d"] += [{"motion2d": x} for x in x2]
        latent = engine.run("content_encoder", {"content": xc})[0]
        own = engine.run("style3d", {"motion3d": xs})[0]
        code2d = engine.run("style2d", {"motion2d": x2[0]})[0]
        table = [engine.codes[(3 * i + k) % n][None] for k in range(3)]
        for code in (own, table[0], table[1], own + 0.5 * (table[2] - own), code2d):
            feeds["decoder"].append({"code": latent, "style_code": code.astype(np.float32)})
    return feeds


def translator_speed_inputs(engine, clips, frames: int) -> dict[str, dict]:
    st = engine.stats
    encs = [Fe.encode(m) for _, m in clips]
    rng = np.random.default_rng(0)

    def cat(kind: str, arrays: list[np.ndarray]) -> np.ndarray:
        x = tiled(Fe.standardize(np.concatenate(arrays), st, kind), frames)
        return np.ascontiguousarray(x.T[None], dtype=np.float32)

    xc = cat("content", [e.content for e in encs])
    latent = engine.run("content_encoder", {"content": xc})[0]
    return {
        "content_encoder": {"content": xc},
        "style3d": {"motion3d": cat("style3d", [e.style3d for e in encs])},
        "style2d": {"motion2d": cat("style2d", [views_2d(e.gpos, rng, 1)[0] for e in encs])},
        "decoder": {"code": latent, "style_code": engine.codes[:1].astype(np.float32)},
    }


TARGET_KINDS = ("by name", "example clip", "2D projection", "video keypoints")
TWO_D = ("2D projection", "video keypoints")


def translator_pipeline(fp, q, held, probe_styles: list[str], keypoints, log) -> dict:
    """Position errors (cm) vs fp32 of ``transfer`` (time warp and foot clean-up as the
    service runs them) with one graph int8 and all int8 (``"family"``). Targets per clip
    (``TARGET_KINDS``): ``probe_styles`` by name, the next held-out clip as a style example
    (3D), the next clip projected at a random yaw (2D) and each real video's keypoints (2D).
    ``style2d`` only changes the 2D targets, so its row counts those alone. Returns
    ``{variant: (error, scale, n)}`` and the same per target kind under ``"by_target"``."""
    variants = {
        g: swapped(fp, q, [g]) for g in ("content_encoder", "style3d", "style2d", "decoder")
    }
    variants["family"] = q

    def targets(engine, i: int) -> list[tuple[str, np.ndarray, float | None]]:
        other = held[(i + 1) % len(held)][1]
        out = []
        for name in probe_styles:
            c = engine.code_of_name(name)
            out.append(("by name", c.code, c.velocity))
        c = engine.code_of_motion(other)
        out.append(("example clip", c.code, c.velocity))
        yaw = float(np.deg2rad(np.random.default_rng(i).uniform(-90, 90)))
        feats = Fe.style2d_from_positions(K.global_positions(other), yaw)
        x = padded(engine, Fe.standardize(feats, engine.stats, "style2d"))
        out.append(("2D projection", engine.run("style2d", {"motion2d": x})[0][0], None))
        for _, kp in keypoints:
            out.append(("video keypoints", engine.code_of_keypoints(kp).code, None))
        return out

    errors: dict[tuple[str, str], list[float]] = {}
    scale: dict[tuple[str, str], list[float]] = {}
    clock = {"fp32": 0.0, "int8": 0.0, "frames": 0}
    for i, (take, canon) in enumerate(held):
        t0 = time.perf_counter()
        refs = [fp.transfer(canon, code, style_velocity=v) for _, code, v in targets(fp, i)]
        clock["fp32"] += time.perf_counter() - t0
        clock["frames"] += canon.num_frames * len(refs)
        dists = [
            position_error(t.motion, Fe.time_warp(canon, t.warp) if t.warp != 1.0 else canon)
            for t in refs
        ]
        for name, engine in variants.items():
            t0 = time.perf_counter()
            outs = [
                (kind, engine.transfer(canon, code, style_velocity=v))
                for kind, code, v in targets(engine, i)
            ]
            if name == "family":
                clock["int8"] += time.perf_counter() - t0
            for (kind, out), ref, d in zip(outs, refs, dists, strict=True):
                if name == "style2d" and kind not in TWO_D:
                    continue
                errors.setdefault((name, kind), []).append(position_error(ref.motion, out.motion))
                scale.setdefault((name, kind), []).append(d)
        log(f"  translator pipeline {i + 1}/{len(held)} {take} ({canon.num_frames} frames)")

    def summary(keys: list[tuple[str, str]]) -> tuple[float, float, float, int]:
        e = [x for k in keys for x in errors[k]]
        d = [x for k in keys for x in scale[k]]
        return float(np.mean(e)), float(np.max(e)), float(np.mean(d)), len(e)

    result: dict = {v: summary([k for k in errors if k[0] == v]) for v in variants}
    result["engine"] = {k: clock["frames"] / clock[k] for k in ("fp32", "int8")}
    result["by_target"] = {
        v: {kind: summary([(v, kind)]) for kind in TARGET_KINDS if (v, kind) in errors}
        for v in variants
    }
    return result


# --------------------------------------------------------------------------- quantisation


def quantize_graph(src: Path, dst: Path, feeds: list[dict], work: Path, ops: list[str]) -> str:
    """``src`` -> int8 QDQ ``dst`` calibrated on ``feeds``, quantising nodes of the types
    ``ops`` only; returns what pre-processing did."""
    from onnxruntime.quantization import CalibrationMethod, QuantFormat, QuantType, quantize_static
    from onnxruntime.quantization.shape_inference import quant_pre_process

    pre = work / f"{src.stem}.pre.onnx"
    source, note = src, "no pre-processing (it failed)"
    for symbolic in (True, False):  # the decoder defeats symbolic shape inference
        try:
            # in ``work``: a failed symbolic inference leaves its temporary model in the cwd
            with contextlib.chdir(work):
                quant_pre_process(str(src), str(pre), skip_symbolic_shape=not symbolic)
        except Exception:  # a study: fall back and say so
            continue
        source = pre
        note = "quant_pre_process" + ("" if symbolic else " (without symbolic shapes)")
        break
    logging.disable(logging.WARNING)  # its advice on pre-processing and biases, per node
    try:
        quantize_static(
            str(source),
            str(dst),
            Feeds(feeds),
            quant_format=QuantFormat.QDQ,
            per_channel=True,
            activation_type=QuantType.QInt8,
            weight_type=QuantType.QInt8,
            calibrate_method=CalibrationMethod.MinMax,
            op_types_to_quantize=ops,
        )
    finally:
        logging.disable(logging.NOTSET)
    return note


def int8_models(snapshot: Path, out: Path, replaced: dict[str, Path]) -> Path:
    """``out/models``: a copy of ``snapshot`` with the graphs in ``replaced`` (manifest
    path -> int8 file) substituted and their sha256 fixed in its manifest."""
    from service.manifest import MANIFEST_NAME, sha256_of

    target = out / "models"
    if target.exists():
        shutil.rmtree(target)
    shutil.copytree(snapshot, target)
    for rel, path in replaced.items():
        shutil.copyfile(path, target / rel)
    manifest = json.loads((target / MANIFEST_NAME).read_text())
    for model in manifest["models"]:
        for f in model["files"]:
            if f["path"] in replaced:
                f["sha256"] = sha256_of(target / f["path"])
    (target / MANIFEST_NAME).write_text(json.dumps(manifest, indent=1) + "\n")
    return target


# --------------------------------------------------------------------------- the study


def study(args, log) -> dict:
    import onnxruntime as ort

    from service.engines.base import create_session
    from service.manifest import load_manifest
    from training.eval_style import held_out_takes

    started = time.time()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix="quantize-"))
    try:
        snapshot = tmp / "models"
        shutil.copytree(args.models_dir, snapshot)
        manifest = load_manifest(snapshot)
        entries = {f: next(m for m in manifest.models if m.family == f) for f in FAMILIES}
        held_takes = {f: held_out_takes(f, entries[f], snapshot) for f in FAMILIES}
        clips = load_clips(held_takes, args)
        log(
            f"clips: {len(clips.calib)} calibration, "
            + ", ".join(f"{len(v)} held-out {f}" for f, v in clips.held.items())
            + f", {len(clips.keypoints)} real keypoint sequences"
        )
        fp = {f: load_engine(f, snapshot) for f in FAMILIES}
        rng = np.random.default_rng(args.seed)
        feeds = {
            "fast": fast_feeds(fp["fast"], clips.calib),
            "translator": translator_feeds(fp["translator"], clips.calib, rng),
        }
        eval_feeds = {
            "fast": fast_feeds(fp["fast"], clips.held["fast"]),
            "translator": translator_feeds(fp["translator"], clips.held["translator"], rng),
        }
        tr = fp["translator"]
        eval_feeds["translator"]["style2d"] += [
            {
                "motion2d": padded(
                    tr, Fe.standardize(Fe.style2d_from_keypoints(kp), tr.stats, "style2d")
                )
            }
            for _, kp in clips.keypoints
        ]  # real video keypoints: never seen in training or calibration

        # quantise
        replaced: dict[str, Path] = {}
        notes: dict[str, str] = {}
        for family in FAMILIES:
            entry = entries[family]
            (out / family).mkdir(exist_ok=True)
            for graph, spec in entry.graphs.items():
                if graph not in feeds[family]:
                    continue
                dst = out / spec.file
                t0 = time.time()
                notes[graph] = quantize_graph(
                    snapshot / spec.file, dst, feeds[family][graph], tmp, args.ops
                )
                replaced[spec.file] = dst
                log(f"  quantised {spec.file} ({len(feeds[family][graph])} feeds, "
                    f"{time.time() - t0:.1f} s, {notes[graph]})")  # fmt: skip
        q_dir = int8_models(snapshot, out, replaced)
        q = {f: load_engine(f, q_dir) for f in FAMILIES}
        log(f"int8 models folder: {q_dir} (manifest sha256 updated, engines load)")

        rows: dict[str, dict] = {}
        for family in FAMILIES:
            entry = entries[family]
            for graph, spec in entry.graphs.items():
                if graph not in feeds[family]:
                    continue
                pairs = [
                    (fp[family].run(graph, f)[0], q[family].run(graph, f)[0])
                    for f in eval_feeds[family][graph]
                ]
                rows[graph] = {
                    "family": family,
                    "file": spec.file,
                    "bytes_fp32": (snapshot / spec.file).stat().st_size,
                    "bytes_int8": replaced[spec.file].stat().st_size,
                    "rel_rms": rel_rms(pairs),
                    "speed": {},
                    "preprocess": notes[graph],
                }

        # speed: one intra-op thread, fp32 and int8 sessions timed alternately
        sessions = {
            g: (
                create_session(snapshot / r["file"], 1),
                create_session(replaced[r["file"]], 1),
            )
            for g, r in rows.items()
        }
        for frames in LENGTHS:
            inputs = {
                **fast_speed_inputs(fp["fast"], clips.calib, frames),
                **translator_speed_inputs(fp["translator"], clips.calib, frames),
            }
            for g, (s32, s8) in sessions.items():
                x = inputs[g]
                t32, t8 = timed_pair(
                    lambda s32=s32, x=x: s32.run(None, x),
                    lambda s8=s8, x=x: s8.run(None, x),
                    args.repeats,
                )
                rows[g]["speed"][frames] = {"fp32": frames / t32, "int8": frames / t8}
            # family chains: the networks one request runs
            style_graph = fp["fast"].style_info[sorted(fp["fast"].style_info)[0]]["graph"]
            xf = inputs[style_graph]

            def fast_chain(i: int, xf=xf, g=style_graph):
                y = sessions[g][i].run(None, xf)[0]
                return sessions["projection"][i].run(None, {"motion": y})

            xt = inputs["content_encoder"]
            xs = inputs["style3d"]
            code = inputs["decoder"]["style_code"]

            def translator_chain(i: int, xt=xt, xs=xs, code=code):
                latent = sessions["content_encoder"][i].run(None, xt)[0]
                sessions["style3d"][i].run(None, xs)
                return sessions["decoder"][i].run(None, {"code": latent, "style_code": code})

            for family, chain in (("fast", fast_chain), ("translator", translator_chain)):
                t32, t8 = timed_pair(lambda c=chain: c(0), lambda c=chain: c(1), args.repeats)
                key = f"{family} (all int8)"
                rows.setdefault(key, {"family": family, "speed": {}})
                rows[key]["speed"][frames] = {"fp32": frames / t32, "int8": frames / t8}
            log(f"  timed {frames} frames ({time.time() - started:.0f} s)")

        # the end result
        styles = sorted(fp["fast"].style_info)
        probe = styles[:: max(1, len(styles) // args.eval_styles)][: args.eval_styles]
        fast_err = fast_pipeline(fp["fast"], q["fast"], clips.held["fast"], styles, probe, log)
        t_styles = list(fp["translator"].style_names)
        t_probe = t_styles[:: max(1, len(t_styles) // args.eval_styles)][: args.eval_styles]
        tr_err = translator_pipeline(
            fp["translator"], q["translator"], clips.held["translator"], t_probe,
            clips.keypoints, log,
        )  # fmt: skip
        by_target = tr_err.pop("by_target")
        for family, errs in (("fast", fast_err), ("translator", tr_err)):
            rows[f"{family} (all int8)"]["engine_fps"] = errs.pop("engine")
            for k, (err, worst, scale, n) in errs.items():
                key = f"{family} (all int8)" if k == "family" else k
                rows[key].update(
                    {"position_cm": err, "worst_pair_cm": worst, "fp32_vs_input_cm": scale,
                     "pairs": n}
                )  # fmt: skip

        ordered = {}
        for family in FAMILIES:
            for g in entries[family].graphs:
                if g in rows:
                    ordered[g] = rows[g]
            ordered[f"{family} (all int8)"] = rows[f"{family} (all int8)"]
        rows = ordered

        verdicts = {}
        for family in FAMILIES:
            r = rows[f"{family} (all int8)"]
            ratios = [s["int8"] / s["fp32"] for s in r["speed"].values()]
            faster = min(ratios) > 1.0
            ok = r["position_cm"] < SHIP_CM
            good = sorted(
                g for g, x in rows.items()
                if x["family"] == family and "(all" not in g and x["position_cm"] < SHIP_CM
                and min(s["int8"] / s["fp32"] for s in x["speed"].values()) > 1.0
            )  # fmt: skip
            verdicts[family] = {
                "ship": ok and faster,
                "position_cm": r["position_cm"],
                "worst_pair_cm": r["worst_pair_cm"],
                "speed_ratio": {f: s["int8"] / s["fp32"] for f, s in r["speed"].items()},
                "networks_passing_alone": good,
                "engine_fps": r["engine_fps"],
            }
        return {
            "onnxruntime": ort.__version__,
            "threads": 1,
            "settings": {
                "format": "QDQ",
                "per_channel": True,
                "weights": "int8",
                "activations": "int8",
                "calibration": "MinMax",
                "quantised_ops": args.ops,
                "pre_process": sorted(set(notes.values())),
            },
            "calibration_clips": [n for n, _ in clips.calib],
            "held_out_clips": {f: [n for n, _ in v] for f, v in clips.held.items()},
            "keypoints": [n for n, _ in clips.keypoints],
            "probe_styles": {"fast": probe, "translator": t_probe},
            "note": clips.note,
            "rows": rows,
            "translator_by_target": {
                ("translator (all int8)" if v == "family" else v): {
                    kind: {"position_cm": e, "fp32_vs_input_cm": d, "pairs": n}
                    for kind, (e, _, d, n) in kinds.items()
                }
                for v, kinds in by_target.items()
            },
            "verdicts": verdicts,
            "ship_cm": SHIP_CM,
            "int8_models_dir": str(q_dir),
            "seconds": round(time.time() - started, 1),
        }
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def markdown(report: dict) -> str:
    lines = [
        f"onnxruntime {report['onnxruntime']}, {report['threads']} intra-op thread; "
        f"QDQ int8 ({', '.join(report['settings']['quantised_ops'])} nodes), per-channel "
        f"weights, MinMax calibration on {len(report['calibration_clips'])} clips; frames/s: "
        "median of fp32/int8 runs interleaved (compare ratios: absolute numbers move with "
        "the machine's load); position errors: mean over held-out clip x style pairs (n)",
        "",
        "| network | fp32 frames/s @240 | int8 frames/s @240 | speed ratio @240 "
        "| fp32 frames/s @960 | int8 frames/s @960 | speed ratio @960 "
        "| output rel. RMS | pipeline position error cm (worst pair) | fp32 vs input cm (scale) "
        "| n |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for name, r in report["rows"].items():
        cells = []
        for frames in LENGTHS:
            s = r["speed"][frames]
            cells += [f"{s['fp32']:,.0f}", f"{s['int8']:,.0f}", f"{s['int8'] / s['fp32']:.2f}x"]
        rms = f"{r['rel_rms']:.4f}" if "rel_rms" in r else "-"
        lines.append(
            f"| {name} | {' | '.join(cells)} | {rms} "
            f"| {r['position_cm']:.3f} ({r['worst_pair_cm']:.2f}) "
            f"| {r['fp32_vs_input_cm']:.2f} | {r['pairs']} |"
        )
    lines += [
        "",
        "translator pipeline position error cm by style source (fp32 vs input cm, n):",
        "",
        "| int8 graphs | " + " | ".join(TARGET_KINDS) + " |",
        "|---|" + "---:|" * len(TARGET_KINDS),
    ]
    for variant, kinds in report["translator_by_target"].items():
        cells = [
            f"{k['position_cm']:.3f} ({k['fp32_vs_input_cm']:.1f}, {k['pairs']})" if k else "-"
            for k in (kinds.get(kind) for kind in TARGET_KINDS)
        ]
        lines.append(f"| {variant} | {' | '.join(cells)} |")
    lines.append("")
    for family, v in report["verdicts"].items():
        ratios = ", ".join(f"{x:.2f}x @{f}" for f, x in v["speed_ratio"].items())
        word = "SHIP int8" if v["ship"] else "do NOT ship int8"
        alone = ", ".join(v["networks_passing_alone"]) or "none"
        eng = v["engine_fps"]
        lines.append(
            f"- **{family}**: {word}: all-int8 position error {v['position_cm']:.3f} cm "
            f"(worst clip x style {v['worst_pair_cm']:.2f} cm; threshold {report['ship_cm']} cm), "
            f"network speed {ratios}, whole engine "
            f"{eng['fp32']:,.0f} -> {eng['int8']:,.0f} frames/s "
            f"({eng['int8'] / eng['fp32']:.2f}x); networks passing alone: {alone}"
        )
    if report["note"]:
        lines.append(f"\nNote: {report['note']}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> dict:
    from service.config import REPO_MODELS_DIR

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path, default=DEFAULT_OUT, help="int8 graphs and report here")
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    p.add_argument("--models-dir", type=Path, default=REPO_MODELS_DIR, help="fp32 models")
    p.add_argument("--calib-clips", type=int, default=20, help="Bandai calibration clips")
    p.add_argument("--eval-clips", type=int, default=6, help="held-out clips per family")
    p.add_argument("--eval-styles", type=int, default=4, help="styles probed by name")
    p.add_argument("--max-frames", type=int, default=450, help="clips are cut to this")
    p.add_argument("--repeats", type=int, default=15, help="timed runs per graph and length")
    p.add_argument(
        "--ops",
        type=lambda text: [op for op in text.split(",") if op],
        default=list(OPS),
        help=f"node types to quantise (default {','.join(OPS)}: the others stay float)",
    )
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args(argv)

    def log(*parts) -> None:
        print(*parts, file=sys.stderr if args.json else sys.stdout, flush=True)

    report = study(args, log)
    (Path(args.out) / "report.json").write_text(json.dumps(report, indent=1) + "\n")
    if args.json:
        print(json.dumps(report, indent=1))
    else:
        print()
        print(markdown(report))
    return report


if __name__ == "__main__":
    main()

"""The dance family (jacob2019, made to work): music in, a dance for the whole song out.

A request's song goes: decoded samples -> per-frame features at 30 fps for its whole decoded
length (``motion.audio_features``; beats tracked on the song itself) -> standardised -> ``audio``
graph (code per frame, genre probabilities) -> the ``step`` graph frame by frame, feeding
back its own pose (LSTM states explicit), from a seeded start pose with seeded noise on the
fed-back pose -> raw features -> Butterworth low-pass -> standstills filled -> canonical
motion (root integrated) -> contacts predicted and the feet planted there
(``motion.dance_feet``) -> time warp putting its
kinematic beats on the song's pulses (``motion.beat_warp``) -> the requested frame rate ->
onto the request's skeleton, if any. The family's core, :meth:`DanceEngine.predict`, runs
from the decoded samples to the canonical dance at 30 fps; the service (through ``prepare``
and ``finish``) and the evaluations call the same one.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field, replace
from typing import Any, ClassVar

import numpy as np

from motion import audio_decode, audio_features, dance_feet
from motion import beat_warp as BW
from motion import canonical as C
from motion import dance_features as DF
from motion import kinematics as K
from motion.anatomy import hinged, knees_forward
from motion.root_motion import in_place
from motion.skeleton import Motion
from service import limits
from service.clips import Clip, Result, RootMotion, answer_format, load_clip, write_result
from service.engines import register_engine
from service.engines.base import Engine
from service.metrics import StageTimer
from service.requests import DanceRequest

logger = logging.getLogger(__name__)

BUCKET = 256  # audio frames: the audio graph runs at multiples of this
NOISE = 0.05  # std of the seeded noise on the fed-back pose (standardised units)
STATES = ("h1", "c1", "h2", "c2")  # the step graph's LSTM states, fed back as ``{name}_out``


@dataclass
class DanceJob:
    """The core's input: decoded music ``samples (N,)`` at ``sr``, the genre (predicted
    when None), the seed and the finishing steps; for a request, the skeleton's clip, the
    answer's rate, frame count and format, for ``finish``."""

    samples: np.ndarray
    sr: int
    genre: str | None = None
    seed: int = 0
    beat_warp: bool = True
    foot_cleanup: bool = True
    features: audio_features.AudioFeatures | None = None
    clip: Clip | None = None
    fps: float = DF.FPS
    frames: int = 0  # of the answer at ``fps``
    format: str | None = None  # of the answer, as asked
    root_motion: RootMotion = "keep"  # of the answer: in_place takes the travel out


@dataclass
class Music:
    """The music's standardised features ``x (F, A)``, its features (beats and tempo at the
    general prior the networks read; the genre's level is tracked once the genre is known),
    and the seeded start pose and noise seed of the rollout."""

    x: np.ndarray
    features: audio_features.AudioFeatures
    playing: np.ndarray  # (F,) bool: frames where the music plays
    start: np.ndarray
    noise_seed: int


@dataclass
class DanceNetworks:
    """What the networks give: the genre (given or predicted) and its
    probabilities, and the rolled-out standardised poses ``(F, M)``."""

    genre: str
    genre_probs: dict[str, float]
    poses: np.ndarray


@dataclass
class DanceResult:
    """A generated dance on the canonical skeleton at 30 fps, with what the engine decided."""

    motion: Motion
    genre: str
    genre_probs: dict[str, float]
    genre_given: bool
    tempo: float
    beats: np.ndarray
    bas: float
    bas_chance: float
    warnings: list[str] = field(default_factory=list)


def song_features(samples: np.ndarray, sr: int) -> audio_features.AudioFeatures:
    """The features a dance of ``samples`` at ``sr`` is made from: at 30 fps, every instant
    of the song covered (two frames at least)."""
    frames = max(2, math.ceil(len(samples) / sr * DF.FPS - 1e-9))
    return audio_features.frame_features(samples, sr, DF.FPS, frames)


class DanceEngine(Engine):
    family: ClassVar[str] = "dance"
    warm_dims: ClassVar[dict[str, int]] = {"batch": 1, "time": BUCKET}
    # the rollout runs the step graph once per frame: sleeping threads cost it 10-20%
    spinning_graphs: ClassVar[frozenset[str]] = frozenset({"step"})

    def load_assets(self) -> None:
        arrays = self.load_npz(self.entry.extra["stats"])
        self.stats = DF.DanceStats.from_arrays(arrays)
        self.start_poses = np.asarray(arrays["start_poses"], np.float32)
        self.hidden = int(self.entry.extra["hidden"])
        self.step_weights = self._choose_step_graph()
        if list(self.entry.extra.get("genres", DF.GENRES)) != list(DF.GENRES):
            raise ValueError("the bundle's genres differ from motion.dance_features.GENRES")

    def _choose_step_graph(self) -> str:
        """The 8-bit step graph where it reproduces the network's recorded steps on this CPU
        (its kernels decide the rounding: one family of them once differed tenfold), else
        its float twin. Bundles without the twin keep their one step graph."""
        check = self.entry.extra.get("step_check")
        if check is None or "step_float" not in self.sessions:
            return "as listed"
        arrays = self.load_npz(check)
        names = [o.name for o in self.sessions["step"].get_outputs()]
        worst = 0.0
        for t in range(len(arrays["in_code"])):
            feeds = {i.name: arrays[f"in_{i.name}"][t] for i in self.sessions["step"].get_inputs()}
            got = self.sessions["step"].run(names, feeds)
            worst = max(worst, *(float(np.abs(g - arrays[f"out_{n}"][t]).max())
                                 for g, n in zip(got, names, strict=True)))  # fmt: skip
        if worst <= float(arrays["atol"]):
            self.sessions.pop("step_float")
            return "8-bit"
        self.warnings.append(f"the 8-bit step graph differs from its network by {worst:.3f} on "
                             f"this CPU (at most {float(arrays['atol']):.3f}): serving the float "
                             "one, about 10 % slower")  # fmt: skip
        logger.warning("%s: %s", self.name, self.warnings[-1])
        self.sessions["step"] = self.sessions.pop("step_float")
        return "float"

    def styles(self) -> list[dict[str, Any]]:
        return [{"name": g, "music": g in DF.MUSIC_GENRES} for g in DF.GENRES]

    # --- network --------------------------------------------------------------------------

    def encode(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Standardised audio ``(F, A)`` -> code ``(F, code)`` and genre probabilities ``(4,)``
        (over the unpadded frames: the graph's own mean includes padding, so the head is
        applied to codes of an edge-padded bucket; the difference is a few frames)."""
        frames = len(x)
        total = max(BUCKET, -(-frames // BUCKET) * BUCKET)
        padded = np.pad(x, ((0, total - frames), (0, 0)), mode="edge")[None]
        code, probs = self.run("audio", {"audio": padded.astype(np.float32)})
        return code[0, :frames], probs[0]

    def rollout(
        self, code: np.ndarray, genre: np.ndarray, start: np.ndarray, seed: int
    ) -> np.ndarray:
        """Standardised poses ``(F, M)``: frame 0 is ``start``, each next one from the step
        graph fed its own (seeded-noisy) output."""
        rng = np.random.default_rng(seed)
        frames = len(code)
        out = np.empty((frames, DF.MOTION_CHANNELS), np.float32)
        out[0] = start
        noise = (NOISE * rng.standard_normal((frames, DF.MOTION_CHANNELS))).astype(np.float32)
        noise[:, DF.CONTACTS] = 0.0
        # A 3-minute song runs the graph 5,400 times: inputs and outputs are bound once to
        # buffers rewritten in place, where session.run's per-call conversions and
        # allocations took about 15 % of the loop.
        state = {n: np.zeros((1, self.hidden), np.float32) for n in STATES}
        inputs = {"code": np.zeros((1, code.shape[1]), np.float32),
                  "genre": genre[None].astype(np.float32),
                  "prev": np.empty((1, DF.MOTION_CHANNELS), np.float32), **state}  # fmt: skip
        outputs = {"pose": start[None].astype(np.float32),
                   **{f"{n}_out": np.empty((1, self.hidden), np.float32) for n in STATES}}  # fmt: skip
        session = self.sessions["step"]
        binding = session.io_binding()
        for name, array in inputs.items():
            binding.bind_input(name, "cpu", 0, np.float32, array.shape, array.ctypes.data)
        for name, array in outputs.items():
            binding.bind_output(name, "cpu", 0, np.float32, array.shape, array.ctypes.data)
        pose = outputs["pose"]
        for t in range(1, frames):
            np.add(pose, noise[t], out=inputs["prev"])
            inputs["code"][0] = code[t]
            session.run_with_iobinding(binding)
            out[t] = pose[0]
            for n in STATES:
                state[n][...] = outputs[f"{n}_out"]
        return out

    # --- the three steps ---------------------------------------------------------------------

    def prepare(self, request: DanceRequest, timer: StageTimer) -> DanceJob:
        """Decode the music (413 over ``max_audio_seconds``, 422 when silent), check the
        answer's frame count, read the skeleton (BVH, or a glTF rig: its rest pose when it
        has no animation)."""
        if request.skeleton is None:
            answer_format(None, request.format)  # format=glb without a glTF rig: 400 now
        with timer.stage("decode_audio"):
            samples, sr = limits.decode_audio(request.audio.read(), self.settings)
            audio_decode.check_not_silent(samples)
        seconds = len(samples) / sr
        frames = max(1, math.ceil(seconds * request.fps - 1e-9))
        limits.check_frames(frames, self.settings, what="result")
        limits.check_frames(math.ceil(seconds * DF.FPS), self.settings, what="result")
        clip = None
        if request.skeleton is not None:
            clip = load_clip(
                request.skeleton,
                self.settings,
                timer,
                mapping=request.mapping,
                answer=request.format,
                rest_if_unanimated=True,
            )
        return DanceJob(samples, sr, request.genre, request.seed, clip=clip,
                        fps=float(request.fps), frames=frames, format=request.format,
                        root_motion=request.root_motion)  # fmt: skip

    def _music(self, job: DanceJob, timer: StageTimer) -> Music:
        with timer.stage("features"):
            feats = job.features
            if feats is None:
                feats = song_features(job.samples, job.sr)
            x = self.stats.normalize_audio(feats.matrix())
        rng = np.random.default_rng(job.seed)
        start = self.stats.normalize_motion(self.start_poses[rng.integers(len(self.start_poses))])
        noise_seed = int(rng.integers(2**31))
        return Music(x, feats, feats.playing, start, noise_seed)

    def predict(self, job: DanceJob, timer: StageTimer) -> DanceResult:
        """The family's core: the music's features, the audio graph (codes, genre
        probabilities), the genre (the given one, else the most probable), the step graph
        frame by frame, then the motion (:meth:`_dance`)."""
        music = self._music(job, timer)
        with timer.stage("network"):
            code, probs = self.encode(music.x)
        probs_by_genre = {
            g: round(float(p), 4) for g, p in zip(DF.MUSIC_GENRES, probs, strict=True)
        }
        genre = job.genre or DF.MUSIC_GENRES[int(np.argmax(probs))]
        with timer.stage("step"):
            poses = self.rollout(code, DF.genre_vector(genre), music.start, music.noise_seed)
        return self._dance(job, music, DanceNetworks(genre, probs_by_genre, poses), timer)

    def finish(self, job: DanceJob, result: DanceResult, timer: StageTimer) -> Result:
        with timer.stage("resample"):
            canon = K.resample_count(result.motion, job.fps, job.frames)
        clip = job.clip
        if clip is not None:  # taken out on the rig, where its root motion lives
            clip = replace(clip, root_motion=job.root_motion)
        elif job.root_motion == "in_place":
            canon = in_place(canon, C.INDEX["Hips"])
        answer = write_result(  # on the rig's own skeleton, if any, at the requested rate
            clip,
            canon,
            self.settings,
            timer,
            warnings=result.warnings,
            suffix=f"dance_{job.genre or 'auto'}",
            fps=job.fps,
            like_clip=False,
            fmt=job.format,
        )
        answer.dance = {
            "genre": result.genre,
            "genre_given": result.genre_given,
            "tempo_bpm": round(float(result.tempo), 1),
            "beat_alignment": round(float(result.bas), 3),
            "beat_alignment_chance": round(float(result.bas_chance), 3),
        }
        return answer

    def _dance(
        self, job: DanceJob, music: Music, out: DanceNetworks, timer: StageTimer
    ) -> DanceResult:
        """The rolled-out poses -> a canonical dance at 30 fps: low-passed, standstills
        filled, root integrated, knees and elbows bent only the way they bend, feet cleaned
        up, knees the clean-up swung behind the leg swivelled forward, its kinematic beats
        warped onto the music's pulses; and its beat alignment."""
        warnings: list[str] = []
        if job.genre is None:
            p = out.genre_probs[out.genre]
            warnings.append(f"genre not given: predicted {out.genre} (p = {p:.2f})")
        with timer.stage("beats"):  # the level a dancer of the genre steps
            tempo, beats, pulses = music.features.for_genre(out.genre)
        if tempo <= 0:
            warnings.append("no beat found in the music: the dance is not beat-aligned")
        with timer.stage("motion"):
            raw = DF.smooth_features(self.stats.denormalize_motion(out.poses))
            x, motion = DF.keep_moving(raw, music.playing)
        with timer.stage("anatomy"):  # the clean-up's IK bends each knee the way it finds it
            motion = hinged(motion)
        if job.foot_cleanup:  # before the warp, which keeps still feet still and sets the timing
            with timer.stage("foot_cleanup"):
                motion = dance_feet.clean_feet(motion, x[:, DF.CONTACTS] > 0.5)
            with timer.stage("knees"):  # its leg IK can swing a knee behind the leg
                motion = knees_forward(motion)
        if job.beat_warp and len(beats) >= 2:
            with timer.stage("beat_warp"):
                motion = BW.warp_to_beats(motion, pulses).motion
        bas, chance = BW.alignment(motion, beats)
        return DanceResult(motion, out.genre, out.genre_probs, job.genre is not None,
                           tempo, beats, bas, chance, warnings)  # fmt: skip


register_engine("dance", DanceEngine)

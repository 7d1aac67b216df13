"""The translator family: content clip + a style code from an example clip, a video's 2D
keypoints, a style name or a mix of names; numpy and onnxruntime only.

Graphs (``model_export/translator.py``): ``style3d`` and ``style2d`` (a clip's or a video's
style code) and ``restyler`` (content and code -> rotations), all ``(batch, channels,
time)``. The restyler reads how the content moves about its own mean posture
(``motion.features.restyler_input``) in overlapping windows of its training length
(``extra.window``), blended with Hann weights, so every frame sees the context it learned
with. A style clip or video goes through its style encoder whole, padded in time to a
length bucket (a multiple of ``BUCKET`` frames, never shorter than the networks'
receptive field) by mirroring it at both ends, so onnxruntime sees few shapes; the codes
of the named styles were computed the same way (their mean over the style's Bandai
takes). A name may be another name of a style (``extra.aliases``: old is elderly).

The family's core, :meth:`TranslatorEngine.predict`, takes and returns canonical motion;
the service (through ``prepare`` and ``finish``) and the evaluations call the same one. A
transfer: restyle with the target code, finish as :mod:`service.engines.restyling` does;
then the time warp, to the power ``strength`` and clamped: for a style clip the ratio of
velocity factors (style over content, aberman2020); for a named style or mix the style's
speed against the other styles on the same action (``model_export.translator``), over the
speed of the named style the content itself is in, if any
(:meth:`TranslatorEngine.own_speed`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from motion import features as Fe
from motion import kernels
from motion.anatomy import Warp
from motion.keypoints import Keypoints2D
from motion.skeleton import Motion
from motion.styles import exaggerated
from service import limits
from service.clips import Clip, Result, load_clip, name_the_clip, write_result
from service.engines import register_engine
from service.engines.base import Engine
from service.engines.restyling import (
    BUCKET,
    MAX_WARP,
    MIN_WARP,
    anatomical,
    pad_mirrored,
    padded_length,
    restyled_motion,
    speed_limited,
    wrapped,
)
from service.errors import NotFound
from service.metrics import StageTimer
from service.registered_styles import RegisteredStyle
from service.requests import (
    RegisterStyleRequest,
    Registration,
    StyleCode,
    StyleCodeRequest,
    StyleCodeResult,
    StyleSource,
    TransferRequest,
)

TranslatorRequest = TransferRequest | StyleCodeRequest | RegisterStyleRequest
# a style as the core takes it: a code (a name's or a mix's, or one computed before), or a
# canonical clip or a video's keypoints to encode
StyleInput = StyleCode | Motion | Keypoints2D

NEAREST = 5  # named styles listed by nearest()
# Codes from a clip or a video are scaled down to this multiple of the largest named style
# code's norm: the decoder never saw larger codes, and throws the body about on them
# (docs/experiments/translator_constants.md).
CODE_NORM_LIMIT = 1.25
# A clip is in a named style when its own style code lies within SAME_STYLE_NEAR x the
# smallest distance between two named codes of that style's code; beyond SAME_STYLE_FAR x it
# is in none (fading between), and a named target's speed then stands alone.
SAME_STYLE_NEAR, SAME_STYLE_FAR = 0.3, 0.5
WINDOWS_PER_CALL = 256  # restyler windows per call: bounds the batch (memory) on long clips
# A style clip shorter than this carries less of its style: on foreign content the judge
# named it in 61-72 % of transfers from 1-8 frames of a take, 81 % from whole takes, 72-78 %
# from half a second (``training.short_style_clips``, docs/translator.md). A video's
# keypoints lose little with length (69 % from one frame, 75 % whole): they are not warned.
SHORT_STYLE_SECONDS = 0.5


@dataclass
class TransferJob:
    """The core's transfer: canonical ``content`` at 30 fps in ``style``, and the request's
    content clip (None when the caller gives canonical motion) for ``finish``."""

    content: Motion
    style: StyleInput
    strength: float = 1.0
    time_warp: bool = True
    foot_cleanup: bool = True
    clip: Clip | None = None
    loop: bool = False  # ``content`` is a closed cycle, to wrap around


@dataclass
class StyleCodeJob:
    """The core's style code of one style input."""

    style: StyleInput


@dataclass
class RegistrationJob:
    """A registration: each clip on the canonical skeleton with its name for messages."""

    request: RegisterStyleRequest
    clips: list[tuple[str, Motion]]

    @property
    def frames(self) -> int:
        return sum(motion.num_frames for _, motion in self.clips)


@dataclass
class Transfer:
    """A transfer's canonical result (30 fps, after clean-up and warp), the time warp
    applied to it (``finish`` warps the original clip alike) and warnings."""

    motion: Motion
    warp: Warp
    warnings: list[str] = field(default_factory=list)


def window_starts(frames: int, window: int, hop: int | None = None) -> list[int]:
    """Starts of the windows covering ``frames`` frames (``frames >= window``): every
    ``hop`` frames (half a window unless given), the last one flush with the end."""
    hop = hop or window // 2
    starts = list(range(0, frames - window + 1, hop))
    if starts[-1] != frames - window:
        starts.append(frames - window)
    return starts


class TranslatorEngine(Engine):
    family: ClassVar[str] = "translator"
    warm_dims: ClassVar[dict[str, int]] = {"batch": 1, "time": 2 * BUCKET}

    def load_assets(self) -> None:
        extra = self.entry.extra
        self.stats = Fe.FeatureStats.from_arrays(self.load_npz(extra["stats"]))
        table = self.load_npz(extra["styles_file"])
        self.style_names = [str(n) for n in table["names"]]
        self.codes = np.asarray(table["codes"], dtype=np.float32)
        self.clips = [int(c) for c in table["clips"]]
        self.velocity = [float(v) for v in table["velocity"]]
        self.speed = [float(v) for v in table["speed"]]
        self.index = {name: i for i, name in enumerate(self.style_names)}
        gains = extra["named_style_gains"]  # model_export.translator's
        self.named_codes = exaggerated(self.codes, [gains[n] for n in self.style_names])
        # how much further out a style clip's ("style") or video's ("keypoints") code plays,
        # as a name's does (older exports: as encoded)
        self.example_gains = {
            "style": float(extra.get("clip_style_gain", 1.0)),
            "keypoints": float(extra.get("video_style_gain", 1.0)),
        }
        # other names of a style (Bandai's two datasets name three styles twice)
        self.aliases = {k: v for k, v in extra.get("aliases", {}).items() if v in self.index}
        self.style_dim = int(self.codes.shape[1])
        gaps = np.linalg.norm(self.codes[:, None] - self.codes[None], axis=-1)
        # one named style: no other to tell it from, so no clip counts as in it
        self.style_gap = float(gaps[~np.eye(len(gaps), dtype=bool)].min()) if len(gaps) > 1 else 0.0
        self.max_code_norm = CODE_NORM_LIMIT * float(np.linalg.norm(self.codes, axis=1).max())
        self.min_frames = padded_length(1, int(extra["receptive_field"]))
        self.window = int(extra["window"])
        # sigma in frames, chosen at export by model_export.output_smoothing
        self.output_smoothing = float(extra["output_smoothing"])
        declared = self.entry.graphs["style3d"].outputs[0].shape[-1]
        if declared != self.style_dim:
            raise ValueError(f"style codes have {self.style_dim} dims, the graphs {declared}")

    def styles(self) -> list[dict[str, Any]]:
        return [
            {
                "name": name,
                "also_named": sorted(a for a, n in self.aliases.items() if n == name),
                "clips": self.clips[i],
                "velocity_factor": round(self.velocity[i], 4),
                "speed": round(self.speed[i], 4),
            }
            for i, name in sorted(enumerate(self.style_names), key=lambda item: item[1])
        ]  # the registered ones: the registry lists them once, beside every model's

    def row(self, name: str) -> int | None:
        """The style table's row of ``name`` or of the style it is another name of."""
        return self.index.get(self.aliases.get(name, name))

    def style_of(self, name: str) -> str | None:
        i = self.row(name)
        return None if i is None else self.style_names[i]

    def offers(self, name: str) -> bool:
        """A shipped style (or another name of one), or one registered with this model."""
        if self.row(name) is not None:
            return True
        style = self.registered.get(name)
        return style is not None and style.model == self.name

    def accepts(self, request: TranslatorRequest) -> bool:
        if isinstance(request, RegisterStyleRequest):
            return True
        return all(self.offers(name) for name in request.style.names())

    def refusal(self, request: TransferRequest | StyleCodeRequest) -> NotFound:
        unknown = next(n for n in request.style.names() if not self.offers(n))
        return self._unknown(unknown)

    def _unknown(self, name: str) -> NotFound:
        return NotFound(
            f"no translator style named {name!r}", styles=sorted(self.style_names), model=self.name
        )

    # --- prepare: the uploads onto the canonical skeleton -----------------------------------

    def prepare(
        self, request: TranslatorRequest, timer: StageTimer
    ) -> TransferJob | StyleCodeJob | RegistrationJob:
        """The style input (a name or mix: its code; a clip: canonical; keypoints: read)
        and, for a transfer, the content clip onto the canonical skeleton; for a
        registration, each clip."""
        if isinstance(request, RegisterStyleRequest):
            return self._registration_job(request, timer)
        style = self._style_input(request.style, timer)
        if isinstance(request, StyleCodeRequest):
            return StyleCodeJob(style)
        content = request.content
        clip = content.load(self.settings, timer)
        return TransferJob(clip.canonical, style, request.strength, content.time_warp,
                           content.foot_cleanup, clip, loop=clip.loop is not None)  # fmt: skip

    def _style_input(self, style: StyleSource, timer: StageTimer) -> StyleInput:
        if style.kind == "style_name":
            return self.code_of_name(style.name)
        if style.kind == "style_mix":
            return self.code_of_mix(style.mix)
        if style.kind == "keypoints":
            with timer.stage("style_parse"):
                return limits.read_keypoints(
                    style.upload.read(), self.settings, fps=style.keypoints_fps
                )
        clip = load_clip(style.upload, self.settings, timer, mapping=style.mapping, prefix="style_")
        return clip.canonical

    def _registration_job(
        self, request: RegisterStyleRequest, timer: StageTimer
    ) -> RegistrationJob:
        """Each clip parsed, mapped and onto the canonical skeleton; a bad clip is its usual
        problem, its detail naming the clip."""
        clips = []
        for k, upload in enumerate(request.clips, 1):
            what = f"clip {k} ({upload.filename or 'unnamed'})"
            try:
                clip = load_clip(upload, self.settings, timer, mapping=request.mapping,
                                 prefix="clip_")  # fmt: skip
            except Exception as exc:
                name_the_clip(exc, what)
                raise
            clips.append((what, clip.canonical))
        return RegistrationJob(request, clips)

    # --- predict: the core, canonical in and out ---------------------------------------------

    def predict(
        self, job: TransferJob | StyleCodeJob | RegistrationJob, timer: StageTimer
    ) -> Transfer | StyleCode | list[StyleCode]:
        """The family's core: a transfer's canonical result, a style input's code (as
        encoded, bounded; it plays as :meth:`played`), or each registered clip's code."""
        if isinstance(job, RegistrationJob):
            with timer.stage("clip_encode"):
                return [self._style_code(motion, timer) for _, motion in job.clips]
        if isinstance(job, StyleCodeJob):
            return self._style_code(job.style, timer)
        return self._transfer(job, timer)

    def _style_code(self, style: StyleInput, timer: StageTimer) -> StyleCode:
        """A code as given, or the style encoder's code of a canonical clip (with its
        velocity factor) or of a video's keypoints (none: a video's joint speeds are in
        image units, so no time warp)."""
        if isinstance(style, StyleCode):
            return style
        with timer.stage("style_features"):
            if isinstance(style, Keypoints2D):
                graph, source, velocity = "style2d", "keypoints", None
                x = Fe.standardize(Fe.style2d_from_keypoints(style), self.stats, "style2d")
            else:
                graph, source = "style3d", "style"
                enc = Fe.encode(style)
                velocity = Fe.encoded_velocity_factor(enc, style.fps)
                x = Fe.standardize(enc.style3d, self.stats, "style3d")
            x, _ = self._padded(x)
        with timer.stage("encode"):
            name = self.sessions[graph].get_inputs()[0].name
            code = self.run(graph, {name: x})[0][0]
        warnings = []
        if isinstance(style, Motion) and style.num_frames / style.fps < SHORT_STYLE_SECONDS:
            warnings.append(
                f"the style clip lasts {style.num_frames / style.fps:.2f} s: clips under "
                f"{SHORT_STYLE_SECONDS:g} s carry less of their style (a judge names it in "
                "about two transfers of three, against four of five from whole takes)"
            )
        return self._bounded(StyleCode(code, velocity, source, warnings))

    def _transfer(self, job: TransferJob, timer: StageTimer) -> Transfer:
        """The content's features, its own code (which tells its own speed), the restyler
        with the target code, the finish and the time warp (module docstring). At strength 0
        the content itself: the networks' own pose would be the content's, but the foot
        clean-up would still move a mocap clip's knees by up to 5 % of its height."""
        if job.strength == 0.0:
            return Transfer(job.content, Warp())
        style = self._style_code(job.style, timer)
        with timer.stage("features"):
            content, cycle = wrapped(job.content, job.loop, self.window)
            enc = Fe.encode(content)
            control = Fe.restyler_input(enc.content, enc.style3d, self.stats)
            x_own, _ = self._padded(Fe.standardize(enc.style3d, self.stats, "style3d"))
        with timer.stage("encode"):
            own = self.run("style3d", {"motion3d": x_own})[0][0]
        with timer.stage("decode"):
            by_example = style.source in self.example_gains
            played = self.played(style.code, style.source) if by_example else style.code
            output = self.restyled(control, played)
        motion = restyled_motion(output, content, enc, self.stats, timer, self.output_smoothing,
                                 job.strength, job.foot_cleanup)  # fmt: skip
        with timer.stage("anatomy"):
            motion = anatomical(motion, cycle, job.content)
        warnings = list(style.warnings)
        warp = Warp()
        if job.time_warp:
            with timer.stage("time_warp"):
                content_velocity = Fe.encoded_velocity_factor(enc, content.fps)
                speed = style.speed
                if speed is not None:
                    speed /= self.own_speed(own)
                factor, warned = self.warp_factor(
                    style.velocity, content_velocity, job.strength, speed
                )
                warp, limited = speed_limited(factor, motion)
                warnings += warned + limited
                motion = warp.apply(motion)
        return Transfer(motion, warp, warnings)

    def restyler_input(self, content: Motion) -> np.ndarray:
        """The restyler's standardised input ``(F, CONTROL_CHANNELS)`` for a canonical clip
        at 30 fps: with :meth:`restyled`, what the fast networks learn to do, one style
        each (``training.fast_style``)."""
        enc = Fe.encode(content)
        return Fe.restyler_input(enc.content, enc.style3d, self.stats)

    def restyled(self, control: np.ndarray, code: np.ndarray) -> np.ndarray:
        """The restyler's blended output ``(F, OUTPUT_CHANNELS)`` for a standardised input
        ``control (F, CONTROL_CHANNELS)`` and ``code``: windows of the training length, half a
        window apart (:meth:`_windows`), decoded and blended."""
        windows, offset, length = self._windows(control, self.window)
        blended = self._blend(self._decoded(windows, code), length)
        return blended[offset : offset + len(control)]

    # --- finish: back onto the request's skeleton, or stored -------------------------------

    def finish(
        self,
        job: TransferJob | StyleCodeJob | RegistrationJob,
        out: Transfer | StyleCode | list[StyleCode],
        timer: StageTimer,
    ) -> Result | StyleCodeResult | Registration:
        if isinstance(job, RegistrationJob):
            return self._registered(job, out, timer)
        if isinstance(job, StyleCodeJob):
            named = out.source in ("style_name", "style_mix")
            return StyleCodeResult(out, self.nearest(out.code, named=named))
        return write_result(job.clip, out.motion, self.settings, timer, warnings=out.warnings,
                            suffix="transfer", warp=out.warp)  # fmt: skip

    def _registered(
        self, job: RegistrationJob, styles: list[StyleCode], timer: StageTimer
    ) -> Registration:
        """The style of the clips: the mean of their codes (as encoded) and velocity
        factors, stored (409 if the name was taken meanwhile or the store filled up)."""
        codes = np.asarray([s.code for s in styles], np.float64)
        velocities = [s.velocity for s in styles if s.velocity is not None]
        warnings = [f"{what}: {w}" for (what, _), s in zip(job.clips, styles, strict=True)
                    for w in s.warnings]  # fmt: skip
        code = codes.mean(axis=0)
        spread = float(np.mean(np.linalg.norm(codes - code, axis=1)))
        request = job.request
        style = RegisteredStyle(
            name=request.name,
            code=code.astype(np.float32),
            velocity=float(np.mean(velocities)) if velocities else 0.0,
            speed=float(request.speed),
            model=self.name,
            version=self.version,
            clips=len(codes),
            frames=job.frames,
            spread=round(spread, 4),
            sources=tuple(u.filename or "" for u in request.clips),
            registered_by=request.registered_by,
        )
        with timer.stage("store"):
            self.registered.add(style)
        return Registration(style, self.nearest(style.code), warnings)

    # --- networks and style codes ------------------------------------------------------------

    def _padded(self, x: np.ndarray) -> tuple[np.ndarray, int]:
        """``x (F, C)`` standardised -> ``(1, C, T)`` float32 at its bucket, and the offset."""
        padded, offset = pad_mirrored(x, padded_length(len(x), self.min_frames))
        return np.ascontiguousarray(padded.T[None], dtype=np.float32), offset

    @staticmethod
    def _windows(x: np.ndarray, length: int) -> tuple[np.ndarray, int, int]:
        """``x (F, C)`` standardised -> windows ``(N, C, length)`` float32 at
        :func:`window_starts` (hop half a window), the offset of frame 0 and the length they
        cover (a clip shorter than a window is mirrored at both ends to one)."""
        offset = 0
        if len(x) < length:
            x, offset = pad_mirrored(x, length)
        windows = np.stack([x[s : s + length] for s in window_starts(len(x), length)])
        windows = np.ascontiguousarray(windows.transpose(0, 2, 1), dtype=np.float32)
        return windows, offset, len(x)

    def _decoded(self, windows: np.ndarray, code: np.ndarray) -> np.ndarray:
        """The restyler on content windows ``(N, C, length)`` for one code, in calls of at
        most :data:`WINDOWS_PER_CALL` windows."""
        target = np.asarray(code, dtype=np.float32).reshape(1, -1)
        decoded = []
        for i in range(0, len(windows), WINDOWS_PER_CALL):
            part = windows[i : i + WINDOWS_PER_CALL]
            codes = np.repeat(target, len(part), 0)
            decoded.append(self.run("restyler", {"content": part, "style_code": codes})[0])
        return np.concatenate(decoded)

    @staticmethod
    def _blend(windows: np.ndarray, frames: int) -> np.ndarray:
        """Decoded windows ``(N, C, length)`` (as :meth:`_windows` cut them) -> ``(frames, C)``,
        overlaps blended with Hann weights (every weight > 0, so every frame is covered)."""
        length = windows.shape[2]
        weight = np.hanning(length + 2)[1:-1]
        starts = np.asarray(window_starts(frames, length), dtype=np.int64)
        out, total = kernels.overlap_add(windows, starts, weight, frames)
        total = total[:, None]
        return (out / total).astype(np.float32)

    def _bounded(self, style: StyleCode) -> StyleCode:
        """``style`` with its code scaled down to ``max_code_norm`` (and a warning) when
        it lies beyond every style the decoder learned."""
        norm = float(np.linalg.norm(style.code))
        if norm <= self.max_code_norm:
            return style
        scaled = (style.code * np.float32(self.max_code_norm / norm)).astype(np.float32)
        what = {"style": "style clip", "keypoints": "video keypoints"}.get(style.source, "input")
        style.warnings.append(
            f"the style code of the {what} (norm {norm:.1f}) lies far outside the learned "
            f"styles (up to {self.max_code_norm:.1f}): scaled down to that norm"
        )
        return StyleCode(scaled, style.velocity, style.source, style.warnings, style.speed)

    def code_of_name(self, name: str) -> StyleCode:
        """The code of a named style: shipped (or another name of one), taken its
        ``named_style_gains`` from the centre of the named codes, or registered
        (``service.registered_styles``; a file read, so called in the inference pool)."""
        i = self.row(name)
        if i is None:
            if (style := self.registered.lookup(name, self.name, self.version)) is not None:
                code = self.played(style.code)  # the mean code of its clips
                return StyleCode(code, style.velocity, "style_name", speed=style.speed)
            raise self._unknown(name)
        code = self.named_codes[i].copy()
        return StyleCode(code, self.velocity[i], "style_name", speed=self.speed[i])

    def code_of_mix(self, mix: dict[str, float]) -> StyleCode:
        """Weighted mean of named codes (and of their velocity factors; geometric mean of
        their speeds); weights >= 0 with a positive sum (:func:`parse_mix`), normalised."""
        styles = [self.code_of_name(name) for name in mix]
        weights = np.array(list(mix.values()), dtype=np.float64)
        weights /= weights.sum()
        code = (weights[:, None] * np.stack([s.code for s in styles]).astype(np.float64)).sum(0)
        velocity = float(np.dot(weights, [s.velocity for s in styles]))
        speed = float(np.exp(np.dot(weights, np.log([s.speed for s in styles]))))
        return StyleCode(code.astype(np.float32), velocity, "style_mix", speed=speed)

    def played(self, code: np.ndarray, source: str = "style") -> np.ndarray:
        """The code a style clip (or a style registered from clips; ``source`` "style") or a
        video ("keypoints") plays: its :attr:`example_gains` times as far from the centre of
        the learned codes as the encoder gives it, as a name's is taken out
        (model_export.translator's ``CLIP_STYLE_GAIN``, ``VIDEO_STYLE_GAIN``). What
        ``/v1/style-code`` reports and registration stores is the code as encoded."""
        gain = self.example_gains[source]
        centre = self.codes.mean(axis=0)
        return exaggerated(np.asarray(code)[None], [gain], centre)[0]

    def nearest(
        self, code: np.ndarray, count: int = NEAREST, named: bool = False
    ) -> list[dict[str, Any]]:
        """The ``count`` named styles nearest to ``code`` (Euclidean), nearest first: among
        the codes the encoders learned for them (what clips and videos are compared with),
        or with ``named`` among those their names use (:meth:`code_of_name`)."""
        codes = self.named_codes if named else self.codes
        distances = np.linalg.norm(codes - np.asarray(code, dtype=np.float32), axis=1)
        order = np.argsort(distances, kind="stable")[:count]
        return [
            {"style": self.style_names[i], "distance": round(float(distances[i]), 4)} for i in order
        ]

    def own_speed(self, own: np.ndarray) -> float:
        """The speed of the named style a clip's own code ``own`` is in: that style's within
        ``SAME_STYLE_NEAR`` x the smallest gap between named codes, 1 (no style) beyond
        ``SAME_STYLE_FAR`` x it, geometrically between."""
        if self.style_gap <= 0:
            return 1.0
        distances = np.linalg.norm(self.codes - np.asarray(own, dtype=np.float32), axis=1)
        i = int(np.argmin(distances))
        near, far = SAME_STYLE_NEAR * self.style_gap, SAME_STYLE_FAR * self.style_gap
        weight = min(max((far - float(distances[i])) / (far - near), 0.0), 1.0)
        return float(self.speed[i] ** weight)

    def warp_factor(
        self,
        style_velocity: float | None,
        content_velocity: float,
        strength: float,
        style_speed: float | None = None,
    ) -> tuple[float, list[str]]:
        """``style_speed ** strength`` for a named style or mix, else ``(style / content) **
        strength`` (the paper's, for a style clip); clamped to [MIN_WARP, MAX_WARP]; and
        warnings."""
        if style_speed is not None:
            factor = style_speed**strength
        elif style_velocity is None:
            return 1.0, ["the style has no velocity factor (2D keypoints): no time warp"]
        elif not (style_velocity > 1e-6 and content_velocity > 1e-6):
            return 1.0, ["a clip hardly moves (velocity factor ~0): no time warp"]
        else:
            factor = (style_velocity / content_velocity) ** strength
        clamped = min(max(factor, MIN_WARP), MAX_WARP)
        if clamped != factor:
            return clamped, [
                f"time warp factor {factor:.3f} clamped to {clamped:g} "
                f"(allowed {MIN_WARP:g} to {MAX_WARP:g})"
            ]
        return factor, []


register_engine("translator", TranslatorEngine)

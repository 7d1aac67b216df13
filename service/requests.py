"""What the routes hand the data plane, family by family, and what comes back: plain data,
no HTTP. Files stay :class:`~service.clips.Upload` objects until an engine's ``prepare``
reads them in the inference pool; a clip's answer is a :class:`~service.clips.Result`."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from service.clips import Clip, GameOptions, RootMotion, Upload, load_clip
from service.config import Settings
from service.metrics import StageTimer
from service.registered_styles import RegisteredStyle

# --- what both restyling families take ------------------------------------------------------


@dataclass
class ContentClip:
    """The clip a request re-styles (/v1/transfer, /v1/stylize) and how to treat it: play
    it at the style's speed (``time_warp``), pin its foot contacts (``foot_cleanup``), a
    joint-name ``mapping``, the answer's ``format`` (None: the clip's own) and the game
    options (loop, root motion)."""

    upload: Upload
    time_warp: bool = True
    foot_cleanup: bool = True
    mapping: dict[str, str] | None = None
    format: str | None = None
    game: GameOptions = field(default_factory=GameOptions)

    @property
    def filename(self) -> str | None:
        return self.upload.filename

    def load(self, settings: Settings, timer: StageTimer) -> Clip:
        """The clip read, mapped and on the canonical skeleton (:func:`load_clip`)."""
        return load_clip(self.upload, settings, timer, mapping=self.mapping,
                         answer=self.format, game=self.game)  # fmt: skip


# --- translator -------------------------------------------------------------------------------


@dataclass
class StyleSource:
    """The one style input of a request: ``kind`` (``style``, ``keypoints``, ``style_name``
    or ``style_mix``) and what it needs; files are read when the work starts."""

    kind: str
    upload: Upload | None = None
    name: str | None = None
    mix: dict[str, float] | None = None
    keypoints_fps: float | None = None  # None: the document's rate, else 30
    mapping: dict[str, str] | None = None

    def names(self) -> list[str]:
        """The named styles it refers to."""
        return [self.name] if self.name else list(self.mix or ())


@dataclass
class TransferRequest:
    """``POST /v1/transfer``: a content clip in the style of ``style``."""

    content: ContentClip
    style: StyleSource
    strength: float = 1.0


@dataclass
class StyleCodeRequest:
    """``POST /v1/style-code``: the style code of one style input."""

    style: StyleSource


@dataclass
class RegisterStyleRequest:
    """``POST /v1/styles``: a name, the clips (BVH or glTF), an optional joint-name
    ``mapping`` for them and the time-warp ``speed``."""

    name: str
    clips: list[Upload]
    mapping: dict[str, str] | None = None
    speed: float = 1.0
    registered_by: str | None = None  # the name of the API key that asked


@dataclass
class StyleCode:
    """A style code ``(S,)`` float32, the velocity factor of its source (None when unknown,
    e.g. a video: no time warp), what it came from, warnings for the client, and for named
    styles and mixes their ``speed`` against the other styles on the same content (the
    time warp then, instead of the ratio of velocity factors)."""

    code: np.ndarray
    velocity: float | None
    source: str
    warnings: list[str] = field(default_factory=list)
    speed: float | None = None


@dataclass
class StyleCodeResult:
    """A style code, the named styles nearest to it, and (set by the data plane) the model
    and stage timings."""

    code: StyleCode
    nearest: list[dict[str, Any]]
    model: tuple[str, str] = ("", "")
    timer: StageTimer | None = None


@dataclass
class Registration:
    """A registered style, the shipped styles nearest its code, warnings, and (set by the
    data plane) the model and stage timings."""

    style: RegisteredStyle
    nearest: list[dict[str, Any]]
    warnings: list[str]
    model: tuple[str, str] = ("", "")
    timer: StageTimer | None = None


# --- fast -------------------------------------------------------------------------------------


@dataclass
class StylizeRequest:
    """``POST /v1/stylize``: a content clip and one named style."""

    content: ContentClip
    style_name: str


# --- dance ------------------------------------------------------------------------------------


@dataclass
class DanceRequest:
    """``POST /v1/dance``: music, an optional genre (predicted when None), a seed, an
    optional skeleton to retarget onto, the frame rate of the answer and its root motion
    (keep the travel across the floor, or in_place)."""

    audio: Upload
    genre: str | None = None
    seed: int = 0
    skeleton: Upload | None = None
    fps: float = 30.0
    mapping: dict[str, str] | None = None
    format: str | None = None  # of the answer; None: the skeleton's, BVH without one
    root_motion: RootMotion = "keep"

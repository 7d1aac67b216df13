"""Registered styles: translator styles a studio makes from its own clips (``POST
/v1/styles``), one JSON file each in a folder (``MOTION_STYLES_DIR``).

The folder is the only state. Every lookup reads it (a name is one small file), so a style
registered or deleted through one worker or replica is seen by all of them at once, with
no cache to go stale. A file is written whole under a temporary name and linked into place,
so a reader never sees half of one, and the link claims the name: of two workers
registering one name at once, one gets a 409. The count limit is checked under a lock file.

Plain storage: the translator engine codes a style's clips and hands the style here. A
style's code is the mean of its clips' style codes (the translator's ``style3d`` network),
kept with the model name and version that computed it: codes of another training do not
share its space, so a style registered under another version is refused (409) until it is
registered again from its clips.

Its ``speed`` (the time warp of a named style against the content's own) is 1 unless the
studio gives one: the shipped styles' speeds compare each style with the others performing
the same content, which clips of one style cannot. ``velocity_factor`` (the clips' mean) is
reported, as for the shipped styles.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import logging
import os
import re
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from service.config import Settings
from service.errors import Conflict, InsufficientStorage, InvalidRequest

logger = logging.getLogger(__name__)

NAME = re.compile(r"[a-z0-9][a-z0-9_-]{0,47}")
NAME_RULE = "1-48 characters of a-z, 0-9, '_' and '-', starting with a letter or digit"
SUFFIX = ".json"


def check_name(name: str) -> str:
    """``name`` when it is a valid style name, else a 400 problem naming the rule."""
    if not NAME.fullmatch(name):
        raise InvalidRequest(
            f"style name {name[:60]!r} is not allowed: {NAME_RULE}", field="name", rule=NAME_RULE
        )
    return name


@dataclass(frozen=True)
class RegisteredStyle:
    """A registered style: its code ``(S,)``, the clips' mean velocity factor, its time-warp
    ``speed``, where it came from and the translator (name, version) that coded it."""

    name: str
    code: np.ndarray
    velocity: float
    speed: float
    model: str
    version: str
    clips: int
    frames: int  # of the clips, at 30 fps on the canonical skeleton
    spread: float  # mean distance of the clips' codes from the style's code
    sources: tuple[str, ...] = ()
    created: str = field(default_factory=lambda: datetime.now(UTC).isoformat(timespec="seconds"))
    registered_by: str | None = None  # the name of the API key that registered it

    def to_json(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "code": [round(float(v), 7) for v in self.code],
            "velocity_factor": self.velocity,
            "speed": self.speed,
            "model": {"name": self.model, "version": self.version},
            "clips": self.clips,
            "frames": self.frames,
            "spread": self.spread,
            "sources": list(self.sources),
            "created": self.created,
            "registered_by": self.registered_by,
        }

    @classmethod
    def from_json(cls, doc: dict[str, Any]) -> RegisteredStyle:
        """A style from :meth:`to_json`'s document; ``ValueError`` when it is not one."""
        try:
            code = np.asarray(doc["code"], dtype=np.float32)
            style = cls(
                name=str(doc["name"]),
                code=code,
                velocity=float(doc["velocity_factor"]),
                speed=float(doc["speed"]),
                model=str(doc["model"]["name"]),
                version=str(doc["model"]["version"]),
                clips=int(doc["clips"]),
                frames=int(doc["frames"]),
                spread=float(doc["spread"]),
                sources=tuple(str(s) for s in doc.get("sources", ())),
                created=str(doc.get("created", "")),
                registered_by=str(doc["registered_by"]) if doc.get("registered_by") else None,
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"not a registered style: {exc}") from None
        if code.ndim != 1 or not np.isfinite(code).all() or not NAME.fullmatch(style.name):
            raise ValueError("not a registered style: bad name or code")
        return style

    def listing(self) -> dict[str, Any]:
        """Its entry in ``GET /v1/styles`` (beside the shipped translator styles)."""
        return {
            "name": self.name,
            "clips": self.clips,
            "velocity_factor": round(self.velocity, 4),
            "speed": round(self.speed, 4),
            "registered": True,
            "frames": self.frames,
            "created": self.created,
            "model_version": self.version,
            **({"registered_by": self.registered_by} if self.registered_by else {}),
        }


class StyleStore:
    """The registered styles in ``folder``: at most ``max_styles`` of them."""

    def __init__(self, folder: Path, max_styles: int) -> None:
        self.folder = Path(folder).resolve()
        self.max_styles = max_styles

    @classmethod
    def from_settings(cls, settings: Settings) -> StyleStore:
        return cls(settings.styles_dir, settings.max_registered_styles)

    def _path(self, name: str) -> Path:
        return self.folder / f"{name}{SUFFIX}"

    # --- reading (any worker, any time) --------------------------------------------------------

    def __contains__(self, name: object) -> bool:
        return isinstance(name, str) and bool(NAME.fullmatch(name)) and self._path(name).is_file()

    def get(self, name: str) -> RegisteredStyle | None:
        """The style registered as ``name``, or None (also for a file that cannot be read,
        which is logged)."""
        if not NAME.fullmatch(name):
            return None
        return self._read(self._path(name))

    def lookup(self, name: str, model: str, version: str) -> RegisteredStyle | None:
        """:meth:`get` for the translator ``model`` at ``version``: a style it did not code
        is a 409 problem (register it again)."""
        style = self.get(name)
        if style is not None and (style.model, style.version) != (model, version):
            raise Conflict(
                f"style {name!r} was registered with {style.model} {style.version}; the service "
                f"now runs {model} {version}, whose codes differ: register it again from its "
                f"clips (DELETE /v1/styles/{name}, then POST /v1/styles)",
                style=name,
                registered_with=f"{style.model}/{style.version}",
            )
        return style

    def all(self) -> list[RegisteredStyle]:
        """Every readable registered style, by name."""
        try:
            paths = sorted(self.folder.glob(f"*{SUFFIX}"))
        except OSError:
            return []
        styles = (self._read(p) for p in paths if NAME.fullmatch(p.stem))
        return [s for s in styles if s is not None]

    def _read(self, path: Path) -> RegisteredStyle | None:
        try:
            doc = json.loads(path.read_text())
            return RegisteredStyle.from_json(doc)
        except (FileNotFoundError, NotADirectoryError):
            return None
        except (OSError, ValueError) as exc:
            logger.warning("skipping registered style %s: %s", path, exc)
            return None

    # --- writing ---------------------------------------------------------------------------

    @contextlib.contextmanager
    def _locked(self) -> Iterator[None]:
        """The store's lock (a lock file; every worker and, on a shared volume that honours
        flock, every replica), created with the folder."""
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
            lock = open(self.folder / ".lock", "a")  # noqa: SIM115 - closed below
        except OSError as exc:
            raise self._unwritable(exc) from None
        with lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            yield

    def _unwritable(self, exc: OSError) -> InsufficientStorage:
        logger.error("cannot write the styles folder %s: %s", self.folder, exc)
        return InsufficientStorage(
            f"the styles folder cannot be written ({exc.strerror or exc}); "
            "its path is set by MOTION_STYLES_DIR"
        )

    def check_room(self, name: str) -> None:
        """409 when ``name`` is registered already or the store is full (before the work
        of coding the clips; :meth:`add` checks again)."""
        if name in self:
            raise Conflict(f"a style named {name!r} is registered already", style=name)
        if self.max_styles <= 0:
            raise Conflict(
                "style registration is off (MOTION_MAX_REGISTERED_STYLES=0)",
                limit=0,
                limit_name="max_registered_styles",
            )
        if len(list(self.folder.glob(f"*{SUFFIX}"))) >= self.max_styles:
            raise self._full()

    def _full(self) -> Conflict:
        return Conflict(
            f"{self.max_styles} styles are registered, the most this service keeps: delete one "
            "first (DELETE /v1/styles/{name})",
            limit=self.max_styles,
            limit_name="max_registered_styles",
        )

    def add(self, style: RegisteredStyle) -> None:
        """Store ``style`` under its name: 409 when the name is taken or the store is full,
        507 when the folder cannot be written."""
        data = json.dumps(style.to_json(), indent=1).encode()
        with self._locked():
            self.check_room(style.name)
            try:
                fd, tmp = tempfile.mkstemp(prefix=".new-", dir=self.folder)
                try:
                    with os.fdopen(fd, "wb") as f:
                        f.write(data)
                        f.flush()
                        os.fsync(f.fileno())
                    os.link(tmp, self._path(style.name))  # fails if the name exists
                finally:
                    os.unlink(tmp)
            except FileExistsError:
                raise Conflict(
                    f"a style named {style.name!r} is registered already", style=style.name
                ) from None
            except OSError as exc:
                raise self._unwritable(exc) from None

    def remove(self, name: str) -> bool:
        """Delete the style ``name``; False when there is none. 507 when the folder cannot be
        written."""
        if not NAME.fullmatch(name):
            return False
        try:
            self._path(name).unlink()
        except (FileNotFoundError, NotADirectoryError):
            return False
        except OSError as exc:
            raise self._unwritable(exc) from None
        return True

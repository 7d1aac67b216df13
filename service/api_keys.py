"""API keys: the keys file (``MOTION_API_KEYS_FILE``), reading it again when it changes,
and knowing a presented key in constant time.

One key a line, a name, its scopes and the SHA-256 of the key (never the key), and when it
was made::

    # motion-style API keys: NAME SCOPES SHA256 [CREATED]
    studio-a use,manage 6b1d...(64 hex digits) 2026-11-28T02:10:00Z
    render-farm use 0c4e... 2026-11-28T02:11:30Z

Scopes: ``use`` (every route that reads or computes) and ``manage`` (also what changes the
service's state: ``POST``/``DELETE /v1/styles``); ``manage`` includes ``use``. Names are
1-48 characters of ``a-z``, ``0-9``, ``_``, ``-``: they go into logs and metric labels.

A key is ``msk_`` and 43 random URL-safe characters (256 bits), so a plain SHA-256 is as
hard to reverse as the key is to guess. :func:`add_key` and :func:`revoke_key` (``python -m
service keys``) rewrite the file whole under a new name and rename it into place, so a
reader never sees half of it; :class:`KeysFile` compares the file's inode, size and
modification time on every request and reads it again when one changed, so a revoked key
stops working at once in every worker and every replica that sees the file.
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import hmac
import logging
import os
import re
import secrets
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

logger = logging.getLogger(__name__)

SCOPES = ("use", "manage")
KEY_PREFIX = "msk_"
NAME = re.compile(r"[a-z0-9][a-z0-9_-]{0,47}")
NAME_RULE = "1-48 characters of a-z, 0-9, '_' and '-', starting with a letter or digit"
_DIGEST = re.compile(r"[0-9a-f]{64}")
HEADER = "# motion-style API keys: NAME SCOPES SHA256 [CREATED]; see docs/api-keys.md\n"
MAX_KEY_LENGTH = 512  # longer is not one of ours: refused before it is hashed


class KeysFileError(Exception):
    """The keys file cannot be read or changed; the message says why (never a key)."""


@dataclass(frozen=True)
class ApiKey:
    """One line of the keys file: the key's name, scopes and digest (raw SHA-256 bytes)."""

    name: str
    scopes: frozenset[str]
    digest: bytes
    created: str = ""

    def allows(self, scope: str) -> bool:
        return scope in self.scopes or (scope == "use" and "manage" in self.scopes)

    def line(self) -> str:
        scopes = ",".join(s for s in SCOPES if s in self.scopes)
        return f"{self.name} {scopes} {self.digest.hex()} {self.created}".rstrip() + "\n"


def new_key() -> str:
    """A new random key (shown once, stored only as its digest)."""
    return KEY_PREFIX + secrets.token_urlsafe(32)


def digest_of(key: str) -> bytes:
    return hashlib.sha256(key.encode("utf-8", "surrogateescape")).digest()


def parse_scopes(text: str) -> frozenset[str]:
    """``"use,manage"`` -> the scopes; ``ValueError`` otherwise (which does not repeat the
    text: in a keys file it could be a key on the wrong line)."""
    scopes = frozenset(s.strip() for s in text.split(",") if s.strip())
    if not scopes or not scopes <= set(SCOPES):
        raise ValueError(f"the scopes are not a comma-separated list of {', '.join(SCOPES)}")
    return scopes


def parse(text: str, source: str = "keys file") -> list[ApiKey]:
    """The keys in ``text``. A malformed line is skipped with a warning naming its number,
    never its text (it may hold a key pasted by mistake); a repeated name keeps the first."""
    keys: dict[str, ApiKey] = {}
    for number, raw in enumerate(text.splitlines(), 1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        parts = line.split()
        try:
            if len(parts) not in (3, 4):
                raise ValueError("expected NAME SCOPES SHA256 [CREATED]")
            name, scopes, digest = parts[:3]
            if not NAME.fullmatch(name):
                raise ValueError(f"the name is not {NAME_RULE}")
            if not _DIGEST.fullmatch(digest):
                raise ValueError("the third field is not a SHA-256 in 64 lowercase hex digits")
            key = ApiKey(name, parse_scopes(scopes), bytes.fromhex(digest), *parts[3:])
        except ValueError as exc:
            logger.warning("%s line %d skipped: %s", source, number, exc)
            continue
        if name in keys:
            logger.warning(
                "%s line %d skipped: the name %s is taken by an earlier line", source, number, name
            )
            continue
        keys[name] = key
    return list(keys.values())


class KeysFile:
    """The keys of ``path``, read again whenever the file changes (checked at each
    :meth:`identify`, one ``stat``). A file that cannot be read after start-up counts as no
    keys (every request is refused) until it can: deleting it revokes every key."""

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        self._seen: tuple[int, ...] | None = None
        self._keys: list[ApiKey] = []
        self._reads = 0
        try:
            self._reload(os.stat(self.path))
        except OSError as exc:
            raise KeysFileError(
                f"the API keys file {self.path} (MOTION_API_KEYS_FILE) cannot be read: "
                f"{exc.strerror or exc}"
            ) from None

    @property
    def keys(self) -> list[ApiKey]:
        self.refresh()
        return list(self._keys)

    def refresh(self) -> None:
        try:
            stat = os.stat(self.path)
        except OSError as exc:
            if self._seen is not None:
                logger.error(
                    "API keys file %s cannot be read (%s): refusing every key",
                    self.path,
                    exc.strerror or exc,
                )
                self._seen, self._keys = None, []
            return
        if self._signature(stat) != self._seen:
            try:
                self._reload(stat)
            except OSError as exc:
                logger.error(
                    "API keys file %s cannot be read (%s): refusing every key",
                    self.path,
                    exc.strerror or exc,
                )
                # tried again when the file changes (a chmod changes its ctime), not each time
                self._seen, self._keys = self._signature(stat), []

    @staticmethod
    def _signature(stat: os.stat_result) -> tuple[int, ...]:
        return (stat.st_dev, stat.st_ino, stat.st_size, stat.st_mtime_ns, stat.st_ctime_ns)

    def _reload(self, stat: os.stat_result) -> None:
        text = self.path.read_text(encoding="utf-8", errors="replace")
        self._keys = parse(text, source=f"API keys file {self.path}")
        self._seen = self._signature(stat)
        self._reads += 1
        names = ", ".join(k.name for k in self._keys) or "none"
        logger.info(
            "API keys %s from %s: %s",
            "read" if self._reads == 1 else "read again",
            self.path,
            names,
        )

    def identify(self, key: str) -> ApiKey | None:
        """The entry of ``key``, or None. Every entry's digest is compared, in constant
        time, whichever matches, so the time taken says nothing about the keys."""
        self.refresh()
        if len(key) > MAX_KEY_LENGTH:
            return None
        digest = digest_of(key)
        found = None
        for entry in self._keys:
            if hmac.compare_digest(entry.digest, digest):
                found = entry
        return found


# --- changing the file (python -m service keys) -------------------------------------------


@contextlib.contextmanager
def _locked(path: Path) -> Iterator[None]:
    """Hold a lock beside ``path`` (``.NAME.lock``) while the file is read and replaced,
    so two ``keys add`` at once both land."""
    lock_path = path.with_name(f".{path.name}.lock")
    try:
        lock = open(lock_path, "a")  # noqa: SIM115 - closed below
    except OSError as exc:
        raise KeysFileError(f"cannot lock {path}: {exc.strerror or exc}") from None
    with lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        yield


def read_keys(path: Path) -> list[ApiKey]:
    """The keys in ``path`` (none when it does not exist yet)."""
    try:
        return parse(Path(path).read_text(encoding="utf-8"), source=str(path))
    except FileNotFoundError:
        return []
    except OSError as exc:
        raise KeysFileError(f"cannot read {path}: {exc.strerror or exc}") from None


def _write(path: Path, keys: list[ApiKey]) -> None:
    """Replace ``path`` whole: a new file in its folder, renamed over it, with the mode of
    the file it replaces (0600 for a new one; a container's user may need it readable)."""
    text = HEADER + "".join(k.line() for k in keys)
    try:
        mode = path.stat().st_mode & 0o777
    except FileNotFoundError:
        mode = 0o600
    except OSError as exc:
        raise KeysFileError(f"cannot read {path}: {exc.strerror or exc}") from None
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
        try:
            os.fchmod(fd, mode)
            with os.fdopen(fd, "w", encoding="utf-8") as f:
                f.write(text)
                f.flush()
                os.fsync(f.fileno())
            os.replace(tmp, path)
        except BaseException:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
            raise
    except OSError as exc:
        raise KeysFileError(f"cannot write {path}: {exc.strerror or exc}") from None


def add_key(path: Path, name: str, scopes: frozenset[str]) -> str:
    """Make a key named ``name`` with ``scopes``, append its line to ``path`` (made if
    missing) and return the key: the only time it is seen."""
    path = Path(path)
    if not NAME.fullmatch(name):
        raise KeysFileError(f"the key name {name[:60]!r} is not allowed: {NAME_RULE}")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise KeysFileError(f"cannot make {path.parent}: {exc.strerror or exc}") from None
    key = new_key()
    created = datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ")
    with _locked(path):
        keys = read_keys(path)
        if any(k.name == name for k in keys):
            raise KeysFileError(f"a key named {name!r} exists already: revoke it first")
        _write(path, [*keys, ApiKey(name, scopes, digest_of(key), created)])
    return key


def revoke_key(path: Path, name: str) -> bool:
    """Remove the key ``name`` from ``path``; False when there is none."""
    path = Path(path)
    with _locked(path):
        keys = read_keys(path)
        kept = [k for k in keys if k.name != name]
        if len(kept) == len(keys):
            return False
        _write(path, kept)
    return True

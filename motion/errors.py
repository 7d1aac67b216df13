"""The one exception type of the motion library."""

from __future__ import annotations


class MotionError(ValueError):
    """Input that the motion library cannot use.

    ``kind`` says how a caller should treat it: ``"invalid"`` for malformed input
    (HTTP 400), ``"unusable"`` for well-formed input that cannot be processed,
    e.g. a skeleton that cannot be mapped or audio with no sound (HTTP 422),
    ``"too-large"`` for input over a limit (HTTP 413), ``"unsupported"`` for a
    format we do not read (HTTP 415).
    Optional details travel as attributes: ``line`` (1-based line of a text
    file), ``unmapped`` (joint names that could not be mapped), ``limit``.
    """

    def __init__(
        self,
        message: str,
        *,
        kind: str = "invalid",
        line: int | None = None,
        unmapped: list[str] | None = None,
        limit: float | int | None = None,
    ) -> None:
        super().__init__(message)
        self.message = message
        self.kind = kind
        self.line = line
        self.unmapped = unmapped
        self.limit = limit

    def details(self) -> dict:
        """Extension members worth showing to a client (only those that are set)."""
        out: dict = {}
        if self.line is not None:
            out["line"] = self.line
        if self.unmapped is not None:
            out["unmapped"] = list(self.unmapped)
        if self.limit is not None:
            out["limit"] = self.limit
        return out

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


class AmbiguousRigError(MotionError):
    """A humanoid skeleton whose mapping cannot be decided: two chains alike and nothing
    (geometry, names) telling which is which. Always ``kind="unusable"`` (HTTP 422).

    ``chains``: per undecided pair, ``{"limbs": "legs", "chains": [[names...], [names...]]}``;
    ``example_mapping``: a ``mapping`` that would settle it (canonical joint -> joint name).
    """

    def __init__(self, message: str, *, chains: list[dict], example_mapping: dict[str, str]):
        super().__init__(message, kind="unusable")
        self.chains = chains
        self.example_mapping = example_mapping

    def details(self) -> dict:
        out = super().details()
        out["ambiguous"] = self.chains
        out["mapping_example"] = dict(self.example_mapping)
        out["mapping_help"] = (
            "send a 'mapping' form field (JSON object, canonical joint -> your joint name, "
            "either way round) naming the left side of each pair"
        )
        return out

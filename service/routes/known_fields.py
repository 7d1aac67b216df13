"""Unknown form fields and query parameters are a 400, never ignored: a misspelt
``root_motion=in_place`` must not answer 200 with the root travelling.

:func:`only_known_fields` is a route dependency; it reads the names the route declares
(its own parameters and its dependencies', by their aliases) from FastAPI's view of the
route, once per route, and compares the request's query and form (which FastAPI has
already parsed, so it is not read twice) with them."""

from __future__ import annotations

from fastapi import Request
from fastapi.dependencies.models import Dependant

from service.errors import InvalidRequest

_DECLARED: dict[int, tuple[frozenset[str], frozenset[str]]] = {}


def declared_fields(dependant: Dependant) -> tuple[frozenset[str], frozenset[str]]:
    """The query parameter and form field names ``dependant`` and its dependencies read."""
    query, form = set(), set()
    stack = [dependant]
    while stack:
        d = stack.pop()
        query.update(f.alias for f in d.query_params)
        form.update(f.alias for f in d.body_params)
        stack.extend(d.dependencies)
    return frozenset(query), frozenset(form)


async def only_known_fields(request: Request) -> None:
    """400 naming every query parameter and form field the route does not read, and saying
    where a name belongs when it came in the other place (``-F format=glb`` for the query
    parameter ``?format=glb``)."""
    route = request.scope.get("route")
    dependant = getattr(route, "dependant", None)
    if dependant is None:
        return
    key = id(route)
    if key not in _DECLARED:
        _DECLARED[key] = declared_fields(dependant)
    query, form = _DECLARED[key]
    in_query = set(request.query_params) - query
    in_form: set[str] = set()
    media = request.headers.get("content-type", "")
    if media.startswith(("multipart/form-data", "application/x-www-form-urlencoded")):
        in_form = set((await request.form()).keys()) - form
    misplaced = sorted((in_query & form) | (in_form & query))
    unknown = sorted((in_query | in_form) - set(misplaced))
    if not (unknown or misplaced):
        return
    parts = []
    if unknown:
        s = "s" if len(unknown) > 1 else ""
        parts.append(f"unknown field{s} {', '.join(map(repr, unknown))}")
    for name in misplaced:
        where = f"the query string (?{name}=...)" if name in query else "the form"
        parts.append(f"{name!r} is read from {where}, not from where it was sent")
    known = sorted(query | form)
    raise InvalidRequest(
        f"{'; '.join(parts)}; this endpoint reads the form fields {', '.join(sorted(form))}"
        + (f" and the query parameters {', '.join(sorted(query))}" if query else ""),
        unknown=unknown,
        misplaced=misplaced,
        known=known,
    )

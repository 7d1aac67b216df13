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
    """400 naming every query parameter and form field the route does not read."""
    route = request.scope.get("route")
    dependant = getattr(route, "dependant", None)
    if dependant is None:
        return
    key = id(route)
    if key not in _DECLARED:
        _DECLARED[key] = declared_fields(dependant)
    query, form = _DECLARED[key]
    unknown = sorted(set(request.query_params) - query)
    media = request.headers.get("content-type", "")
    if media.startswith(("multipart/form-data", "application/x-www-form-urlencoded")):
        unknown += sorted(set((await request.form()).keys()) - form - set(unknown))
    if unknown:
        known = sorted(query | form)
        raise InvalidRequest(
            f"unknown field{'s' if len(unknown) > 1 else ''} {', '.join(map(repr, unknown))}; "
            f"this endpoint reads {', '.join(known)}",
            unknown=unknown,
            known=known,
        )

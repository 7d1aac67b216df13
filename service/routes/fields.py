"""The form fields several routes share, declared once with one description each, and the
readers that turn a form's fields into what the data plane takes (:mod:`service.clips`
uploads, parsed JSON): 415 for a wrong media type, 413 over ``max_upload_bytes``, 400 for an
empty file or a field that does not parse."""

from __future__ import annotations

import json
import math
from typing import Annotated

from fastapi import Depends, File, Form, Query, UploadFile

from service.clips import Format, GameOptions, LoopMode, RootMotion, Upload
from service.config import Settings
from service.deps import SettingsDep
from service.errors import InvalidRequest, PayloadTooLarge, UnsupportedMediaType
from service.requests import ContentClip

# Media types a BVH upload may carry (clients label text files in many ways).
TEXT_TYPES = ("text/", "application/octet-stream", "application/x-bvh", "application/bvh")
# ... and a clip, which may be glTF (the bytes decide which)
CLIP_TYPES = (
    *TEXT_TYPES, "model/gltf-binary", "model/gltf+json", "application/json",
    "application/vnd.autodesk.fbx", "model/fbx", "model/vnd.fbx",
)  # fmt: skip
CLIP_WHAT = "a BVH, glTF (.glb) or FBX file"

MappingField = Annotated[
    str | None,
    Form(
        description="JSON object of joint names, the clip's to the canonical ones (either way "
        "round), for joints the known naming conventions miss"
    ),
]
RootMotionField = Annotated[
    RootMotion,
    Form(
        description="keep the root's travel across the floor, or in_place: the hips held "
        "over one spot on the floor (vertical bob and facing kept)"
    ),
]
FormatQuery = Annotated[
    Format | None,
    Query(
        description="answer format; default the clip's own (BVH, GLB or FBX). glb and fbx "
        "need a clip in that format to write into; json gives the result as BVH text with "
        "frames, rate, model, timings, warnings, rig"
    ),
]


def upload(
    file: UploadFile,
    settings: Settings,
    *,
    field: str = "content",
    accept: tuple[str, ...] = CLIP_TYPES,
    what: str = CLIP_WHAT,
) -> Upload:
    """An uploaded file as an :class:`Upload`: 415 when its media type starts with none of
    ``accept`` (``'<field>' must be <what>``), 413 over ``max_upload_bytes`` (the middleware
    usually stops it first), 400 when empty."""
    media = (file.content_type or "").split(";")[0].strip().lower()
    if media and not media.startswith(accept):
        raise UnsupportedMediaType(
            f"'{field}' must be {what}, got media type {media!r}", field=field
        )
    size = file.size
    if size is None:
        file.file.seek(0, 2)
        size = file.file.tell()
    if size > settings.max_upload_bytes:
        raise upload_too_large(field, settings)
    if size == 0:
        raise InvalidRequest(f"'{field}' is empty", field=field)
    return Upload(field, file=file.file, filename=file.filename)


def text_upload(text: str, settings: Settings, *, field: str) -> Upload:
    """A file sent as a plain form field (BVH text)."""
    data = text.encode()
    if len(data) > settings.max_upload_bytes:
        raise upload_too_large(field, settings)
    return Upload(field, data=data)


def upload_too_large(field: str, settings: Settings) -> PayloadTooLarge:
    return PayloadTooLarge(
        f"'{field}' is over {settings.max_upload_bytes} bytes",
        limit=settings.max_upload_bytes,
        limit_name="max_upload_bytes",
    )


def parse_mapping(text: str | None, field: str = "mapping") -> dict[str, str] | None:
    """An optional joint-name map field: a JSON object of joint names (either way round);
    400 naming ``field`` when it is not one."""
    if text is None or not text.strip():
        return None
    try:
        value = json.loads(text)
    except ValueError as exc:
        raise InvalidRequest(f"'{field}' is not JSON: {exc}", field=field) from None
    if not isinstance(value, dict) or not all(
        isinstance(k, str) and isinstance(v, str) for k, v in value.items()
    ):
        raise InvalidRequest(f"'{field}' must be a JSON object of joint names", field=field)
    return value


def parse_mix(text: str) -> dict[str, float]:
    """The ``style_mix`` field: a JSON object name -> weight, weights finite and >= 0 with a
    positive sum; 400 otherwise. Weights are returned as given (normalised later)."""
    try:
        value = json.loads(text)
    except ValueError as exc:
        raise InvalidRequest(f"'style_mix' is not JSON: {exc}", field="style_mix") from None
    if not isinstance(value, dict) or not value:
        raise InvalidRequest(
            "'style_mix' must be a non-empty JSON object of style name -> weight",
            field="style_mix",
        )
    mix: dict[str, float] = {}
    for name, weight in value.items():
        number = isinstance(weight, int | float) and not isinstance(weight, bool)
        if not number or not math.isfinite(weight) or weight < 0:
            raise InvalidRequest(
                f"'style_mix' weight of {name!r} must be a finite number >= 0, got {weight!r}",
                field="style_mix",
            )
        mix[name] = float(weight)
    if sum(mix.values()) <= 0:
        raise InvalidRequest("'style_mix' weights must have a positive sum", field="style_mix")
    return mix


async def read_content_fields(
    settings: SettingsDep,
    content: Annotated[UploadFile, File(description="content clip (BVH or glTF)")],
    time_warp: Annotated[
        bool,
        Form(
            description="play the result at the style's speed (a style clip's: the ratio of "
            "velocity factors); the frame count may change"
        ),
    ] = True,
    foot_cleanup: Annotated[bool, Form(description="pin the content's foot contacts")] = True,
    mapping: MappingField = None,
    format: FormatQuery = None,  # noqa: A002
    loop: Annotated[
        LoopMode,
        Form(
            description="auto: a clip whose last pose meets its first (root travel aside) "
            "comes back looping; true: take it as a loop; false: never"
        ),
    ] = "auto",
    root_motion: RootMotionField = "keep",
) -> ContentClip:
    """The content fields as one dependency: the routes that re-style a clip declare them
    once, and hand the request its :class:`ContentClip`."""
    return ContentClip(
        upload(content, settings),
        time_warp,
        foot_cleanup,
        parse_mapping(mapping),
        format,
        GameOptions(loop, root_motion),
    )


ContentDep = Annotated[ContentClip, Depends(read_content_fields)]

"""Service settings: environment variables with a ``MOTION_`` prefix (``MOTION_PORT=9000``).

Settings are created by the app factory (or ``python -m service``), never at import time,
and reach handlers through :data:`service.deps.SettingsDep`.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Annotated, Literal

from pydantic import Field, field_validator
from pydantic_settings import BaseSettings, NoDecode, SettingsConfigDict

REPO_MODELS_DIR = Path(__file__).resolve().parent.parent / "models"


def available_cpus() -> int:
    """CPU cores this process may use: its affinity mask, capped by a cgroup v2 CPU quota.

    onnxruntime sizes its thread pools to the host's cores, not a container's share, so the
    service sizes them itself from this number.
    """
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        cores = os.cpu_count() or 1
    try:
        quota, period = Path("/sys/fs/cgroup/cpu.max").read_text().split()[:2]
        if quota != "max":
            cores = min(cores, math.ceil(int(quota) / int(period)))
    except (OSError, ValueError):
        pass
    return max(1, cores)


def _per_worker_cores(data: dict) -> int:
    return max(1, available_cpus() // max(1, int(data.get("workers") or 1)))


class Settings(BaseSettings):
    """Every knob of the service. Field names are the environment variables without prefix."""

    model_config = SettingsConfigDict(env_prefix="MOTION_", extra="ignore", frozen=True)

    host: str = "127.0.0.1"
    port: int = Field(8000, ge=0, le=65535)
    workers: int = Field(1, ge=1, description="uvicorn worker processes")
    models_dir: Annotated[tuple[Path, ...], NoDecode] = Field(
        (REPO_MODELS_DIR,),
        description="model folders, each holding a manifest.json: one, or several separated "
        f"by {os.pathsep!r} (a studio's models beside the shipped ones); the first folder's "
        "model takes the requests that name no style",
    )

    max_upload_bytes: int = Field(20 * 1024 * 1024, ge=1, description="request body limit")
    max_frames: int = Field(20_000, ge=1, description="frames per clip, in or out")
    max_audio_seconds: float = Field(900.0, gt=0, description="decoded audio length limit")
    request_timeout_s: float = Field(60.0, gt=0, description="limit for one inference (-> 504)")
    queue_wait_s: float = Field(
        5.0, gt=0, description="longest wait for an inference slot before a 503 (overloaded)"
    )
    max_queued: int = Field(
        32, ge=0, description="requests waiting for an inference slot; one more is a 503"
    )

    # Declared after ``workers``: their defaults are computed from it.
    max_concurrent_inferences: int = Field(
        default_factory=_per_worker_cores,
        ge=1,
        description="inferences running at once per worker; default cores // workers",
    )
    intra_op_threads: int = Field(
        default_factory=_per_worker_cores,
        ge=1,
        description="onnxruntime intra-op threads per session; default cores // workers",
    )

    fbx_workers: int = Field(
        default_factory=lambda data: min(2, _per_worker_cores(data)),
        ge=0,
        description="Blender processes reading and writing FBX per worker (the fbx extra); "
        "0: FBX is refused (415); default min(2, cores // workers)",
    )

    styles_dir: Path = Field(
        Path("styles"),
        description="folder of the registered styles (POST /v1/styles), relative to the "
        "working directory; every worker and replica must see the same one",
    )
    max_registered_styles: int = Field(
        100, ge=0, description="registered styles kept at most (0: registration is off)"
    )
    max_style_clips: int = Field(32, ge=1, description="clips one style is registered from")

    api_keys_file: Path | None = Field(
        None,
        description="file of the API keys (name, scopes, SHA-256 of the key; `python -m "
        "service keys add`): set, every /v1 request needs a key; unset, the service is open",
    )
    metrics_key_required: bool = Field(
        False, description="GET /metrics also needs a key (when api_keys_file is set)"
    )
    key_requests_per_minute: float = Field(
        600.0, ge=0, description="requests one API key may make a minute, per replica (0: any)"
    )
    key_burst: int = Field(
        30, ge=1, description="requests one API key may make at once after a pause, per replica"
    )
    key_max_concurrent: int = Field(
        8, ge=0, description="requests of one API key in progress at once, per replica (0: any)"
    )
    key_state_dir: Path | None = Field(
        None,
        description="folder where the workers of a replica share the keys' rate and "
        "concurrency counts (`python -m service` makes one; default: a folder per process)",
    )

    log_level: Literal["critical", "error", "warning", "info", "debug"] = "info"
    log_format: Literal["text", "json"] = Field("text", description="json: one object a line")

    debug_routes: bool = Field(
        False, description="serve /_debug/* (slow requests for shutdown tests); never in production"
    )

    @field_validator("models_dir", mode="before")
    @classmethod
    def _model_folders(cls, value: object) -> object:
        # MOTION_MODELS_DIR=models:/srv/studio, as PATH lists folders; a list as it is
        if isinstance(value, str):
            value = [part for part in value.split(os.pathsep) if part.strip()]
        elif isinstance(value, os.PathLike):
            value = [value]
        if isinstance(value, list | tuple) and not value:
            raise ValueError("give at least one model folder")
        return value

    @field_validator("api_keys_file", "key_state_dir", mode="before")
    @classmethod
    def _empty_is_unset(cls, value: object) -> object:
        # MOTION_API_KEYS_FILE= (as compose's ${VAR:-} writes it) means none, not "."
        return None if isinstance(value, str) and not value.strip() else value

    @property
    def oversubscribed(self) -> bool:
        """True when workers x intra-op threads exceed the cores this process may use."""
        return self.workers * self.intra_op_threads > available_cpus()

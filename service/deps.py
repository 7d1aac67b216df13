"""Typed dependencies for route handlers. Everything lives on ``app.state`` (set by the app
factory), so an app built with its own :class:`Settings` sees its own objects. Each is
``async``: FastAPI runs a plain function dependency in its thread pool, a thread hop per
dependency and request for an attribute read."""

from __future__ import annotations

from typing import Annotated

from fastapi import Depends, Request

from service.config import Settings
from service.dataplane import DataPlane
from service.inference import InferenceRunner
from service.registry import ModelRegistry


async def get_settings(request: Request) -> Settings:
    return request.app.state.settings


async def get_registry(request: Request) -> ModelRegistry:
    return request.app.state.registry


async def get_runner(request: Request) -> InferenceRunner:
    return request.app.state.runner


async def get_dataplane(request: Request) -> DataPlane:
    return request.app.state.dataplane


SettingsDep = Annotated[Settings, Depends(get_settings)]
RegistryDep = Annotated[ModelRegistry, Depends(get_registry)]
InferenceDep = Annotated[InferenceRunner, Depends(get_runner)]
DataPlaneDep = Annotated[DataPlane, Depends(get_dataplane)]

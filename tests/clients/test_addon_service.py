"""The Blender add-on's HTTP module (standard library only, so it runs without Blender)
against the real service: a transfer gives the BVH and the service's warnings, which the
add-on reports in Blender's status bar."""

from __future__ import annotations

import importlib.util

import pytest

from motion import bvh
from tests.rigs import bind_pose_first, load_fixture
from tests.server import REPO, ServerProcess

SERVICE = REPO / "clients" / "blender" / "motion_style" / "service.py"


@pytest.fixture(scope="module")
def addon_service():
    """The module loaded from its file: the package's ``__init__`` needs ``bpy``."""
    spec = importlib.util.spec_from_file_location("addon_service", SERVICE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    with ServerProcess(log_path=tmp_path_factory.mktemp("addon") / "server.log") as running:
        yield running


def test_a_transfer_brings_back_the_services_warnings(addon_service, server):
    """A walk whose first frame is the rig's bind pose: that frame comes back unrestyled,
    and the add-on hears why; the same walk without it comes back with no warning."""
    walk = load_fixture().slice(0, 60)
    bound = bind_pose_first(walk)
    answer = addon_service.transfer(server.url, bvh.dumps(bound).encode(), "proud", 1.0)
    assert bvh.loads(answer.bvh.decode()).num_frames > 1
    assert any("reference" in w for w in answer.warnings), answer.warnings
    plain = addon_service.transfer(server.url, bvh.dumps(walk).encode(), "proud", 1.0)
    assert plain.warnings == [] and bvh.loads(plain.bvh.decode()).num_frames > 1


def test_a_header_that_is_not_a_json_list_is_kept_whole(addon_service):
    assert addon_service.warnings_of(None) == []
    assert addon_service.warnings_of('["a, b", "c"]') == ["a, b", "c"]
    assert addon_service.warnings_of("plain text") == ["plain text"]
    assert addon_service.warnings_of('{"not": "a list"}') == ['{"not": "a list"}']
    assert addon_service.warnings_of("[]") == []

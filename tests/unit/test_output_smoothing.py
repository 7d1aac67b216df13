"""``model_export.output_smoothing``: the smallest smoothing whose output jerks no more than
real mocap, measured on the shipped engines and recorded in their entry."""

from __future__ import annotations

import shutil

import pytest

from model_export import output_smoothing as OS


def test_the_smallest_sigma_within_the_limit_is_chosen():
    assert OS.smallest_within({0.0: 1.36, 0.5: 1.19, 1.0: 0.92, 1.5: 0.78, 2.0: 0.70}) == 1.0
    assert OS.smallest_within({2.0: 0.7, 0.0: 0.99}) == 0.0  # in whatever order measured
    assert OS.smallest_within({0.0: 1.5, 1.0: 1.0}) == 1.0  # at the limit counts


def test_no_sigma_within_the_limit_is_an_error_that_gives_the_figures():
    with pytest.raises(ValueError, match=r"sigma 0: 1\.50, sigma 2: 1\.20"):
        OS.smallest_within({0.0: 1.5, 2.0: 1.2})


@pytest.mark.parametrize("family", ["translator", "fast"])
def test_the_shipped_smoothing_is_the_one_the_rule_gives(family, tmp_path):
    """Measured again on the shipped networks, the rule gives the sigma their entry holds,
    smoothing lowers the jerk, and the choice is written into the entry's copy."""
    from service.config import Settings
    from service.manifest import load_manifest
    from tests.conftest import data_path

    data_path("bandai")  # skips without the shared data
    models = tmp_path / "models"
    shutil.copytree(Settings().models_dir[0], models)
    entry = next(m for m in load_manifest(models).models if m.family == family)
    sigma = OS.choose(family, models)
    assert sigma == entry.extra["output_smoothing"]
    stored = next(m for m in load_manifest(models).models if m.family == family)
    jerk = stored.metrics["held_out_jerk"]
    assert jerk["0"] > jerk["2"]  # the smoothing takes jitter out
    assert stored.version == entry.version and stored.extra["output_smoothing"] == sigma

"""The compiled loops of motion/kernels.py, bvh_kernels.py and ik_kernels.py against the
numpy arithmetic they replaced."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from motion import ik, ik_kernels, kernels
from motion import rotations as rot

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("n", [0, 1, 7, 8, 9, 127, 128, 129, 130, 257, 1000, 5003])
def test_pairwise_sum_adds_as_numpy_does(n):
    values = np.random.default_rng(n).normal(size=n) * 123.4
    assert ik_kernels._pairwise_sum(values, 0, n) == np.sum(values)  # bit for bit


def test_long_contacts_run_in_a_process_that_loads_the_kernels_from_the_cache():
    """A contact over 128 frames takes the pairwise sum's halving path. Written as a
    function calling itself, numba's cached copy could not be called from code compiled
    afresh (an LLVM error ended the process): the knee poles' sums found it."""
    script = (
        "import numpy as np; from motion import ik, rotations as rot\n"
        "rng = np.random.default_rng(0)\n"
        "ankle = np.cumsum(rng.normal(size=(900, 3)), axis=0)\n"
        "contact = np.zeros(900, bool); contact[100:800] = True\n"
        "out = ik._pin_offsets(ankle, None, contact, None, 1.0, 1.0, 6)\n"
        "grot = rot.normalize(rng.normal(size=(900, 4)))\n"
        "poles = ik._knee_poles(grot, ankle, ankle + [0, -40, 5], ankle + [0, -80, 0], None,"
        " np.arange(900))\n"
        "assert np.isfinite(out).all() and np.isfinite(poles).all()\n"
    )
    for _ in range(2):  # the first may compile and write the cache, the second loads it
        done = subprocess.run([sys.executable, "-c", script], cwd=ROOT, capture_output=True)
        assert done.returncode == 0, done.stderr.decode()[-2000:]


def test_contact_offsets_hold_a_long_contact_still():
    rng = np.random.default_rng(1)
    ankle = np.cumsum(rng.normal(size=(600, 3)), axis=0)
    contact = np.zeros(600, bool)
    contact[50:450] = True
    offsets = ik._pin_offsets(ankle, None, contact, None, 2.0, 2.0, 6)
    held = ankle[50:450] + offsets[50:450]
    np.testing.assert_allclose(held - held[0], 0.0, atol=1e-9)  # one place all through
    np.testing.assert_allclose(held[:, 1], 2.0, atol=1e-9)  # on the ground level


def test_slerp_ends_equal_numpys_normalised_quaternions():
    rng = np.random.default_rng(2)
    lrot = rng.normal(size=(50, 6, 4))
    lrot[3, 2] = 0.0  # a zero quaternion reads as the identity
    first, second = rng.integers(0, 50, 40), rng.integers(0, 50, 40)
    a, b, d = kernels.slerp_ends(lrot, first, second)
    assert np.array_equal(a, rot.normalize(lrot[first]))
    assert np.array_equal(b, rot.normalize(lrot[second]))
    assert np.array_equal(d, np.einsum("...i,...i->...", a, b))


def test_unwrap_degrees_is_numpys_unwrap():
    rng = np.random.default_rng(3)
    angles = np.cumsum(rng.normal(0, 90, (300, 4, 3)), axis=0)
    angles = (angles + 180.0) % 360.0 - 180.0
    want = np.rad2deg(np.unwrap(np.deg2rad(angles), axis=0))
    assert np.array_equal(kernels.unwrap_degrees(angles), want)

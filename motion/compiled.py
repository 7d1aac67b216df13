"""Every loop the motion core compiles (:mod:`motion.kernels`, :mod:`motion.bvh_kernels`,
:mod:`motion.ik_kernels`), compiled before a request needs it.

Several processes must not compile into one cache at once (it can be left inconsistent,
and a process loading it then crashes): ``python -m service`` calls :func:`warm` before it
starts its workers.
"""

from __future__ import annotations

from motion import bvh_kernels, ik_kernels, kernels


def warm() -> None:
    """Compile (or load from the cache) every kernel for the types the motion core calls
    them with, so that no request pays for it."""
    kernels.warm()
    bvh_kernels.warm()
    ik_kernels.warm()

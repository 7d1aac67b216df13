"""The machine an evaluation runs on, recorded in its report."""

from __future__ import annotations

import os
from pathlib import Path


def measuring_machine() -> str:
    """The CPU and BLAS kernels an evaluation ran on, recorded with its figures: the same
    code trained classifiers on another CPU that judged one translator up to 0.8 points
    apart and the real targets' content 2.6 apart (OpenBLAS picks its kernels by CPU), so
    recorded figures compare only between models measured on one machine."""
    import platform

    from threadpoolctl import threadpool_info

    try:
        info = Path("/proc/cpuinfo").read_text().splitlines()
    except OSError:
        info = []
    names = [line.split(":", 1)[1].strip() for line in info if line.startswith("model name")]
    cpu = (names[0] if names else "") or platform.processor() or platform.machine()
    kernels = sorted(
        {
            f"{i['internal_api']} {i['architecture']}"
            for i in threadpool_info()
            if i.get("architecture")
        }
    )
    return f"{cpu}, {os.cpu_count()} cores; BLAS kernels: {', '.join(kernels) or 'unknown'}"

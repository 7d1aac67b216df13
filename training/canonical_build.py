"""Recompute the measured constants of ``motion/canonical.py`` from the Bandai data.

``python -m training.canonical_build`` prints (1) the median bone vectors of the
first frames of Bandai dataset-1 in the body frame (used for the short bones of
the canonical T-pose) and (2) Bandai's standing reference pose (mean local
rotations of upright first frames), which retargeting needs because Bandai's
rest pose lies flat along X. Numpy only; no torch needed.
"""

from __future__ import annotations

import argparse
import glob
import os

import numpy as np
from scipy.spatial.transform import Rotation

from motion import bvh, retarget
from motion import kinematics as K
from motion import rotations as R


def measure(data_dir: str, max_tilt_deg: float = 10.0) -> tuple[np.ndarray, np.ndarray, list[str]]:
    files = sorted(glob.glob(os.path.join(data_dir, "bandai", "dataset-1", "*.bvh")))
    if not files:
        raise SystemExit(f"no Bandai files under {data_dir}")
    vectors, poses = [], []
    names: list[str] = []
    for path in files:
        m = bvh.load(path)
        sk = m.skeleton
        names = list(sk.names)
        index = {n: i for i, n in enumerate(sk.names)}
        grot, gpos = K.fk(m.lrot[0], m.lpos[0], sk.parents)
        frame = retarget.body_frame(gpos, index)
        bones = np.array([gpos[j] - gpos[max(p, 0)] for j, p in enumerate(sk.parents)])
        vectors.append(bones @ frame)
        if np.degrees(np.arccos(np.clip(frame[1, 1], -1.0, 1.0))) > max_tilt_deg:
            continue
        lrot = m.lrot[0].copy()
        lrot[0] = R.IDENTITY
        lrot[1] = R.mul(R.from_matrix(frame.T), grot[1])  # hips facing +Z
        poses.append(lrot)
    poses_arr = np.array(poses)
    mean = np.stack(
        [Rotation.from_quat(poses_arr[:, j]).mean().as_quat() for j in range(poses_arr.shape[1])]
    )
    return np.median(np.array(vectors), axis=0), mean, names


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--data", default=os.environ.get("MOTION_DATA_DIR", "../shared/data"))
    args = parser.parse_args()
    bones, reference, names = measure(args.data)
    np.set_printoptions(precision=5, suppress=True)
    print("median bone vectors in the body frame (left, up, forward):")
    for n, v in zip(names, bones, strict=True):
        print(f"  {n:12s} {v}")
    print("BANDAI_REFERENCE_LROT =")
    print(repr(reference.round(5)))


if __name__ == "__main__":
    main()

"""Forward kinematics in torch, equal to ``motion.kinematics.fk`` (tests/unit/test_translator).

Rotations travel as 3x3 matrices (the decoder writes 6D, whose Gram-Schmidt gives a
matrix directly); quaternions are x, y, z, w as in ``motion.rotations``. Everything
broadcasts over leading dimensions and loops over joints, never frames.
"""

from __future__ import annotations

import numpy as np
import torch

from motion import canonical as C
from motion import features as Fe


def matrix_from_quat(q: torch.Tensor) -> torch.Tensor:
    """Rotation matrices ``(..., 3, 3)`` from unit quaternions ``(..., 4)`` (x, y, z, w)."""
    q = q / q.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    x, y, z, w = q.unbind(-1)
    rows = [
        1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w),
        2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w),
        2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y),
    ]  # fmt: skip
    return torch.stack(rows, dim=-1).reshape(q.shape[:-1] + (3, 3))


def matrix_from_6d(r6: torch.Tensor) -> torch.Tensor:
    """Matrices ``(..., 3, 3)`` from 6D ``(..., 6)`` by Gram-Schmidt, as
    ``motion.rotations.from_6d`` (columns: first vector, second made orthogonal, cross)."""
    a, b = r6[..., :3], r6[..., 3:]
    x = a / a.norm(dim=-1, keepdim=True).clamp_min(1e-8)
    b = b - (x * b).sum(dim=-1, keepdim=True) * x
    y = b / b.norm(dim=-1, keepdim=True).clamp_min(1e-8)
    z = torch.cross(x, y, dim=-1)
    return torch.stack([x, y, z], dim=-1)


def fk(
    lmat: torch.Tensor, lpos: torch.Tensor, parents: np.ndarray | list[int]
) -> tuple[torch.Tensor, torch.Tensor]:
    """Global matrices ``(..., J, 3, 3)`` and positions ``(..., J, 3)`` from local ones.

    ``lmat (..., J, 3, 3)``, ``lpos (..., J, 3)`` (the root's is its world position),
    ``parents (J,)`` parents first: the same maths as ``motion.kinematics.fk``.
    """
    gmat = [lmat[..., 0, :, :]]
    gpos = [lpos[..., 0, :]]
    for j in range(1, len(parents)):
        p = int(parents[j])
        gpos.append(torch.einsum("...ij,...j->...i", gmat[p], lpos[..., j, :]) + gpos[p])
        gmat.append(gmat[p] @ lmat[..., j, :, :])
    return torch.stack(gmat, dim=-3), torch.stack(gpos, dim=-2)


class RootLocalFK(torch.nn.Module):
    """Body positions in the facing frame relative to the root on the floor, in leg lengths:
    the 3D style encoding (``motion.features``) of decoded rotations.

    ``forward(rot6 (..., 21, 6), hips_height (...))`` -> ``(..., 21, 3)``; ``rot6`` are
    unstandardised output channels (Hips relative to the facing frame), ``hips_height`` in
    leg lengths (the content's root channel 0).
    """

    def __init__(self) -> None:
        super().__init__()
        self.register_buffer("offsets", torch.tensor(C.OFFSETS[Fe.BODY], dtype=torch.float32))
        # BODY joints renumbered from 0 (Hips): parents shift by one, Hips becomes the root.
        self.parents = [-1] + [int(p) - 1 for p in C.PARENTS[Fe.BODY[1:]]]

    def forward(self, rot6: torch.Tensor, hips_height: torch.Tensor) -> torch.Tensor:
        lmat = matrix_from_6d(rot6)
        lpos = self.offsets.expand(rot6.shape[:-1] + (3,)) / Fe.LEG
        zeros = torch.zeros_like(hips_height)
        root = torch.stack([zeros, hips_height, zeros], dim=-1)
        lpos = torch.cat([root.unsqueeze(-2), lpos[..., 1:, :]], dim=-2)
        return fk(lmat, lpos, self.parents)[1]

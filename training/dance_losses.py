"""The dance network's losses on standardised poses: features, forward-kinematics positions
(root-local, leg lengths), Laban effort and foot skating (``training.dance`` trains with them)."""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from motion import canonical as C
from motion import dance_features as DF
from training import fk as TFK


class Losses(nn.Module):
    """Feature, FK position, Laban effort and foot skating losses on standardised poses."""

    def __init__(self, stats: DF.DanceStats) -> None:
        super().__init__()
        self.register_buffer("mean", torch.from_numpy(stats.motion_mean))
        self.register_buffer("std", torch.from_numpy(stats.motion_std))
        self.register_buffer(
            "offsets", torch.tensor(C.OFFSETS[DF.BODY] / DF.LEG, dtype=torch.float32)
        )
        self.parents = [-1] + [int(p) - 1 for p in C.PARENTS[DF.BODY[1:]]]
        feet = [int(np.flatnonzero(DF.BODY == j)[0]) for j in DF.FOOT_JOINTS]
        self.feet = feet

    def raw(self, z: torch.Tensor) -> torch.Tensor:
        return z * self.std + self.mean

    def kinematics(self, raw: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Local matrices ``(..., 21, 3, 3)`` and root-local positions ``(..., 21, 3)``."""
        r6 = raw[..., DF.ROTATIONS].reshape(raw.shape[:-1] + (len(DF.BODY), 6))
        lmat = TFK.matrix_from_6d(r6)
        lpos = self.offsets.expand(raw.shape[:-1] + (len(DF.BODY), 3))
        h = raw[..., DF.HEIGHT]
        root = torch.stack([torch.zeros_like(h), h, torch.zeros_like(h)], dim=-1)
        lpos = torch.cat([root.unsqueeze(-2), lpos[..., 1:, :]], dim=-2)
        return lmat, TFK.fk(lmat, lpos, self.parents)[1]

    def forward(self, pred: torch.Tensor, target: torch.Tensor) -> dict[str, torch.Tensor]:
        """``pred``, ``target`` ``(B, T, M)`` standardised -> named scalar losses."""
        out = {"feat": ((pred - target) ** 2).mean()}
        rp, rt = self.raw(pred), self.raw(target)
        mp, pp = self.kinematics(rp)
        mt, pt = self.kinematics(rt)
        out["pos"] = ((pp - pt) ** 2).sum(-1).mean()
        # Laban effort: angular-velocity energy (frame-to-frame rotation change), per window
        ep = ((mp[:, 1:] - mp[:, :-1]) ** 2).sum((-1, -2)).mean((1, 2)) * DF.FPS**2
        et = ((mt[:, 1:] - mt[:, :-1]) ** 2).sum((-1, -2)).mean((1, 2)) * DF.FPS**2
        out["effort"] = (torch.log(ep + 1e-3) - torch.log(et + 1e-3)).abs().mean()
        # foot skating: world speed on the floor of the predicted feet where the target is planted
        fp = pp[..., self.feet, :]
        vel = (fp[:, 1:] - fp[:, :-1]) * DF.FPS
        root_v = rp[:, 1:, DF.VELOCITY]
        turn = rp[:, 1:, DF.TURN].unsqueeze(-1)
        vx = vel[..., 0] + root_v[..., 0:1] + turn * fp[:, 1:, :, 2]
        vz = vel[..., 2] + root_v[..., 1:2] - turn * fp[:, 1:, :, 0]
        planted = (rt[:, 1:, DF.CONTACTS] > 0.5).float()
        out["skate"] = (planted * (vx**2 + vz**2)).sum() / planted.sum().clamp_min(1.0)
        return out

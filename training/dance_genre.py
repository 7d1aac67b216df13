"""Genre the dance network cannot ignore: a judge of real dances and a per-genre prior.

Every training song is danced in one genre, so its music already says the genre and the
network learnt to read it there, not from the genre it is given: asked for a waltz on a
cha-cha it danced the cha-cha. The fine-tuning stage therefore asks, for a share of the
music windows, another music genre than the song's ("swapped" windows). Those windows run
free after their warm-up frames and have no ground truth; they are scored by

- a **judge**: logistic regression of the music genre on window statistics of the poses
  (mean and standard deviation over the window of the root-local joint positions and joint
  speeds, the root's speed, turning and the hips' height), fitted on windows of the real
  training dances; cross-entropy towards the asked genre;
- a **prior**: each statistic standardised by the asked genre's real windows must stay
  within ``PRIOR_BAND`` standard deviations of that genre's mean (squared excess), so the
  judge is not satisfied by poses no dancer of the genre takes.

Windows of the song's own genre keep the reconstruction losses and get the judge too.
"""

from __future__ import annotations

import torch
from torch import nn

from motion import dance_features as DF

PRIOR_BAND = 2.0
JUDGE_STEPS = 400


def window_statistics(pos: torch.Tensor, raw: torch.Tensor) -> torch.Tensor:
    """``(B, D)`` statistics of windows: root-local positions ``pos (B, T, J, 3)`` (leg
    lengths) and raw motion features ``raw (B, T, M)`` of the same frames."""
    b, t = pos.shape[:2]
    local = pos.reshape(b, t, -1)
    speed = (pos[:, 1:] - pos[:, :-1]).norm(dim=-1) * DF.FPS
    root = torch.cat(
        [raw[..., DF.VELOCITY], raw[..., DF.TURN : DF.TURN + 1].abs(),
         raw[..., DF.HEIGHT : DF.HEIGHT + 1]], dim=-1
    )  # fmt: skip
    parts = [local, speed, root]
    return torch.cat([p.mean(1) for p in parts] + [p.std(1) for p in parts], dim=-1)


class GenreJudge(nn.Module):
    """Standardised window statistics -> music-genre logits (a linear layer), with each
    genre's mean and standard deviation of the standardised statistics for the prior."""

    def __init__(self, dim: int) -> None:
        super().__init__()
        genres = len(DF.MUSIC_GENRES)
        self.register_buffer("mean", torch.zeros(dim))
        self.register_buffer("std", torch.ones(dim))
        self.register_buffer("genre_mean", torch.zeros(genres, dim))
        self.register_buffer("genre_std", torch.ones(genres, dim))
        self.linear = nn.Linear(dim, genres)

    def standardise(self, stats: torch.Tensor) -> torch.Tensor:
        return (stats - self.mean) / self.std

    def forward(self, stats: torch.Tensor) -> torch.Tensor:
        return self.linear(self.standardise(stats))

    def prior(self, stats: torch.Tensor, genre: torch.Tensor) -> torch.Tensor:
        """Mean squared excess of each standardised statistic beyond ``PRIOR_BAND`` of the
        asked ``genre (B,)``'s real windows."""
        z = (self.standardise(stats) - self.genre_mean[genre]) / self.genre_std[genre]
        return (torch.relu(z.abs() - PRIOR_BAND) ** 2).mean()

    def fit(self, stats: torch.Tensor, genre: torch.Tensor, steps: int = JUDGE_STEPS) -> float:
        """Fit on real windows ``stats (N, D)`` of ``genre (N,)``, classes weighted by their
        inverse frequency; returns the training accuracy. Frozen afterwards."""
        self.mean.copy_(stats.mean(0))
        self.std.copy_(stats.std(0).clamp_min(1e-4))
        z = self.standardise(stats)
        for g in range(len(DF.MUSIC_GENRES)):
            rows = z[genre == g]
            self.genre_mean[g] = rows.mean(0)
            self.genre_std[g] = rows.std(0).clamp_min(0.05)
        counts = torch.bincount(genre, minlength=len(DF.MUSIC_GENRES)).float().clamp_min(1)
        weight = counts.sum() / counts / len(counts)
        optimiser = torch.optim.Adam(self.linear.parameters(), lr=0.05, weight_decay=1e-3)
        for _ in range(steps):
            loss = nn.functional.cross_entropy(self.linear(z), genre, weight=weight)
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
        self.requires_grad_(False)
        with torch.no_grad():
            return float((self.linear(z).argmax(-1) == genre).float().mean())


def real_windows(sampler, losses, batches: int, size: int, skip: int):
    """Statistics ``(N, D)`` and genres ``(N,)`` of real music windows drawn by ``sampler``
    (a ``training.dance_data.WindowSampler``), their first ``skip + 1`` frames left out as the
    rollouts' warm-up is."""
    stats, genres = [], []
    with torch.no_grad():
        for _ in range(batches):
            _, motion, genre, music = sampler.batch(size, beat_dropout=0.0)
            raw = losses.raw(motion[music][:, skip + 1 :])
            stats.append(window_statistics(losses.kinematics(raw)[1], raw))
            genres.append(genre[music])
    return torch.cat(stats), torch.cat(genres)


def swap_genres(genre: torch.Tensor, music: torch.Tensor, share: float, rng) -> torch.Tensor:
    """``(B,)`` bool: music windows (with probability ``share``) whose genre is swapped, and
    ``genre`` changed in place to another music genre, uniformly, for them."""
    count = len(DF.MUSIC_GENRES)
    swapped = music & torch.from_numpy(rng.random(len(genre)) < share)
    shift = torch.from_numpy(rng.integers(1, count, len(genre)))
    genre[swapped] = (genre[swapped] + shift[swapped]) % count
    return swapped


def fit_judge(train_windows, held_windows, losses, skip: int) -> GenreJudge:
    """The judge fitted on windows of the real training dances drawn by ``train_windows``
    (a seeded ``training.dance_data.WindowSampler``), frozen; its accuracy on the windows of
    ``held_windows`` (the held-out songs) printed beside its training accuracy."""
    x, y = real_windows(train_windows, losses, 40, 32, skip)
    judge = GenreJudge(x.shape[1])
    accuracy = judge.fit(x, y)
    vx, vy = real_windows(held_windows, losses, 4, 32, skip)
    with torch.no_grad():
        held = float((judge(vx).argmax(-1) == vy).float().mean())
    print(
        f"genre judge: {len(y)} real windows, accuracy {accuracy:.3f} (held-out songs' {held:.3f})"
    )
    return judge

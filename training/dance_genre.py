"""Genre the dance network cannot ignore: a judge of real dances, a kinetic prior, a
diversity guard and feet that stand, for windows asked another genre.

Every training song is danced in one genre, so its music already says the genre and the
network learnt to read it there, not from the genre it is given: asked for a waltz on a
cha-cha it danced the cha-cha. The fine-tuning stage therefore asks, for a share of the
music windows, another music genre than the song's ("swapped" windows). Those windows run
free after their warm-up frames and have no ground truth; they are scored by

- a **judge**: a small convolutional network over time (dilated 1-D convolutions, mean
  pooling) of the per-frame root-local joint positions, joint velocities and root motion,
  fitted on windows of the real training dances and frozen; cross-entropy towards the asked
  genre, beyond a margin (a window named the asked genre with 80 % is left alone). ``training.eval_dance`` names genres with a linear model of window statistics (mean
  and deviation of positions and speeds): a judge of another family on other inputs, so
  that the evaluation stays evidence rather than the judge's own features learnt;
- a **kinetic prior**: the window's AIST++-style kinetic statistics (per joint, log mean
  squared horizontal and vertical speed and log mean acceleration), each standardised by
  the asked genre's real windows, must stay within ``PRIOR_BAND`` deviations of that
  genre's mean (squared excess), so the judge is not satisfied by motion no dancer of the
  genre makes, and each asked genre's mean of them over the batch must match the genre's
  real mean (``--w-match``: without it the fine-tuned dances moved half as much as real);
- a **diversity guard**: the swapped windows asked the same genre (different songs) must
  stay at least ``DIVERSITY_FLOOR`` of the real windows' mean pairwise distance apart in
  those kinetic statistics, so the genre is not learnt as one pattern for every song;
- **free skating**: with no ground-truth contacts, at every frame the stillest of the four
  foot points (heel and toe of each foot) is taken as standing, as ``motion.dance_feet``
  takes the slower foot; a window whose mean squared floor speed of it exceeds the asked
  genre's real windows' mean (at most the median genre's) is penalised by the excess (the captured dances' feet are
  never still: 0.46 leg lengths per second median, so a plain penalty would stiffen them).

Windows of the song's own genre keep the reconstruction losses and get the judge too.
"""

from __future__ import annotations

import torch
from torch import nn

from motion import dance_features as DF

PRIOR_BAND = 2.0
JUDGE_MARGIN = 0.22  # cross-entropy at which the judge stops pushing: -log(0.8)
DIVERSITY_FLOOR = 0.75
JUDGE_STEPS = 600
JUDGE_BATCH = 128
JUDGE_WIDTH = 48
KINETIC_EPS = 1e-3


def frame_inputs(pos: torch.Tensor, raw: torch.Tensor) -> torch.Tensor:
    """``(B, T - 1, C)`` per-frame judge inputs of root-local positions ``pos (B, T, J, 3)``
    (leg lengths) and raw motion features ``raw (B, T, M)``: positions, joint velocities,
    root velocity and turning."""
    b, t = pos.shape[:2]
    local = pos.reshape(b, t, -1)
    vel = (local[:, 1:] - local[:, :-1]) * DF.FPS
    root = torch.cat([raw[:, 1:, DF.VELOCITY], raw[:, 1:, DF.TURN : DF.TURN + 1]], dim=-1)
    return torch.cat([local[:, 1:], vel, root], dim=-1)


def kinetic_statistics(pos: torch.Tensor, raw: torch.Tensor) -> torch.Tensor:
    """``(B, 3J)`` per joint: log mean squared horizontal and vertical speed and log mean
    acceleration of a window (root-local positions plus the root's travel)."""
    vel = (pos[:, 1:] - pos[:, :-1]) * DF.FPS
    travel = raw[:, 1:, DF.VELOCITY]  # facing frame x, z
    vx = vel[..., 0] + travel[..., 0:1]
    vz = vel[..., 2] + travel[..., 1:2]
    horizontal = (vx**2 + vz**2).mean(1)
    vertical = (vel[..., 1] ** 2).mean(1)
    acc = ((vel[:, 1:] - vel[:, :-1]) * DF.FPS).norm(dim=-1).mean(1)
    return torch.log(torch.cat([horizontal, vertical, acc], dim=-1) + KINETIC_EPS)


def free_skating(pos: torch.Tensor, raw: torch.Tensor, feet: list[int]) -> torch.Tensor:
    """``(B,)`` per window, the mean over frames of the squared floor speed (leg lengths per
    second) of the stillest foot point: a dancer always stands somewhere."""
    fp = pos[:, :, feet]
    vel = (fp[:, 1:] - fp[:, :-1]) * DF.FPS
    root_v = raw[:, 1:, DF.VELOCITY]
    turn = raw[:, 1:, DF.TURN].unsqueeze(-1)
    vx = vel[..., 0] + root_v[..., 0:1] + turn * fp[:, 1:, :, 2]
    vz = vel[..., 2] + root_v[..., 1:2] - turn * fp[:, 1:, :, 0]
    return (vx**2 + vz**2).min(dim=-1).values.mean(1)


class ConvJudge(nn.Module):
    """Per-frame inputs ``(B, T, C)`` -> music-genre logits: standardised, three dilated
    1-D convolutions with ReLU, mean over time, a linear layer. Also holds the kinetic
    statistics' standardisation and each genre's mean, deviation and mean pairwise distance
    of them (for the prior and the diversity guard)."""

    def __init__(self, channels: int, kinetic: int, width: int = JUDGE_WIDTH) -> None:
        super().__init__()
        genres = len(DF.MUSIC_GENRES)
        self.register_buffer("mean", torch.zeros(channels))
        self.register_buffer("std", torch.ones(channels))
        self.register_buffer("kin_mean", torch.zeros(kinetic))
        self.register_buffer("kin_std", torch.ones(kinetic))
        self.register_buffer("genre_mean", torch.zeros(genres, kinetic))
        self.register_buffer("genre_std", torch.ones(genres, kinetic))
        self.register_buffer("genre_spread", torch.ones(genres))
        self.register_buffer("genre_skate", torch.zeros(genres))
        self.body = nn.Sequential(
            nn.Conv1d(channels, width, 5, padding=2),
            nn.ReLU(),
            nn.Dropout(0.2),
            nn.Conv1d(width, width, 5, padding=4, dilation=2),
            nn.ReLU(),
            nn.Dropout(0.2),
            nn.Conv1d(width, width, 5, padding=8, dilation=4),
            nn.ReLU(),
        )
        self.head = nn.Linear(width, genres)

    def forward(self, frames: torch.Tensor) -> torch.Tensor:
        x = ((frames - self.mean) / self.std).transpose(1, 2)
        return self.head(self.body(x).mean(-1))

    def kinetic_z(self, kinetic: torch.Tensor) -> torch.Tensor:
        return (kinetic - self.kin_mean) / self.kin_std

    def prior(self, kinetic: torch.Tensor, genre: torch.Tensor) -> torch.Tensor:
        """Mean squared excess of each standardised kinetic statistic beyond ``PRIOR_BAND``
        deviations of the asked ``genre (B,)``'s real windows."""
        z = (self.kinetic_z(kinetic) - self.genre_mean[genre]) / self.genre_std[genre]
        return (torch.relu(z.abs() - PRIOR_BAND) ** 2).mean()

    def skating(self, skate: torch.Tensor, genre: torch.Tensor) -> torch.Tensor:
        """Mean excess of each window's free skating ``skate (B,)`` over the asked ``genre
        (B,)``'s real windows' mean."""
        return torch.relu(skate - self.genre_skate[genre]).mean()

    def judged(self, logits: torch.Tensor, genre: torch.Tensor) -> torch.Tensor:
        """Cross-entropy towards the asked ``genre (B,)`` beyond ``JUDGE_MARGIN`` per window:
        a window the judge already names so is left alone instead of made ever more so."""
        ce = nn.functional.cross_entropy(logits, genre, reduction="none")
        return torch.relu(ce - JUDGE_MARGIN).mean()

    def match(self, kinetic: torch.Tensor, genre: torch.Tensor) -> torch.Tensor:
        """Mean squared gap between each asked genre's mean standardised kinetic statistics
        (over the windows asked it) and its real windows' mean: the band of :meth:`prior`
        lets every joint move half as much as the genre's dancers, this does not."""
        z = self.kinetic_z(kinetic)
        gaps = [((z[genre == g].mean(0) - self.genre_mean[g]) ** 2).mean() for g in genre.unique()]
        return torch.stack(gaps).mean()

    def diversity(self, kinetic: torch.Tensor, genre: torch.Tensor) -> torch.Tensor:
        """Squared shortfall of each asked genre's mean pairwise distance (standardised
        kinetic statistics) below ``DIVERSITY_FLOOR`` of its real windows', relative,
        averaged over the genres asked of at least two windows."""
        z = self.kinetic_z(kinetic)
        out = []
        for g in genre.unique():
            rows = z[genre == g]
            if len(rows) < 2:
                continue
            d = torch.pdist(rows).mean()
            floor = DIVERSITY_FLOOR * self.genre_spread[g]
            out.append((torch.relu(floor - d) / floor) ** 2)
        return torch.stack(out).mean() if out else kinetic.new_zeros(())

    def fit(
        self,
        frames: torch.Tensor,
        kinetic: torch.Tensor,
        skate: torch.Tensor,
        genre: torch.Tensor,
        steps: int = JUDGE_STEPS,
        seed: int = 0,
    ) -> float:
        """Fit on real windows ``frames (N, T, C)``, ``kinetic (N, K)``, free skating
        ``skate (N,)`` of ``genre (N,)``,
        classes weighted by their inverse frequency; returns the training accuracy (eval
        mode). Frozen afterwards."""
        self.mean.copy_(frames.mean((0, 1)))
        self.std.copy_(frames.std((0, 1)).clamp_min(1e-4))
        self.kin_mean.copy_(kinetic.mean(0))
        self.kin_std.copy_(kinetic.std(0).clamp_min(1e-4))
        z = self.kinetic_z(kinetic)
        for g in range(len(DF.MUSIC_GENRES)):
            rows = z[genre == g]
            self.genre_mean[g] = rows.mean(0)
            self.genre_std[g] = rows.std(0).clamp_min(0.05)
            self.genre_spread[g] = torch.pdist(rows).mean() if len(rows) > 1 else 1.0
            self.genre_skate[g] = skate[genre == g].mean()
        # one travelling tango song glides far more than every other genre: no genre is
        # allowed more than the median genre's skating
        self.genre_skate.clamp_(max=float(self.genre_skate.median()))
        counts = torch.bincount(genre, minlength=len(DF.MUSIC_GENRES)).float().clamp_min(1)
        weight = counts.sum() / counts / len(counts)
        params = list(self.body.parameters()) + list(self.head.parameters())
        optimiser = torch.optim.AdamW(params, lr=3e-3, weight_decay=1e-2)
        gen = torch.Generator().manual_seed(seed)
        self.train()
        for _ in range(steps):
            rows = torch.randint(0, len(genre), (min(JUDGE_BATCH, len(genre)),), generator=gen)
            loss = nn.functional.cross_entropy(self(frames[rows]), genre[rows], weight=weight)
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
        self.eval()
        self.requires_grad_(False)
        return self.accuracy(frames, genre)

    @torch.no_grad()
    def accuracy(self, frames: torch.Tensor, genre: torch.Tensor) -> float:
        named = torch.cat([self(frames[i : i + 512]).argmax(-1) for i in range(0, len(genre), 512)])
        return float((named == genre).float().mean())


def window_inputs(losses, z: torch.Tensor) -> tuple[torch.Tensor, ...]:
    """Judge frames, kinetic statistics, root-local positions and raw features of
    standardised poses ``z (B, T, M)`` (``losses``: a ``training.dance_losses.Losses``)."""
    raw = losses.raw(z)
    pos = losses.kinematics(raw)[1]
    return frame_inputs(pos, raw), kinetic_statistics(pos, raw), pos, raw


def real_windows(sampler, losses, batches: int, size: int, skip: int):
    """Judge frames ``(N, T, C)``, kinetic statistics ``(N, K)``, free skating ``(N,)`` and
    genres ``(N,)`` of real music windows drawn by ``sampler`` (a ``training.dance_data.WindowSampler``), their first
    ``skip + 1`` frames left out as the rollouts' warm-up is."""
    frames, kinetic, skate, genres = [], [], [], []
    with torch.no_grad():
        for _ in range(batches):
            _, motion, genre, music = sampler.batch(size, beat_dropout=0.0)
            f, k, pos, raw = window_inputs(losses, motion[music][:, skip + 1 :])
            frames.append(f)
            kinetic.append(k)
            skate.append(free_skating(pos, raw, losses.feet))
            genres.append(genre[music])
    return torch.cat(frames), torch.cat(kinetic), torch.cat(skate), torch.cat(genres)


def swap_genres(genre: torch.Tensor, music: torch.Tensor, share: float, rng) -> torch.Tensor:
    """``(B,)`` bool: music windows (with probability ``share``) whose genre is swapped, and
    ``genre`` changed in place to another music genre, uniformly, for them."""
    count = len(DF.MUSIC_GENRES)
    swapped = music & torch.from_numpy(rng.random(len(genre)) < share).to(music.device)
    shift = torch.from_numpy(rng.integers(1, count, len(genre))).to(genre.device)
    genre[swapped] = (genre[swapped] + shift[swapped]) % count
    return swapped


def fit_judge(
    train_windows, held_windows, losses, skip: int, batches: int = 60, steps: int = JUDGE_STEPS
) -> ConvJudge:
    """The judge fitted on windows of the real training dances drawn by ``train_windows``
    (a seeded ``training.dance_data.WindowSampler``), frozen; its accuracy on the windows of
    ``held_windows`` (the held-out songs) printed beside its training accuracy."""
    x, k, s, y = real_windows(train_windows, losses, batches, 32, skip)
    judge = ConvJudge(x.shape[-1], k.shape[-1])
    accuracy = judge.fit(x, k, s, y, steps)
    vx, _, _, vy = real_windows(held_windows, losses, 4, 32, skip)
    print(
        f"genre judge: {len(y)} real windows, accuracy {accuracy:.3f} "
        f"(held-out songs' {judge.accuracy(vx, vy):.3f})"
    )
    return judge

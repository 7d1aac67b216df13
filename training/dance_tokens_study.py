"""Study 9a / 9b (issue 67, rules 17 and 18 in docs/dance_alignment.md): a dance made of
sampled real phrases. A VQ-VAE learns a codebook of a fold's training dances (a
choreographic memory, as Bailando's); a per-genre order-2 Markov chain over the tokens of
that genre's training dances samples a token sequence, decoded in one pass, in place of
the LSTM's rollout; everything after the rollout is the shipped engine's. Not shipped:
both variants failed; committed so the study replays, and taken out in the next commit.

    python -m training.dance_tokens_study train FOLD OUT.pt [--smooth 1.0]   # 12 min
    python -m training.dance_tokens_study judge OUTDIR PREFIX   # PREFIX{0,1}.pt, the judge set
    python -m training.dance_tokens_study recon PREFIX          # the codec on held-out dances
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from motion import dance_features as DF
from training.dance import FOLDS
from training.dance_data import prepare

REPO = Path(__file__).resolve().parent.parent
STATS = {0: "models/dance/stats.npz", 1: "runs/eval/models-fold1/dance/stats.npz"}
CODES, DIM, WIDTH, WINDOW, DOWN, ORDER = 256, 64, 256, 64, 4, 2


def fold_stats(fold: int) -> DF.DanceStats:
    """The shipped fold model's statistics (``make eval-dance`` exports fold 1's)."""
    return DF.DanceStats.from_arrays(np.load(REPO / STATS[fold]))


def fold_dances(fold: int) -> list[tuple[str, int, np.ndarray]]:
    stats = fold_stats(fold)
    seqs = [s for s in prepare(log=lambda *a: None) if s.has_music and s.name not in FOLDS[fold]]
    return [(s.name, s.genre, stats.normalize_motion(s.motion).astype(np.float32)) for s in seqs]


class Res(nn.Module):
    def __init__(self, c: int) -> None:
        super().__init__()
        self.a, self.b = nn.Conv1d(c, c, 3, padding=1), nn.Conv1d(c, c, 1)

    def forward(self, x):
        return x + self.b(F.relu(self.a(F.relu(x))))


class VQ(nn.Module):
    """Conv encoder (time / 4), EMA codebook with dead codes restarted, conv decoder."""

    def __init__(self) -> None:
        super().__init__()
        C, W = DF.MOTION_CHANNELS, WIDTH
        self.enc = nn.Sequential(
            nn.Conv1d(C, W, 3, padding=1),
            nn.ReLU(),
            nn.Conv1d(W, W, 4, 2, 1),
            Res(W),
            nn.Conv1d(W, W, 4, 2, 1),
            Res(W),
            nn.ReLU(),
            nn.Conv1d(W, DIM, 3, padding=1),
        )
        self.dec = nn.Sequential(
            nn.Conv1d(DIM, W, 3, padding=1),
            Res(W),
            nn.Upsample(scale_factor=2),
            nn.Conv1d(W, W, 3, padding=1),
            Res(W),
            nn.Upsample(scale_factor=2),
            nn.Conv1d(W, W, 3, padding=1),
            nn.ReLU(),
            nn.Conv1d(W, C, 3, padding=1),
        )
        self.register_buffer("book", torch.randn(CODES, DIM) * 0.1)
        self.register_buffer("ema_n", torch.ones(CODES))
        self.register_buffer("ema_w", self.book.clone())

    def tokens(self, z):  # (B, D, T) -> (B, T)
        flat = z.permute(0, 2, 1).reshape(-1, DIM)
        d = (flat**2).sum(1, keepdim=True) - 2 * flat @ self.book.T + (self.book**2).sum(1)[None]
        return d.argmin(1).view(z.shape[0], z.shape[2])

    def decode(self, tok):  # (B, T) -> (B, 4T, C)
        return self.dec(self.book[tok].permute(0, 2, 1)).permute(0, 2, 1)

    def forward(self, x, train: bool = True):  # x (B, T, C)
        z = self.enc(x.permute(0, 2, 1))
        tok = self.tokens(z)
        q = self.book[tok].permute(0, 2, 1)
        if train:
            flat = z.permute(0, 2, 1).reshape(-1, DIM).detach()
            onehot = F.one_hot(tok.reshape(-1), CODES).float()
            self.ema_n.mul_(0.99).add_(onehot.sum(0), alpha=0.01)
            self.ema_w.mul_(0.99).add_(onehot.T @ flat, alpha=0.01)
            n = (self.ema_n + 1e-5) / (self.ema_n.sum() + CODES * 1e-5) * self.ema_n.sum()
            self.book.copy_(self.ema_w / n[:, None])
            dead = self.ema_n < 0.03
            if dead.any():
                pick = flat[torch.randint(len(flat), (int(dead.sum()),))]
                self.book[dead], self.ema_w[dead], self.ema_n[dead] = pick, pick, 1.0
        commit = F.mse_loss(z, q.detach())
        out = self.dec(z + (q - z).detach()).permute(0, 2, 1)
        return out, commit, tok


def train(fold: int, out: Path, steps: int = 6000, smooth: float = 0.0) -> None:
    """Rule 17's codec (``smooth`` 0), rule 18's (``smooth`` 1: velocity and acceleration
    losses); batch 32, seed 0, one thread."""
    torch.manual_seed(0)
    torch.set_num_threads(1)
    rng = np.random.default_rng(0)
    dances = fold_dances(fold)
    w = np.array([len(m) - WINDOW for _, _, m in dances], float)
    w /= w.sum()
    model = VQ()
    opt = torch.optim.Adam(model.parameters(), 3e-4)
    t0 = time.time()
    for step in range(1, steps + 1):
        batch = []
        for i in rng.choice(len(dances), 32, p=w):
            m = dances[i][2]
            t = rng.integers(0, len(m) - WINDOW)
            batch.append(m[t : t + WINDOW])
        x = torch.from_numpy(np.stack(batch))
        y, commit, tok = model(x)
        rec = F.mse_loss(y, x)
        loss = rec + 0.25 * commit
        if smooth:
            dy, dx = y.diff(dim=1), x.diff(dim=1)
            loss = loss + smooth * (F.mse_loss(dy, dx) + F.mse_loss(dy.diff(dim=1), dx.diff(dim=1)))
        opt.zero_grad()
        loss.backward()
        opt.step()
        if step % 200 == 0:
            print(f"step {step} rec {rec.item():.4f} commit {commit.item():.4f} "
                  f"used {len(torch.unique(tok))} {(time.time() - t0) / step * 1e3:.0f} ms/step",
                  flush=True)  # fmt: skip
        if step % 1000 == 0 or step == steps:
            torch.save({"model": model.state_dict(), "fold": fold, "step": step}, out)


def load_vq(path: Path) -> VQ:
    model = VQ()
    model.load_state_dict(torch.load(path)["model"])
    return model.eval()


class Sampler:
    """Per genre, an order-2 Markov chain over the tokens of that genre's training dances
    (back-off to order 1, then to the genre's unigram)."""

    def __init__(self, fold: int, prefix: str) -> None:
        self.model = load_vq(Path(f"{prefix}{fold}.pt"))
        self.seqs: dict[int, list[np.ndarray]] = {}
        with torch.no_grad():
            for _, genre, m in fold_dances(fold):
                z = self.model.enc(torch.from_numpy(m[: len(m) // DOWN * DOWN]).T[None])
                self.seqs.setdefault(genre, []).append(self.model.tokens(z)[0].numpy())
        self.tables = {}
        for g, seqs in self.seqs.items():
            table: dict[int, dict[tuple, list[int]]] = {k: {} for k in range(ORDER + 1)}
            for s in seqs:
                for i in range(len(s)):
                    for k in range(min(i, ORDER) + 1):
                        table[k].setdefault(tuple(s[i - k : i]), []).append(int(s[i]))
            self.tables[g] = table

    def poses(self, genre: int, frames: int, rng: np.random.Generator) -> np.ndarray:
        seqs, table = self.seqs[genre], self.tables[genre]
        s = seqs[rng.integers(len(seqs))]
        i = int(rng.integers(0, len(s) - ORDER))
        out = [int(x) for x in s[i : i + ORDER]]
        while len(out) < -(-frames // DOWN):
            for k in range(ORDER, -1, -1):
                nxt = table[k].get(tuple(out[len(out) - k :]) if k else ())
                if nxt:
                    out.append(nxt[rng.integers(len(nxt))])
                    break
        with torch.no_grad():
            x = self.model.decode(torch.tensor(out[: -(-frames // DOWN)])[None])[0].numpy()
        return x[:frames].astype(np.float32)


def judge(out: Path, prefix: str) -> None:
    """``make judge-dance``'s set on the shipped fold models, the rollout replaced."""
    import service.engines.dance as E
    from training import eval_dance as ED

    samplers: dict[int, Sampler] = {}

    def rollout(self, code, genre, start, seed):
        fold = 1 if "fold1" in self.entry.name else 0
        if fold not in samplers:
            samplers[fold] = Sampler(fold, prefix)
        rng = np.random.default_rng(seed)
        return samplers[fold].poses(int(np.argmax(genre)), len(code), rng)

    torch.set_num_threads(1)
    E.DanceEngine.rollout = rollout
    ED.main(["--held-out-only", "--whole-songs", "--seeds", "12", "--fold-models",
             "runs/eval/models-fold1", "--json", str(out / "judged.json")])  # fmt: skip


def recon(prefix: str) -> None:
    """Distance ratios of the held-out real dances through the engine's pipeline after the
    rollout, as they are and through the codec."""
    from motion import dance_feet
    from training import dance_metrics as DM
    from training import eval_dance as ED

    for fold in (0, 1):
        stats, model = fold_stats(fold), load_vq(Path(f"{prefix}{fold}.pt"))
        held, train_set = ED.held_out_songs(FOLDS[fold], audio=False)
        for kind in ("pipeline", "codec"):
            made = {}
            for name, _, real, _, _ in held:
                x = stats.normalize_motion(DF.encode(real).features)
                if kind == "codec":
                    with torch.no_grad():
                        x = model(torch.from_numpy(x[: len(x) // DOWN * DOWN])[None], False)[0]
                    x = x[0].numpy()
                raw, motion = DF.keep_moving(DF.smooth_features(stats.denormalize_motion(x)))
                made[name] = [dance_feet.clean_feet(motion, raw[:, DF.CONTACTS] > 0.5)]
            fd = DM.feature_distances(held, train_set, made)
            ratios = {h: {g: (round(fd[h][g]["kinetic"]["ratio"], 2),
                              round(fd[h][g]["geometric"]["ratio"], 2))
                          for g in fd[h] if g not in ("all", "segment_seconds")}
                      for h in ("dev", "test")}  # fmt: skip
            print(fold, kind, ratios, flush=True)


def main() -> None:
    p = argparse.ArgumentParser()
    sub = p.add_subparsers(dest="cmd", required=True)
    t = sub.add_parser("train")
    t.add_argument("fold", type=int)
    t.add_argument("out", type=Path)
    t.add_argument("--steps", type=int, default=6000)
    t.add_argument("--smooth", type=float, default=0.0)
    j = sub.add_parser("judge")
    j.add_argument("out", type=Path)
    j.add_argument("prefix")
    r = sub.add_parser("recon")
    r.add_argument("prefix")
    a = p.parse_args()
    if a.cmd == "train":
        train(a.fold, a.out, a.steps, a.smooth)
    elif a.cmd == "judge":
        judge(a.out, a.prefix)
    else:
        recon(a.prefix)


if __name__ == "__main__":
    main()

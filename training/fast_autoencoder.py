"""Train the fast style networks' loss network: a 1D convolutional autoencoder over time
(holden2017 section 3.2) on every canonical clip of the shared data.

    python -m training.fast_autoencoder [--steps N] [--stop-after N] [--max-steps N]

Writes ``checkpoints/fast/stats.npz`` (feature statistics of the training split),
``checkpoints/fast/split.json`` (held-out Bandai takes) and
``checkpoints/fast/autoencoder.pt`` (weights, config, final losses; overwritten at each
checkpoint); logs to ``runs/fast/autoencoder``. ``MOTION_SMOKE=1`` runs a few steps.
"""

from __future__ import annotations

import argparse
import datetime as dt
import time

import numpy as np
import torch
from tqdm import tqdm

from motion import fast_features as FF
from training import fast_common as FC


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--steps", type=int, default=6000)
    p.add_argument("--max-steps", type=int, default=None, help="stop after this many (smoke)")
    p.add_argument(
        "--stop-after", type=int, default=None,
        help="end at this step of the --steps schedule (the committed autoencoder: 1,606 of 3,600)",
    )  # fmt: skip
    p.add_argument("--batch", type=int, default=32)
    p.add_argument("--window", type=int, default=FC.WINDOW)
    p.add_argument("--hidden", type=int, default=FC.HIDDEN)
    p.add_argument("--lr", type=float, default=1e-3)
    p.add_argument("--sparsity", type=float, default=1e-4, help="alpha of the L1 term (eq. 3)")
    p.add_argument("--val-every", type=int, default=250)
    p.add_argument("--checkpoint-dir", default=str(FC.CHECKPOINTS))
    p.add_argument("--log-dir", default=str(FC.RUNS), help="TensorBoard and text logs")
    p.add_argument("--log-name", default="autoencoder")
    p.add_argument("--threads", type=int, default=None)
    p.add_argument("--seed", type=int, default=0)
    return p.parse_args(argv)


def main(argv: list[str] | None = None) -> dict:
    args = parse_args(argv)
    if FC.smoke():
        args.max_steps = args.max_steps or 3
    if args.threads:
        torch.set_num_threads(args.threads)
    torch.manual_seed(args.seed)
    rng = np.random.default_rng(args.seed)
    out_dir = FC.Path(args.checkpoint_dir)
    out_dir.mkdir(parents=True, exist_ok=True)

    bandai, others = FC.load_encoded()
    train_b, val_b = FC.split(bandai)
    FC.save_split(val_b, out_dir / "split.json")
    train = train_b + others
    stats = FF.FastStats.fit([c.features for c in train])
    stats.save(out_dir / "stats.npz")
    val_x = torch.tensor(
        stats.normalize(FC.sample_windows(val_b, 64, args.window, np.random.default_rng(123)))
    )

    model = FC.Autoencoder(hidden=args.hidden)
    opt = torch.optim.Adam(model.parameters(), lr=args.lr)
    steps = min(args.steps, args.max_steps or args.steps)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, steps, eta_min=args.lr * 0.05)
    log = FC.Logger(args.log_name, FC.Path(args.log_dir))
    weights = [model.conv.weight, model.deconv.weight]
    started = time.time()
    result: dict = {}

    def validate() -> float:
        model.eval()
        with torch.no_grad():
            loss = torch.mean((model(val_x) - val_x) ** 2).item()
        model.train()
        return loss

    def save(step: int, train_loss: float, val_loss: float) -> None:
        result.update(
            step=step,
            train_mse=train_loss,
            val_mse=val_loss,
            minutes=(time.time() - started) / 60,
            trained_at=dt.date.today().isoformat(),
        )
        torch.save(
            {
                "model": model.state_dict(),
                "config": {"hidden": args.hidden, "width": FC.WIDTH, "window": args.window},
                "args": vars(args),
                "result": result,
                "data": {"bandai_train": len(train_b), "bandai_val": len(val_b),
                         "others": len(others), "frames": sum(len(c.features) for c in train)},
            },
            out_dir / "autoencoder.pt",
        )  # fmt: skip

    bar = tqdm(range(1, steps + 1), desc="autoencoder", mininterval=5)
    mse_avg = None
    for step in bar:
        x = torch.tensor(stats.normalize(FC.sample_windows(train, args.batch, args.window, rng)))
        y = model(x)
        mse = torch.mean((y - x) ** 2)
        l1 = sum(w.abs().mean() for w in weights)
        loss = mse + args.sparsity * l1
        opt.zero_grad()
        loss.backward()
        opt.step()
        sched.step()
        mse_avg = mse.item() if mse_avg is None else 0.98 * mse_avg + 0.02 * mse.item()
        if step % 25 == 0:
            rate = step / (time.time() - started)
            bar.set_postfix(mse=f"{mse_avg:.4f}", it_s=f"{rate:.2f}")
            log.scalars(step, {"train/mse": mse.item(), "train/l1": l1.item(), "it_per_s": rate})
        stop = step == args.stop_after
        if step % args.val_every == 0 or step == steps or stop:
            val = validate()
            log.scalars(step, {"val/mse": val})
            save(step, mse_avg, val)
        if stop:
            break
    log.close()
    print(f"autoencoder: {result}")
    return result


if __name__ == "__main__":
    main()

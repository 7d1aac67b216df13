"""Training on several processes with PyTorch's own engine, ``torch.distributed`` as
``torchrun`` starts it: gloo on CPUs, NCCL on GPUs.

    torchrun --nproc_per_node 2 -m training.translator.fit --library LIB ...

Every process holds the same data and the same weights (broadcast from the first) and
draws its own batches; after each backward pass the gradients are averaged over the
processes in one collective, as ``DistributedDataParallel`` does (the trainer calls its
networks' parts one by one, which DDP's wrapper would not follow), so N processes train
as one with N times the batch. The first process alone logs and writes checkpoints.
Without ``torchrun`` (``WORLD_SIZE`` unset) everything here does nothing.
"""

from __future__ import annotations

import os

import torch
import torch.distributed as dist


def world() -> int:
    return dist.get_world_size() if dist.is_initialized() else 1


def rank() -> int:
    return dist.get_rank() if dist.is_initialized() else 0


def started() -> bool:
    return dist.is_initialized()


def start(device: str) -> str:
    """Joins the process group ``torchrun`` describes (if any); the device this process
    trains on (``cuda:<LOCAL_RANK>`` for CUDA)."""
    if int(os.environ.get("WORLD_SIZE", "1")) <= 1:
        return device
    cuda = device.startswith("cuda")
    if cuda:
        device = f"cuda:{int(os.environ.get('LOCAL_RANK', '0'))}"
        torch.cuda.set_device(device)
    if not dist.is_initialized():
        dist.init_process_group("nccl" if cuda else "gloo")
    return device


def stop() -> None:
    if dist.is_initialized():
        dist.destroy_process_group()


def barrier() -> None:
    if dist.is_initialized():
        dist.barrier()


def broadcast_parameters(module: torch.nn.Module) -> None:
    """The first process's weights everywhere."""
    if world() > 1:
        for p in module.parameters():
            dist.broadcast(p.data, 0)


def average_gradients(parameters) -> None:
    """Every process's gradients replaced by their mean, in one flat all-reduce."""
    if world() == 1:
        return
    grads = [p.grad for p in parameters if p.grad is not None]
    if not grads:
        return
    flat = torch.cat([g.reshape(-1) for g in grads])
    dist.all_reduce(flat)
    flat /= world()
    offset = 0
    for g in grads:
        g.copy_(flat[offset : offset + g.numel()].view_as(g))
        offset += g.numel()


def _device() -> torch.device:
    """Where collectives' own tensors live: NCCL moves CUDA tensors only."""
    if dist.get_backend() == "nccl":
        return torch.device("cuda", torch.cuda.current_device())
    return torch.device("cpu")


def agree(flag: bool) -> bool:
    """The first process's ``flag`` in every process (decisions taken by the clock, such
    as when to save, must be taken together)."""
    if world() == 1:
        return bool(flag)
    t = torch.tensor([1 if flag else 0], device=_device())
    dist.broadcast(t, 0)
    return bool(t.item())


def gather(obj) -> list:
    """``obj`` of every process, in rank order (``[obj]`` alone)."""
    if world() == 1:
        return [obj]
    out = [None] * world()
    dist.all_gather_object(out, obj)
    return out


def spread(module: torch.nn.Module) -> float:
    """The largest difference of a weight between processes (0 when they agree)."""
    if world() == 1:
        return 0.0
    flat = torch.cat([p.detach().reshape(-1).double() for p in module.parameters()])
    high, low = flat.clone(), flat.clone()
    dist.all_reduce(high, op=dist.ReduceOp.MAX)
    dist.all_reduce(low, op=dist.ReduceOp.MIN)
    return float((high - low).abs().max())

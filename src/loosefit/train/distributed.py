"""Training on several processes and machines with PyTorch DistributedDataParallel (DDP).

Two ways to start the processes, both ending in the same :func:`loosefit.train.trainer.train`:

- ``loosefit train ... --nproc N`` (:func:`launch`) spawns N processes on this machine with
  ``torch.multiprocessing`` and a free localhost port;
- ``torchrun`` (one line per machine, see the README) sets ``RANK``, ``LOCAL_RANK``, ``WORLD_SIZE``,
  ``MASTER_ADDR`` and ``MASTER_PORT``; ``loosefit train`` run under it needs no ``--nproc``.

Either way the environment carries the rank, and :func:`setup` (called by the trainer) joins the
process group with the ``env://`` rendezvous: ``gloo`` on the CPU, ``nccl`` on CUDA (one GPU per
process, ``cuda:LOCAL_RANK``).

Semantics, so that N processes train the same model as one process with the same config:

- ``batch_size`` is the *global* batch: each process takes ``batch_size / N`` samples a step (it must
  divide), DDP averages the gradients, so a step sees the same mean loss gradient as one process. A
  model whose loss is a mean over a varying count (masked frames) declares it with ``loss_weight``
  and each process's loss is scaled by its share (:func:`weight_share`).
- :class:`ShardedSampler` shards the single-process shuffle: the permutation is drawn from the
  same per-epoch generator as one process draws it, and rank ``r`` takes every N-th index from ``r``
  (:class:`torch.utils.data.DistributedSampler`'s sharding), so the union of the ranks' k-th
  batches is one process's k-th batch. When the training set is not a multiple of the global batch
  the last batch differs (the sampler pads by repeating samples, as DistributedSampler does).
- Only rank 0 writes: checkpoints, ``metrics.csv``, TensorBoard, ``run.json``, the run's config;
  it also validates. Every rank reads ``checkpoints/last.pt`` to resume, so on several machines the
  run folder must be on a shared file system.
"""

from __future__ import annotations

import os
import pickle
import socket
import sys
import tempfile
import traceback
from pathlib import Path
from typing import Any, Callable, Iterator

import torch
import torch.distributed as dist
from torch.utils.data import DistributedSampler

from loosefit import device
from loosefit.errors import InputError, LoosefitError


def world_size() -> int:
    """Processes in the job: the process group's size, else ``WORLD_SIZE`` from the environment, else 1."""
    if dist.is_available() and dist.is_initialized():
        return dist.get_world_size()
    return int(os.environ.get("WORLD_SIZE", "1"))


def rank() -> int:
    """This process's global rank: the process group's, else ``RANK`` from the environment, else 0."""
    if dist.is_available() and dist.is_initialized():
        return dist.get_rank()
    return int(os.environ.get("RANK", "0"))


def is_main() -> bool:
    """Whether this process writes files and logs (rank 0)."""
    return rank() == 0


def is_distributed() -> bool:
    """Whether this process belongs to a job of more than one process."""
    return world_size() > 1


def resolve_device(name: str) -> torch.device:
    """:func:`loosefit.device.resolve_device`; CUDA in a distributed job is ``cuda:LOCAL_RANK``."""
    local = int(os.environ.get("LOCAL_RANK", "0")) if is_distributed() else 0
    return device.resolve_device(name, local)


def setup(device: torch.device) -> bool:
    """Join the process group described by the environment (``env://``), with ``nccl`` for a CUDA
    ``device`` and ``gloo`` otherwise. Returns True when this call created the group (the caller then
    calls :func:`teardown`), False when the job is one process or the group exists already."""
    if not is_distributed() or dist.is_initialized():
        return False
    missing = [k for k in ("MASTER_ADDR", "MASTER_PORT") if k not in os.environ]
    if missing:
        raise InputError(f"WORLD_SIZE={os.environ['WORLD_SIZE']} but {missing} not set: start the job with "
                         "`loosefit train --nproc N` or torchrun")
    if device.type == "cuda":
        torch.cuda.set_device(device)
    dist.init_process_group("nccl" if device.type == "cuda" else "gloo", init_method="env://")
    return True


def teardown(wait: bool = True) -> None:
    """Leave the process group; with ``wait``, after every rank has arrived (not after an error, when
    the others may never arrive)."""
    if dist.is_initialized():
        if wait:
            dist.barrier()
        dist.destroy_process_group()


def local_batch_size(global_batch: int) -> int:
    """Samples per process and step for a global batch of ``global_batch``."""
    n = world_size()
    if global_batch % n:
        raise InputError(f"batch_size {global_batch} is the global batch and must be a multiple of the "
                         f"{n} processes")
    return global_batch // n


class ShardedSampler(DistributedSampler):
    """This rank's share of one process's shuffle (see the module docstring).

    ``generator`` is the epoch's generator, the same object given to the DataLoader (which draws its
    base seed from it first, as it does in one process); the permutation is then
    ``torch.randperm(n, generator)``, exactly what a shuffling DataLoader of one process draws.
    """

    def __init__(self, dataset, generator: torch.Generator, shuffle: bool = True):
        super().__init__(dataset, num_replicas=world_size(), rank=rank(), shuffle=shuffle, drop_last=False)
        self.generator = generator

    def __iter__(self) -> Iterator[int]:
        n = len(self.dataset)
        order = torch.randperm(n, generator=self.generator).tolist() if self.shuffle else list(range(n))
        order += (order * (self.total_size // n + 1))[: self.total_size - n]  # pad to a multiple of the ranks
        return iter(order[self.rank : self.total_size : self.num_replicas])


def weight_share(weight: float, device: torch.device) -> float:
    """``N * weight / sum of every rank's weight``: the factor on this rank's loss so that the mean of
    the N scaled losses (what DDP's gradient averaging computes) is the loss of the whole global batch,
    for losses that are means normalised by ``weight`` (see ``loss_weight`` in
    :mod:`loosefit.train.protocol`); 1 in one process."""
    if not (is_distributed() and dist.is_initialized()):
        return 1.0
    total = torch.tensor([float(weight)], dtype=torch.float64, device=device)
    dist.all_reduce(total)
    return dist.get_world_size() * float(weight) / max(float(total.item()), 1e-30)


def all_finite(value: torch.Tensor) -> bool:
    """Whether ``value`` is finite on every rank (one all-reduce in a distributed job)."""
    ok = bool(torch.isfinite(value.detach()).all())
    if not (is_distributed() and dist.is_initialized()):
        return ok
    flag = torch.tensor([1.0 if ok else 0.0], device=value.device)
    dist.all_reduce(flag, op=dist.ReduceOp.MIN)
    return bool(flag.item() > 0)


def gather(obj: Any) -> list[Any]:
    """Every rank's ``obj`` (a picklable object), in rank order; ``[obj]`` in one process."""
    if not (is_distributed() and dist.is_initialized()):
        return [obj]
    out: list[Any] = [None] * dist.get_world_size()
    dist.all_gather_object(out, obj)
    return out


# -- launching on one machine -----------------------------------------------------------------
def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _worker(local_rank: int, nproc: int, port: int, outbox: str, fn: Callable, args: tuple, kwargs: dict) -> None:
    os.environ.update({"RANK": str(local_rank), "LOCAL_RANK": str(local_rank), "WORLD_SIZE": str(nproc),
                       "LOCAL_WORLD_SIZE": str(nproc), "MASTER_ADDR": "127.0.0.1", "MASTER_PORT": str(port)})
    try:
        result = fn(*args, **kwargs)
        if local_rank == 0:
            Path(outbox, "result.pkl").write_bytes(pickle.dumps(result))
        if dist.is_initialized():
            # every rank done before any tears its connections down: a rank whose peer closed first could abort
            # in gloo's shutdown (SIGABRT, seen on a loaded 2-core machine) after a run that succeeded
            dist.barrier()
    except LoosefitError as e:
        # a clear message for the parent instead of a traceback per process
        kind = "input" if isinstance(e, InputError) else "loosefit"
        Path(outbox, f"error-{local_rank}.pkl").write_bytes(pickle.dumps((kind, str(e))))
        sys.exit(2)
    except BaseException:
        Path(outbox, f"error-{local_rank}.pkl").write_bytes(pickle.dumps(("crash", traceback.format_exc())))
        raise
    finally:
        if dist.is_initialized():
            dist.destroy_process_group()


def launch(fn: Callable, nproc: int, *args, **kwargs) -> Any:
    """Run ``fn(*args, **kwargs)`` in ``nproc`` processes of one job on this machine; returns rank 0's result.

    ``nproc == 1``, or a process already started by torchrun (``WORLD_SIZE`` set), calls ``fn`` here.
    ``fn`` must be importable by name (the processes are spawned, not forked). A
    :class:`~loosefit.errors.LoosefitError` in any process is raised here with its message.
    """
    if nproc < 1:
        raise InputError(f"--nproc must be >= 1, got {nproc}")
    if nproc == 1 or "WORLD_SIZE" in os.environ:
        return fn(*args, **kwargs)
    import torch.multiprocessing as mp
    from torch.multiprocessing.spawn import ProcessException

    with tempfile.TemporaryDirectory(prefix="loosefit-ddp-") as outbox:
        try:
            mp.spawn(_worker, args=(nproc, _free_port(), outbox, fn, args, kwargs), nprocs=nproc, join=True)
        except ProcessException as e:
            errors = sorted(Path(outbox).glob("error-*.pkl"))
            if not errors:
                raise LoosefitError(f"a training process failed: {e}") from None
            kind, message = pickle.loads(errors[0].read_bytes())
            rank_of = errors[0].stem.split("-")[1]
            if kind == "input":
                raise InputError(message) from None
            raise LoosefitError(f"training process {rank_of} failed: {message}") from None
        return pickle.loads(Path(outbox, "result.pkl").read_bytes())

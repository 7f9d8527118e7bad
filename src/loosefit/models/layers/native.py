"""Native CPU kernels: C compiled on first use by the machine's C compiler, called through :mod:`ctypes`.

One kernel so far, ``gat_ln_cpu.c``: a GAT-LN layer's attention and aggregation in one sweep over the vertices
(:func:`gat_ln_concat_node_centred`), where torch's eager passes write and read the ``(V, heads, slots)`` scores about
ten times. It serves inference (no autograd) on the CPU in float32; training, other devices and dtypes, and the
designs it does not cover keep the eager layer (:mod:`loosefit.models.layers.gat_ln`).

Building: ``$CC`` (else ``cc``) with ``-O3 -march=native``, once per source, compiler and CPU, into
``$XDG_CACHE_HOME/loosefit/native`` (else ``~/.cache/loosefit/native``), written under a temporary name and renamed,
so that concurrent first uses do not read a half-written library. Without a compiler, or when the build fails, the
eager layer runs (one warning says why). ``LOOSEFIT_NATIVE=0`` switches the kernels off.
"""

from __future__ import annotations

import ctypes
import functools
import hashlib
import os
import platform
import shutil
import subprocess
import tempfile
import warnings
from pathlib import Path

import torch

SOURCE = Path(__file__).with_name("gat_ln_cpu.c")
#: -fno-trapping-math lets the exponential's floor vectorise; no -ffast-math: the sums keep their order.
FLAGS = ("-O3", "-march=native", "-fno-math-errno", "-fno-trapping-math", "-shared", "-fPIC")
_INT64, _FLOAT, _PTR = ctypes.c_int64, ctypes.c_float, ctypes.c_void_p


def enabled() -> bool:
    """Whether native kernels may be used at all (``LOOSEFIT_NATIVE`` is not ``0``)."""
    return os.environ.get("LOOSEFIT_NATIVE", "1") != "0"


def _cache_dir() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "loosefit" / "native"


def _cpu_signature() -> str:
    """What ``-march=native`` depends on: the machine and, on Linux, the CPU's model and feature flags."""
    text = platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            text += "".join(line for line in f if line.startswith(("model name", "flags")))[:4096]
    except OSError:
        pass
    return text


@functools.cache
def library() -> ctypes.CDLL | None:
    """The compiled kernels, built on first call; None where they are off or cannot be built."""
    if not enabled():
        return None
    compiler = shutil.which(os.environ.get("CC", "cc")) or shutil.which("gcc")
    if compiler is None:
        warnings.warn("loosefit: no C compiler found; GAT-LN runs its eager CPU path", RuntimeWarning, stacklevel=2)
        return None
    try:
        source = SOURCE.read_bytes()
    except OSError as error:
        warnings.warn(f"loosefit: the native GAT-LN kernel's source is missing ({error}); GAT-LN runs its eager CPU "
                      "path", RuntimeWarning, stacklevel=2)
        return None
    try:
        version = subprocess.run([compiler, "--version"], capture_output=True, text=True, timeout=30).stdout
    except (OSError, subprocess.SubprocessError):
        version = ""
    key = hashlib.sha256(b"\0".join([source, " ".join(FLAGS).encode(), version.encode(),
                                     _cpu_signature().encode()])).hexdigest()[:16]
    target = _cache_dir() / f"gat_ln_cpu-{key}.so"
    if not target.exists():
        partial = None
        try:
            target.parent.mkdir(parents=True, exist_ok=True)
            fd, partial = tempfile.mkstemp(suffix=".so", dir=target.parent)
            os.close(fd)
            subprocess.run([compiler, *FLAGS, "-o", partial, str(SOURCE), "-lm"], check=True, capture_output=True,
                           text=True, timeout=300)
            os.replace(partial, target)
        except (OSError, subprocess.SubprocessError) as error:
            detail = getattr(error, "stderr", "") or error
            warnings.warn(f"loosefit: could not build the native GAT-LN kernel ({str(detail).strip()[:300]}); GAT-LN "
                          "runs its eager CPU path", RuntimeWarning, stacklevel=2)
            if partial is not None and os.path.exists(partial):
                os.unlink(partial)
            return None
    lib = ctypes.CDLL(str(target))
    lib.gat_ln_concat_node_centred.restype = ctypes.c_int
    lib.gat_ln_concat_node_centred.argtypes = [_INT64] * 6 + [_PTR] * 8 + [ctypes.c_int] + [_FLOAT] * 3 + [_PTR]
    return lib


def gat_ln_concat_node_centred(x: torch.Tensor, y: torch.Tensor, u: torch.Tensor, lip: torch.Tensor,
                               table: torch.Tensor, valid: torch.Tensor, head_of: torch.Tensor, bias: torch.Tensor,
                               tanh: bool, alpha: float, slope: float, eps: float) -> torch.Tensor:
    """A GAT-LN layer's output features, ``(B, V, C_out)`` float32 (see ``gat_ln_cpu.c``).

    Args:
        x: ``(B, V, C_in)``: the input features.
        y: ``(B, V, C_out)``: the projected features ``x W``.
        u: ``(B, V, 2 H)``: ``c_dst . x`` then ``c_src . x``, the score function's two halves per head.
        lip: ``(H,)``: each head's score function's Lipschitz constant.
        table, valid: ``(V, D)``: the attention table (:func:`~loosefit.models.layers.gat_ln.attention_table`).
        head_of: ``(C_out,)`` int64: each output channel's head, non-decreasing (each head's channels one block).
        bias: ``(C_out,)``, added before the activation; tanh: apply tanh (else none).
        alpha, slope, eps: SwinGar Eq. 4's score scale, the LeakyReLU slope, the smallest norm.
    """
    lib = library()
    if lib is None:
        raise RuntimeError("the native GAT-LN kernel is not available")
    B, V, C_in = x.shape
    C_out, H, D = y.shape[-1], lip.shape[0], table.shape[1]
    x, y, u, lip, bias = (t.detach().contiguous().float() for t in (x, y, u, lip, bias))
    table, head_of = table.contiguous().long(), head_of.contiguous().long()
    valid = valid.contiguous().view(torch.uint8) if valid.dtype == torch.bool else valid.contiguous().to(torch.uint8)
    out = torch.empty(B, V, C_out, dtype=torch.float32)
    status = lib.gat_ln_concat_node_centred(B, V, D, C_in, C_out, H, *(t.data_ptr() for t in (
        x, y, u, lip, table, valid, head_of, bias)), int(tanh), alpha, slope, eps, out.data_ptr())
    if status != 0:
        raise MemoryError("the native GAT-LN kernel could not allocate its scratch memory")
    return out

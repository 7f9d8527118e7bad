"""Optional dependencies: which extra of ``pip install loosefit[...]`` provides what, and a clear error
when one is missing.

``pip install loosefit`` gives the library, the CLI, training and animation. The extras:

- ``sim``: ground-truth cloth simulation (``bpy``, Blender as a module; ``newton``, NVIDIA Newton) and
  parallel simulation on Ray (``ray``); Alembic export runs through Blender too.
- ``viz``: offscreen rendering to PNG / MP4 / GIF (``pyvista``, ``imageio``, ``imageio-ffmpeg``,
  ``matplotlib``) and ``loosefit report`` (``jinja2``).
- ``smpl``: SMPL / SMPL-X bodies (``smplx``; the model files come from the user).
- ``view``: ``loosefit view`` (nothing beyond the core: a standard-library server and vendored scripts).
- ``onnx``: ``loosefit export-onnx`` (``onnx``) and running the exported model (``onnxruntime``).
"""

from __future__ import annotations

import functools
import importlib
import importlib.util
from types import ModuleType

from loosefit.errors import InputError

#: module -> the extra that installs it
EXTRA_OF = {"bpy": "sim", "newton": "sim", "warp": "sim", "ray": "sim", "pyvista": "viz", "imageio": "viz",
            "imageio_ffmpeg": "viz", "matplotlib": "viz", "jinja2": "viz", "smplx": "smpl",
            "onnx": "onnx", "onnxruntime": "onnx"}


def _missing(module: str, what: str, error) -> InputError:
    top = module.split(".")[0]
    extra = EXTRA_OF.get(top)
    hint = f"pip install 'loosefit[{extra}]'" if extra else f"pip install {top}"
    return InputError(f"{what} needs {top!r}, which is not installed ({error}): {hint}")


def require_installed(module: str, what: str) -> None:
    """Check that ``module`` is installed without importing it, for a process that hands the work to others.
    (Importing ``bpy`` puts Blender's script folders first on ``sys.path``; processes spawned afterwards inherit
    it, and there Blender's own ``bpy`` package shadows the module: ``No module named '_bpy'``.)

    Raises:
        InputError: the module is not installed, as :func:`require`.
    """
    try:
        found = importlib.util.find_spec(module.split(".")[0]) is not None
    except (ImportError, ValueError) as e:  # a finder that refuses it, a module with no spec
        raise _missing(module, what, e) from None
    if not found:
        raise _missing(module, what, f"no module named {module!r}")


def require(module: str, what: str) -> ModuleType:
    """Import ``module`` (e.g. ``"bpy"``) for ``what`` (e.g. ``"Blender cloth simulation"``).

    Raises:
        InputError: the module is not installed; the message names the extra that installs it.
    """
    try:
        return importlib.import_module(module)
    except ImportError as e:
        raise _missing(module, what, e) from None


@functools.lru_cache(maxsize=None)
def warp_kernels(module: str, *names: str) -> tuple | None:
    """``(warp, kernel, ...)``: Warp and the kernels ``names`` of loosefit's ``module`` (which imports Warp),
    compiled on first use and then cached on disk by Warp; ``None`` when Warp cannot be imported, so that the
    caller takes its NumPy or libigl path."""
    try:
        import warp as wp

        kernels = importlib.import_module(module)
    except Exception:  # not installed or broken
        return None
    return (wp, *(getattr(kernels, name) for name in names))

"""Optional dependencies: which extra of ``pip install loosefit[...]`` provides what, and a clear error
when one is missing.

``pip install loosefit`` gives the library, the CLI, training and animation. The extras:

- ``sim``: ground-truth cloth simulation (``bpy``, Blender as a module; ``newton``, NVIDIA Newton) and
  parallel simulation on Ray (``ray``); Alembic export runs through Blender too.
- ``viz``: offscreen rendering to PNG / MP4 / GIF (``pyvista``, ``imageio``, ``imageio-ffmpeg``,
  ``matplotlib``) and ``loosefit report`` (``jinja2``).
- ``smpl``: SMPL / SMPL-X bodies (``smplx``; the model files come from the user).
- ``view``: ``loosefit view`` (nothing beyond the core: a standard-library server and vendored scripts).
"""

from __future__ import annotations

import importlib
from types import ModuleType

from loosefit.errors import InputError

#: module -> the extra that installs it
EXTRA_OF = {"bpy": "sim", "newton": "sim", "warp": "sim", "ray": "sim", "pyvista": "viz", "imageio": "viz",
            "imageio_ffmpeg": "viz", "matplotlib": "viz", "jinja2": "viz", "smplx": "smpl"}


def require(module: str, what: str) -> ModuleType:
    """Import ``module`` (e.g. ``"bpy"``) for ``what`` (e.g. ``"Blender cloth simulation"``).

    Raises:
        InputError: the module is not installed; the message names the extra that installs it.
    """
    try:
        return importlib.import_module(module)
    except ImportError as e:
        top = module.split(".")[0]
        extra = EXTRA_OF.get(top)
        hint = f"pip install 'loosefit[{extra}]'" if extra else f"pip install {top}"
        raise InputError(f"{what} needs {top!r}, which is not installed ({e}): {hint}") from None

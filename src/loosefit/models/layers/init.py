"""Building a layer's sub-modules without drawing their initial values, so that the layer's
``reset_parameters`` is its one initialiser.

A torch or PyG module draws its parameters in its constructor. A layer that built its parts that way and
then called its own ``reset_parameters`` (PyG's habit) would draw everything twice, and a layer that adjusted
its parts after building them (a bias filled, a read-out scaled) would spread its initialisation over two
places. Built with :func:`undrawn`, the parts hold memory but no values, and no random number is drawn; the
layer's ``__init__`` ends with ``self.reset_parameters()``, which draws and sets every parameter in one place,
in the order the parts were built: the same draws as building them initialised.
"""

from __future__ import annotations

from typing import Callable, TypeVar

import torch
from torch import nn

M = TypeVar("M", bound=nn.Module)


def undrawn(factory: Callable[..., M], *args, **kwargs) -> M:
    """``factory(*args, **kwargs)`` with its parameters and buffers allocated on the default device but not
    initialised (built on the meta device, then given empty memory): for parts whose every parameter and
    buffer the caller's ``reset_parameters`` sets."""
    device = torch.get_default_device()
    with torch.device("meta"):
        module = factory(*args, **kwargs)
    return module.to_empty(device=device)

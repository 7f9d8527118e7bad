"""Projecting a trained JointNet's pose-space deformation onto the garment's smoothest vibration modes.

A free PSD basis (one displacement per vertex, JointNet Eq. 5) memorises the training subjects' wrinkles; its
projection onto the ``k`` smoothest modes of the rest mesh keeps the smooth part (:class:`JointNetConfig`'s
``psd_modes`` says what was measured). The shipped JointNet garments are projected so.
"""

from __future__ import annotations

from dataclasses import replace

import torch

from loosefit.errors import InputError
from loosefit.geometry.laplacian import mass_matrix, smoothest_modes
from loosefit.models.jointnet import JointNet


def project_psd(model: JointNet, modes: int) -> JointNet:
    """A copy of the trained ``model`` whose PSD bases (free, per vertex) are projected onto the garment's ``modes``
    smoothest vibration modes, ``C_j = Phi^T M D_j`` (``config.psd_modes = modes``): their smooth part, what a
    model trained with ``psd_modes`` could hold; everything else as trained. For measuring what the free basis's
    high frequencies add, and for a smaller model.

    Raises:
        InputError: the model's basis is already in modes, or ``modes`` is out of range.
    """
    if model.psd_mode_count:
        raise InputError(f"the model's PSD is already in {model.psd_mode_count} modes")
    if not 1 <= modes < model.rig_rest.shape[0]:
        raise InputError(f"the garment of {model.rig_rest.shape[0]} vertices has no {modes} smoothest modes")
    out = JointNet({**model.sizes(), "psd_modes": modes}, replace(model.config, psd_modes=modes))
    rest, faces = model.rig_rest.double().numpy(), model.faces.numpy()
    phi = smoothest_modes(rest, faces, out.psd_mode_count)
    weighted = phi * mass_matrix(rest, faces).diagonal()[:, None]  # M Phi, M diagonal
    state = model.state_dict()
    basis = state.pop("psd_basis").double()
    state["psd_basis"] = torch.einsum("vk,gxvc->gxkc", torch.from_numpy(weighted), basis).float()
    state["psd_modes"] = torch.from_numpy(phi).float()
    out.load_state_dict(state)
    return out.eval()

"""SMPL, SMPL-H and SMPL-X bodies through ``smplx``, from model files the user supplies.

The model files are not distributed with loosefit (their licence forbids it): pass the path of a
``SMPL_*.pkl`` / ``.npz``, ``SMPLH_*.npz`` or ``SMPLX_*.npz`` file. The forward pass is smplx's own
``lbs`` (shape blend shapes, pose-corrective blend shapes, skinning); loosefit only changes the frame:
SMPL is Y-up facing +Z, loosefit is Z-up facing -Y, a rotation of +90 degrees about X, then the same
floor placement as every body (soles on ``z = 0``, root above the origin).
"""

from __future__ import annotations

import pickle
from pathlib import Path

import numpy as np
import torch

from loosefit.body.base import BodyModel, PosedBody
from loosefit.errors import InputError
from loosefit.geometry.lbs import forward_kinematics
from loosefit.geometry.rotations import axis_angle_to_matrix, matrix_to_axis_angle
from loosefit.motion.motion import Motion

#: SMPL (Y-up, facing +Z) to loosefit (Z-up, facing -Y): (x, y, z) -> (x, -z, y).
Y_UP_TO_Z_UP = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]], dtype=np.float64)

_REQUIRED = ("v_template", "shapedirs", "posedirs", "J_regressor", "weights", "kintree_table", "f")


def smpl_joint_names(num_joints: int) -> list[str]:
    """Joint names of the SMPL family by joint count: 24 (SMPL), 52 (SMPL-H), 55 (SMPL-X)."""
    from smplx.joint_names import JOINT_NAMES

    if num_joints == 24:
        return JOINT_NAMES[:22] + ["left_hand", "right_hand"]
    if num_joints == 52:
        return JOINT_NAMES[:22] + JOINT_NAMES[25:55]
    if num_joints == 55:
        return JOINT_NAMES[:55]
    raise InputError(f"unsupported SMPL-family joint count {num_joints} (expected 24, 52 or 55)")


def _dense(a) -> np.ndarray:
    return np.asarray(a.todense() if hasattr(a, "todense") else a, dtype=np.float64)


def read_smpl_file(path: str | Path) -> dict[str, np.ndarray]:
    """Read a SMPL-family model file (``.pkl`` or ``.npz``) into plain float64 / int64 arrays."""
    path = Path(path)
    if not path.is_file():
        raise InputError("SMPL model file not found", path)
    try:
        if path.suffix == ".pkl":
            with open(path, "rb") as f:
                raw = pickle.load(f, encoding="latin1")
        else:
            raw = dict(np.load(path, allow_pickle=True))
    except ModuleNotFoundError as e:
        raise InputError(f"the pickle needs module {e.name!r} (original SMPL files use chumpy); "
                         "convert it to .npz or install that module", path) from None
    except Exception as e:  # noqa: BLE001 - any unreadable file gets the same clear message
        raise InputError(f"cannot read SMPL model file: {e}", path) from None
    missing = [k for k in _REQUIRED if k not in raw]
    if missing:
        raise InputError(f"not a SMPL-family model file, missing {missing}", path)
    data = {k: _dense(raw[k]) for k in ("v_template", "shapedirs", "posedirs", "J_regressor", "weights")}
    data["kintree_table"] = np.asarray(raw["kintree_table"], dtype=np.int64)
    data["f"] = np.asarray(raw["f"], dtype=np.int64)
    V, J = data["v_template"].shape[0], data["J_regressor"].shape[0]
    checks = {
        "shapedirs": data["shapedirs"].shape[:2] == (V, 3),
        "posedirs": data["posedirs"].shape[:2] == (V, 3) and data["posedirs"].shape[2] == 9 * (J - 1),
        "J_regressor": data["J_regressor"].shape == (J, V),
        "weights": data["weights"].shape == (V, J),
        "kintree_table": data["kintree_table"].shape == (2, J),
        "f": data["f"].ndim == 2 and data["f"].shape[1] == 3 and data["f"].max() < V,
    }
    bad = [k for k, ok in checks.items() if not ok]
    if bad:
        raise InputError(f"inconsistent array shapes for {V} vertices and {J} joints: {bad}", path)
    return data


class SMPLBody(BodyModel):
    """A SMPL-family body; ``shape`` is a betas vector ``(B,)`` (missing trailing betas are zero)."""

    def __init__(self, model_path: str | Path, betas=None):
        import smplx.lbs  # noqa: F401 - fail early with a clear ImportError when smplx is absent

        data = read_smpl_file(model_path)
        self.path = Path(model_path)
        J = data["J_regressor"].shape[0]
        self.joint_names = smpl_joint_names(J)
        self.rig = {24: "smpl", 52: "smplh", 55: "smplx"}[J]
        self.name = f"{self.rig}:{self.path.name}"
        parents = data["kintree_table"][0].copy()
        parents[0] = -1
        self.parents = parents
        self.faces = data["f"]
        self.num_betas = data["shapedirs"].shape[2]
        t = lambda a: torch.from_numpy(np.ascontiguousarray(a))  # noqa: E731
        self._v_template = t(data["v_template"])
        self._shapedirs = t(data["shapedirs"])
        self._posedirs = t(data["posedirs"].reshape(-1, data["posedirs"].shape[2]).T)
        self._J_regressor = t(data["J_regressor"])
        self._parents_t = torch.from_numpy(data["kintree_table"][0].copy())
        self._weights = data["weights"].astype(np.float32)
        self.betas = self._betas(betas)
        self._rest: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}
        self._offsets: dict[bytes, np.ndarray] = {}

    def _betas(self, shape) -> np.ndarray:
        if shape is None:
            return getattr(self, "betas", np.zeros(self.num_betas))
        b = np.asarray(shape, dtype=np.float64).reshape(-1)
        if b.shape[0] > self.num_betas:
            raise InputError(f"{b.shape[0]} betas given, model {self.path} has {self.num_betas}")
        return np.pad(b, (0, self.num_betas - b.shape[0]))

    def _smpl_lbs(self, betas: np.ndarray, pose: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """smplx's forward pass in SMPL's own frame: ``pose (T, J*3)`` -> verts ``(T,V,3)``, joints ``(T,J,3)``."""
        from smplx.lbs import lbs

        b = torch.from_numpy(betas)[None].expand(pose.shape[0], -1)
        return lbs(b, pose, self._v_template, self._shapedirs, self._posedirs, self._J_regressor,
                   self._parents_t, torch.from_numpy(self._weights).double())

    def _rest_geometry(self, shape):
        betas = self._betas(shape)
        key = betas.tobytes()
        if key not in self._rest:
            J = len(self.joint_names)
            with torch.no_grad():
                v, j = self._smpl_lbs(betas, torch.zeros(1, 3 * J, dtype=torch.float64))
            v, j = v[0].numpy() @ Y_UP_TO_Z_UP.T, j[0].numpy() @ Y_UP_TO_Z_UP.T
            offset = np.array([-j[0, 0], -j[0, 1], -v[:, 2].min()])
            self._rest[key] = ((v + offset).astype(np.float32), (j + offset).astype(np.float32))
            self._offsets[key] = offset
        return self._rest[key]

    def pose(self, motion: Motion, shape=None, batch: int = 128) -> PosedBody:
        """Pose with smplx's full forward pass (pose-corrective blend shapes included)."""
        self.check_motion(motion)
        betas = self._betas(shape)
        _, rest_j = self._rest_geometry(shape)
        offset = self._offsets[betas.tobytes()]
        C = torch.from_numpy(Y_UP_TO_Z_UP)
        R = axis_angle_to_matrix(torch.from_numpy(motion.rotations).double())
        # A rotation R in loosefit's frame is C^T R C in SMPL's frame.
        pose_smpl = matrix_to_axis_angle(C.T @ R @ C).reshape(motion.num_frames, -1)
        # smplx leaves the root joint where it is at rest (root_smpl, in loosefit axes before the floor
        # offset); shift every frame so that the root lands on motion.translation.
        root_smpl = torch.from_numpy(rest_j[0] - offset).double()
        trans = torch.from_numpy(motion.translation).double()
        verts = []
        with torch.no_grad():
            for s in range(0, motion.num_frames, batch):
                v, _ = self._smpl_lbs(betas, pose_smpl[s : s + batch])
                verts.append(v @ C.T - root_smpl + trans[s : s + batch, None])
            world = forward_kinematics(R, trans, torch.from_numpy(rest_j).double(), self.parents)
        return PosedBody(torch.cat(verts).numpy().astype(np.float32), world.numpy().astype(np.float32), self.faces)

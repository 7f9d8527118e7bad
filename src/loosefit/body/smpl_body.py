"""SMPL, SMPL-H and SMPL-X bodies through ``smplx``, from model files the user supplies.

The model files are not distributed with loosefit (their licence forbids it): pass the path of a
``SMPL_*.pkl`` / ``.npz``, ``SMPLH_*.npz`` or ``SMPLX_*.npz`` file. Reading one runs no code from it
(:func:`read_smpl_file`). The forward pass is smplx's own
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
from loosefit.io.npz import load_npz
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


class _ChumpyArray:
    """What a ``chumpy.ch.Ch`` in an original SMPL pickle becomes: its array (the ``x`` of its pickled
    state) without chumpy's own code, which the pickle would otherwise run."""

    def __setstate__(self, state):
        if not isinstance(state, dict) or not isinstance(state.get("x"), np.ndarray):
            raise pickle.UnpicklingError("a chumpy array without its values ('x')")
        self.x = state["x"]

    def __array__(self, dtype=None, copy=None):
        return np.asarray(self.x, dtype=dtype)


def _pickle_allow_list() -> dict[tuple[str, str], object]:
    """The only globals a SMPL-family pickle may name: numpy arrays, dtypes and scalars, scipy sparse
    matrices (the J_regressor), chumpy arrays (as :class:`_ChumpyArray`) and the helpers that rebuild
    them. Module paths of several numpy / scipy versions (numpy 2 writes ``numpy._core``)."""
    import _codecs
    import copyreg

    import scipy.sparse

    core = np.core.multiarray
    allowed = {
        ("numpy", "ndarray"): np.ndarray,
        ("numpy", "dtype"): np.dtype,
        ("_codecs", "encode"): _codecs.encode,  # bytes in protocol-2 pickles written by Python 3
        ("copyreg", "_reconstructor"): copyreg._reconstructor,
        ("builtins", "object"): object,
        ("builtins", "set"): set,
        ("builtins", "frozenset"): frozenset,
        ("chumpy.ch", "Ch"): _ChumpyArray,
    }
    for module in ("numpy.core", "numpy._core"):
        allowed[(f"{module}.multiarray", "_reconstruct")] = core._reconstruct
        allowed[(f"{module}.multiarray", "scalar")] = core.scalar
        allowed[(f"{module}.numeric", "_frombuffer")] = np.core.numeric._frombuffer
    for kind in ("csc", "csr", "coo"):
        for name in (f"{kind}_matrix", f"{kind}_array"):
            if hasattr(scipy.sparse, name):
                for module in ("scipy.sparse", f"scipy.sparse.{kind}", f"scipy.sparse._{kind}"):
                    allowed[(module, name)] = getattr(scipy.sparse, name)
    return allowed


class _RefusedGlobal(pickle.UnpicklingError):
    def __init__(self, module: str, name: str):
        self.name = f"{module}.{name}"
        super().__init__(self.name)


class _SMPLUnpickler(pickle.Unpickler):
    """An unpickler that builds only the objects of :func:`_pickle_allow_list`: a crafted pickle that
    names anything else (``os.system``, ``builtins.eval``...) is refused before it can run."""

    def __init__(self, file):
        super().__init__(file, encoding="latin1")  # Python 2 pickles (the original SMPL files)
        self._allowed = _pickle_allow_list()

    def find_class(self, module, name):
        from _compat_pickle import IMPORT_MAPPING, NAME_MAPPING  # Python 2 names: copy_reg, __builtin__

        module, name = NAME_MAPPING.get((module, name), (IMPORT_MAPPING.get(module, module), name))
        try:
            return self._allowed[(module, name)]
        except (KeyError, TypeError):
            raise _RefusedGlobal(module, name) from None


def _read_pickle(path: Path) -> object:
    try:
        with open(path, "rb") as f:
            return _SMPLUnpickler(f).load()
    except _RefusedGlobal as e:
        raise InputError(f"the pickle asks for {e.name}, which a SMPL-family model file never holds; refused "
                         "(unpickling it could run code)", path) from None
    except Exception as e:  # noqa: BLE001 - a damaged pickle raises many types
        raise InputError(f"cannot read SMPL model file: {type(e).__name__}: {e}", path) from None


def read_smpl_file(path: str | Path) -> dict[str, np.ndarray]:
    """Read a SMPL-family model file (``.pkl`` or ``.npz``) into plain float64 / int64 arrays.

    No code from the file runs: an ``.npz`` is read without pickles (an object array is refused) and a
    ``.pkl`` through an unpickler that builds only numpy arrays, scipy sparse matrices and chumpy arrays
    (read as their values, without chumpy).
    """
    path = Path(path)
    if not path.is_file():
        raise InputError("SMPL model file not found", path)
    if path.suffix.lower() == ".pkl":
        raw = _read_pickle(path)
        if not isinstance(raw, dict):
            raise InputError(f"not a SMPL-family model file (a pickled {type(raw).__name__}, not a dict)", path)
    else:
        raw = load_npz(path, "SMPL model file", names=_REQUIRED)
    missing = [k for k in _REQUIRED if k not in raw]
    if missing:
        raise InputError(f"not a SMPL-family model file, missing {missing}", path)
    try:
        data = {k: _dense(raw[k]) for k in ("v_template", "shapedirs", "posedirs", "J_regressor", "weights")}
        data["kintree_table"] = np.asarray(raw["kintree_table"], dtype=np.int64)
        data["f"] = np.asarray(raw["f"], dtype=np.int64)
    except (TypeError, ValueError) as e:
        raise InputError(f"not a SMPL-family model file: an array is not numeric ({e})", path) from None
    ndims = {"v_template": 2, "shapedirs": 3, "posedirs": 3, "J_regressor": 2, "weights": 2}
    flat = [k for k, n in ndims.items() if data[k].ndim != n]
    if flat:
        raise InputError(f"not a SMPL-family model file: arrays {flat} have the wrong number of axes", path)
    V, J = data["v_template"].shape[0], data["J_regressor"].shape[0]
    checks = {
        "shapedirs": data["shapedirs"].shape[:2] == (V, 3),
        "posedirs": data["posedirs"].shape[:2] == (V, 3) and data["posedirs"].shape[2] == 9 * (J - 1),
        "J_regressor": data["J_regressor"].shape == (J, V),
        "weights": data["weights"].shape == (V, J),
        "kintree_table": data["kintree_table"].shape == (2, J),
        "f": data["f"].ndim == 2 and data["f"].shape[1] == 3 and data["f"].size > 0
             and 0 <= data["f"].min() and data["f"].max() < V,
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

"""Virtual bones: a garment mesh sequence decomposed into rigid bones plus linear blend skinning (SSDR).

VirtualBones (Pan et al. 2022, Sec. 4.1) turns the low-frequency garment sequence into a rest mesh ``P``,
sparse skinning weights ``W (V, B)`` and per-frame rigid bone transforms ``[R | T]`` such that::

    v_i(t) = sum_j W[i, j] (R_j(t) p_i + T_j(t))            (VirtualBones Eq. 1)

The bones are free (no hierarchy) and the networks of the later stages predict ``R, T`` per frame.
Here the decomposition is Smooth Skinning Decomposition with Rigid bones (Le and Deng 2012) through
``py-dem-bones``. The rest mesh is given (not solved): the caller passes the smoothed rest garment.

Two solver settings matter and are exposed:

- ``trans_affine``: Dem Bones' soft constraint tying each bone's translation to the motion of the
  vertices around it (default in Dem Bones: 10). It keeps bones near their vertices but costs
  accuracy, and a lot of it: on a 2k-vertex swirling cone with 20 bones, RMSE is 5.3 mm at 10,
  1.5 mm at 0.1 and 0.4 mm at 0 (it is scale invariant: metres or centimetres give the same
  result). Without it, bones move less smoothly: on a simulated 3.6k-vertex spinning skirt
  (20 bones) the mean second difference of the bone translations over frames is 11.9 mm at 0,
  9.3 mm at 0.1 and 9.1 mm at 1 (RMSE 1.1, 1.7 and 2.5 mm); hence :data:`DEFAULT_TRANS_AFFINE` = 0.1.
- ``max_solve_frames``: the weight solve (the expensive, alternating part) sees at most this many
  frames, evenly spread over the input. The transforms of *every* frame are then solved with the
  weights fixed (:func:`solve_bone_transforms`), independently per frame, in chunks, starting from
  the nearest solved frame. That step must run to convergence (30 sweeps): with 10, bones that their
  vertices hold loosely stop wherever their start left them and jump from frame to frame. Measured
  on a simulated 3.6k-vertex spinning skirt (150 frames, 80 bones, weights from 50 frames): all-frame
  RMSE 0.71 mm and a bone rotation second difference of 0.19 per frame with 10 sweeps, 0.43 mm and
  0.032 with 25 or more, the same as solving the weights on all 150 frames (0.42 mm, 0.032).

Threads: Dem Bones runs OpenMP loops. On the 2-core machines shared with other jobs, 2 threads made
the same 5-bone fit of a 5.4k-vertex dress (60 frames, 20 iterations) take 2.1 to 34 s from run to
run, 1 thread 2.4 to 2.6 s; so ``threads`` defaults to 1 (limited with threadpoolctl during the calls).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch
from threadpoolctl import threadpool_limits

from loosefit.errors import InputError
from loosefit.io.npz import load_npz, save_npz

#: Virtual bones per garment (VirtualBones Sec. 5 uses 80): the default of fit_virtual_bones, PrepareSettings,
#: prepare and the CLI.
DEFAULT_BONES = 80
#: Dem Bones' translation-affinity weight used by default (see the module docstring for its cost).
DEFAULT_TRANS_AFFINE = 0.1
#: Frames seen by the weight solve unless told otherwise.
DEFAULT_MAX_SOLVE_FRAMES = 300
#: Frames per native transform solve (bounds memory: ``chunk * V * 24`` bytes of float64 input).
TRANSFORM_CHUNK = 128
#: OpenMP threads of the Dem Bones calls unless told otherwise (see the module docstring).
DEFAULT_THREADS = 1


@dataclass
class VirtualBoneRig:
    """The skinning model of a garment's virtual bones.

    Attributes:
        rest_verts: ``(V, 3)`` float32 rest mesh ``P``, metres.
        faces: ``(F, 3)`` int64 triangles of the garment.
        weight_indices: ``(V, K)`` int64 bone index of each vertex's ``K`` strongest influences.
        weight_values: ``(V, K)`` float32 weights matching ``weight_indices``, non-negative, each row
            summing to 1, sorted decreasing; unused slots hold weight 0 (and bone 0).
        bone_rest_positions: ``(B, 3)`` float32 rest position of each bone: the weighted centroid
            ``sum_i W[i, j] p_i / sum_i W[i, j]`` of the rest vertices it moves (bone transforms are
            relative to the rest mesh, so the rest transform of every bone is the identity).
        rmse: root mean squared vertex error of the decomposition over the frames it was measured on,
            metres (``sqrt(mean_t,i |v_i(t) - v_hat_i(t)|^2)``).
        settings: the solver settings and frame counts that produced the rig (JSON values).
    """

    rest_verts: np.ndarray
    faces: np.ndarray
    weight_indices: np.ndarray
    weight_values: np.ndarray
    bone_rest_positions: np.ndarray
    rmse: float = float("nan")
    settings: dict = field(default_factory=dict)

    def __post_init__(self):
        self.rest_verts = np.asarray(self.rest_verts, np.float32)
        self.faces = np.asarray(self.faces, np.int64)
        self.weight_indices = np.asarray(self.weight_indices, np.int64)
        self.weight_values = np.asarray(self.weight_values, np.float32)
        self.bone_rest_positions = np.asarray(self.bone_rest_positions, np.float32)
        V, B = len(self.rest_verts), len(self.bone_rest_positions)
        if self.weight_indices.shape != self.weight_values.shape or self.weight_indices.shape[:1] != (V,):
            raise InputError(
                f"rig weights must be (V, K) index and value arrays for {V} vertices, "
                f"got {self.weight_indices.shape} and {self.weight_values.shape}"
            )
        if self.weight_indices.size and (self.weight_indices.min() < 0 or self.weight_indices.max() >= B):
            raise InputError(f"rig weight indices outside [0, {B})")

    @property
    def num_verts(self) -> int:
        return len(self.rest_verts)

    @property
    def num_bones(self) -> int:
        return len(self.bone_rest_positions)

    @property
    def max_influences(self) -> int:
        return self.weight_indices.shape[1]

    def dense_weights(self) -> np.ndarray:
        """``(V, B)`` float32 skinning weights."""
        W = np.zeros((self.num_verts, self.num_bones), np.float32)
        np.add.at(W, (np.arange(self.num_verts)[:, None], self.weight_indices), self.weight_values)
        return W

    def skin(self, rotations, translations):
        """Skin the rest mesh: ``rotations (..., B, 3, 3)``, ``translations (..., B, 3)`` -> ``(..., V, 3)``.

        NumPy in, NumPy float32 out; torch in, torch out (differentiable, on the inputs' device).
        """
        if isinstance(rotations, torch.Tensor):
            rest = torch.as_tensor(self.rest_verts, dtype=rotations.dtype, device=rotations.device)
            W = torch.as_tensor(self.dense_weights(), dtype=rotations.dtype, device=rotations.device)
            return skin_bones(rest, W, rotations, translations)
        R = torch.as_tensor(np.asarray(rotations, np.float64))
        T = torch.as_tensor(np.asarray(translations, np.float64))
        rest = torch.as_tensor(self.rest_verts, dtype=torch.float64)
        W = torch.as_tensor(self.dense_weights(), dtype=torch.float64)
        return skin_bones(rest, W, R, T).numpy().astype(np.float32)

    def save(self, path: str | Path) -> None:
        """Write the rig to an ``.npz`` file, atomically."""
        save_npz(path, self.to_arrays(), compressed=True)

    @classmethod
    def load(cls, path: str | Path) -> "VirtualBoneRig":
        """Read a rig written by :meth:`save`; a bad file raises :class:`InputError` naming it."""
        path = Path(path)
        arrays = load_npz(path, "a virtual bone rig")
        try:
            return cls.from_arrays(arrays)
        except InputError as e:
            raise InputError(e.problem, path) from None

    def to_arrays(self) -> dict[str, np.ndarray]:
        """The rig as named arrays (``rmse`` and the settings as JSON text) for files and stores."""
        return {
            "rest_verts": self.rest_verts,
            "faces": self.faces,
            "weight_indices": self.weight_indices,
            "weight_values": self.weight_values,
            "bone_rest_positions": self.bone_rest_positions,
            "rmse": np.float64(self.rmse),
            "settings": np.array(json.dumps(self.settings)),
        }

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray]) -> "VirtualBoneRig":
        """The inverse of :meth:`to_arrays`."""
        needed = {"rest_verts", "faces", "weight_indices", "weight_values", "bone_rest_positions"}
        missing = sorted(needed - set(arrays))
        if missing:
            raise InputError(f"virtual bone rig is missing arrays {missing}")
        return cls(
            rest_verts=arrays["rest_verts"],
            faces=arrays["faces"],
            weight_indices=arrays["weight_indices"],
            weight_values=arrays["weight_values"],
            bone_rest_positions=arrays["bone_rest_positions"],
            rmse=float(arrays.get("rmse", np.nan)),
            settings=json.loads(str(arrays["settings"])) if "settings" in arrays else {},
        )


#: At most this many frames are skinned through the sparse weight table (:func:`sparse_weights`);
#: more go through one dense product, which is faster in bulk (bench dress, 80 bones, 8 influences,
#: one thread: one frame 0.55 ms sparse vs 1.03 ms dense; 600 frames 1.5 s sparse vs 0.31 s dense).
SPARSE_FRAMES = 4


def sparse_weights(weights: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """The non-zero part of dense skinning weights ``(V, B)``: bone indices ``(V, K)`` int64 and weights
    ``(V, K)``, ``K`` the most non-zero weights of any vertex (padding entries have weight 0)."""
    K = max(int((weights != 0).sum(-1).max()), 1)
    values, indices = weights.topk(K, -1)
    return indices, values


def skin_bones(
    rest_verts: torch.Tensor,
    weights: torch.Tensor,
    rotations: torch.Tensor,
    translations: torch.Tensor,
    sparse: tuple[torch.Tensor, torch.Tensor] | None = None,
) -> torch.Tensor:
    """Linear blend skinning by free bones (VirtualBones Eq. 1), any leading batch dimensions.

    Args:
        rest_verts: ``(V, 3)`` or ``(..., V, 3)`` rest mesh, metres.
        weights: ``(V, B)`` dense skinning weights.
        rotations: ``(..., B, 3, 3)`` bone rotations (rest to frame).
        translations: ``(..., B, 3)`` bone translations, metres.
        sparse: ``weights`` as :func:`sparse_weights` gives them; used (same result) when at most
            :data:`SPARSE_FRAMES` frames are skinned, the streaming case.

    Returns:
        ``(..., V, 3)`` skinned vertices.
    """
    if sparse is not None and rotations.shape[:-3].numel() <= SPARSE_FRAMES:
        indices, values = sparse
        transforms = torch.cat([rotations, translations[..., None]], -1).flatten(-2)  # (..., B, 12)
        picked = transforms.index_select(-2, indices.reshape(-1)).unflatten(-2, indices.shape)  # (..., V, K, 12)
        blend = (values[..., None] * picked).sum(-2).unflatten(-1, (3, 4))
        return (blend[..., :3] @ rest_verts[..., None])[..., 0] + blend[..., 3]  # VirtualBones Eq. 1
    blend_R = torch.einsum("vb,...bij->...vij", weights, rotations)
    blend_T = torch.einsum("vb,...bi->...vi", weights, translations)
    return (blend_R @ rest_verts[..., None])[..., 0] + blend_T  # VirtualBones Eq. 1


def _check_frames(frames, rest_verts, faces) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rest = np.asarray(rest_verts, np.float64)
    faces = np.asarray(faces, np.int64)
    if rest.ndim != 2 or rest.shape[1] != 3 or not np.isfinite(rest).all():
        raise InputError(f"rest mesh must be finite (V, 3), got shape {rest.shape}")
    if faces.ndim != 2 or faces.shape[1] != 3 or faces.min() < 0 or faces.max() >= len(rest):
        raise InputError(f"faces must be (F, 3) indices into {len(rest)} vertices")
    shape = tuple(getattr(frames, "shape", ()))
    if len(shape) != 3 or shape[1:] != rest.shape:
        raise InputError(f"frames must have shape (T, {len(rest)}, 3) like the rest mesh, got {shape}")
    if shape[0] == 0:
        raise InputError("no frames to decompose")
    return rest, faces, shape


def _native_solver(
    rest: np.ndarray,
    frames: np.ndarray,
    faces: np.ndarray,
    bones: int,
    influences: int,
    iterations: int,
    trans_affine: float,
    weight_smoothness: float,
    transform_iterations: int,
    weight_iterations: int,
):
    """A native Dem Bones solver loaded with one rest mesh and ``(T, V, 3)`` frames (float64)."""
    import py_dem_bones

    native = py_dem_bones.DemBones()
    native.transAffine = float(trans_affine)
    native.weightsSmooth = float(weight_smoothness)
    native.nTransIters = int(transform_iterations)
    native.nWeightsIters = int(weight_iterations)
    wrapper = py_dem_bones.DemBonesWrapper(native)
    wrapper.max_influences = int(influences)
    wrapper.num_iterations = int(iterations)
    # Validates the arrays and lays them out as Dem Bones wants ((3T, V) frames); keeps the options above.
    wrapper.set_mesh_sequence(rest, frames, bone_count=int(bones), faces=faces)
    return wrapper.native_solver


def _pack(rotations: np.ndarray, translations: np.ndarray) -> np.ndarray:
    """``(T, B, 3, 3)``, ``(T, B, 3)`` -> Dem Bones' ``(4T, 4B)`` column-vector transform blocks."""
    T, B = rotations.shape[:2]
    M = np.zeros((T, B, 4, 4))
    M[..., :3, :3] = rotations
    M[..., :3, 3] = translations
    M[..., 3, 3] = 1.0
    return np.ascontiguousarray(M.transpose(0, 2, 1, 3).reshape(4 * T, 4 * B))


def _unpack(blocks: np.ndarray, T: int, B: int) -> tuple[np.ndarray, np.ndarray]:
    M = np.asarray(blocks, np.float64).reshape(T, 4, B, 4).transpose(0, 2, 1, 3)
    return M[..., :3, :3], M[..., :3, 3]


def solve_frames(count: int, max_frames: int) -> np.ndarray:
    """Indices of at most ``max_frames`` frames evenly spread over ``count`` (all when fewer)."""
    if count <= max_frames:
        return np.arange(count)
    return np.unique(np.round(np.linspace(0, count - 1, max_frames)).astype(np.int64))


def fit_virtual_bones(
    frames,
    rest_verts: np.ndarray,
    faces: np.ndarray,
    bones: int = DEFAULT_BONES,
    influences: int = 8,
    iterations: int = 20,
    trans_affine: float = DEFAULT_TRANS_AFFINE,
    weight_smoothness: float = 1e-4,
    max_solve_frames: int = DEFAULT_MAX_SOLVE_FRAMES,
    threads: int = DEFAULT_THREADS,
) -> tuple[VirtualBoneRig, np.ndarray, np.ndarray]:
    """Decompose a mesh sequence into virtual bones by SSDR (Dem Bones).

    Args:
        frames: ``(T, V, 3)`` mesh sequence, metres (anything with ``.shape`` and NumPy fancy
            indexing on the first axis; only the weight-solve frames are read here).
        rest_verts: ``(V, 3)`` rest mesh the bones transform.
        faces: ``(F, 3)`` triangles (Dem Bones needs them to seed bones and smooth weights).
        bones: bones requested. Dem Bones seeds them by splitting vertex clusters and drops empty
            ones, so the rig may have fewer (bones that end with no weight are dropped too).
        influences: non-zero weights per vertex at most.
        iterations: alternating transform / weight iterations.
        trans_affine: Dem Bones' translation-affinity weight (see the module docstring).
        weight_smoothness: Dem Bones' Laplacian weight-smoothness term.
        max_solve_frames: frames used by the weight solve, evenly spread over ``T``.
        threads: OpenMP threads of the solver.

    Returns:
        ``(rig, rotations, translations)`` with ``rotations (S, B, 3, 3)`` and ``translations (S, B, 3)``
        float32 of the ``S`` weight-solve frames :func:`solve_frames` ``(T, max_solve_frames)``;
        ``rig.rmse`` is measured on those frames.
    """
    rest, faces, shape = _check_frames(frames, rest_verts, faces)
    if not 1 <= bones <= len(rest):
        raise InputError(f"bone count must be in [1, {len(rest)}], got {bones}")
    if influences < 1:
        raise InputError(f"influences per vertex must be at least 1, got {influences}")
    picked = solve_frames(shape[0], max_solve_frames)
    sample = np.asarray(frames[picked] if len(picked) < shape[0] else frames[:], np.float64)
    if not np.isfinite(sample).all():
        raise InputError("frames contain NaN or infinite vertices")
    solver = _native_solver(rest, sample, faces, bones, influences, iterations, trans_affine, weight_smoothness, 5, 3)
    with threadpool_limits(limits=int(threads), user_api="openmp"):
        solver.compute()
    W = np.asarray(solver.get_weights(), np.float64).T  # (V, B)
    R, T = _unpack(solver.m, len(picked), solver.nB)
    used = W.sum(0) > 0
    W, R, T = W[:, used], R[:, used], T[:, used]
    rig = _rig_from_dense(rest, faces, W, min(influences, W.shape[1]))
    rig.settings = {
        "bones_requested": int(bones),
        "influences": int(influences),
        "iterations": int(iterations),
        "trans_affine": float(trans_affine),
        "weight_smoothness": float(weight_smoothness),
        "max_solve_frames": int(max_solve_frames),
        "solve_frames": int(len(picked)),
        "frames": int(shape[0]),
    }
    recon = rig.skin(R, T)
    rig.rmse = float(np.sqrt(((recon - sample) ** 2).sum(-1).mean()))
    return rig, R.astype(np.float32), T.astype(np.float32)


def _rig_from_dense(rest: np.ndarray, faces: np.ndarray, W: np.ndarray, K: int) -> VirtualBoneRig:
    """Keep each vertex's ``K`` largest weights (Dem Bones already limits them), renormalised."""
    order = np.argsort(-W, axis=1, kind="stable")[:, :K]
    values = np.take_along_axis(W, order, 1)
    values = values / values.sum(1, keepdims=True)
    idx = np.where(values > 0, order, 0)
    totals = W.sum(0)
    centres = (W.T @ rest) / totals[:, None]
    return VirtualBoneRig(rest, faces, idx, values, centres)


def solve_bone_transforms(
    rig: VirtualBoneRig,
    frames,
    init_rotations: np.ndarray | None = None,
    init_translations: np.ndarray | None = None,
    iterations: int = 30,
    chunk: int = TRANSFORM_CHUNK,
    threads: int = DEFAULT_THREADS,
) -> tuple[np.ndarray, np.ndarray]:
    """Best rigid bone transforms for every frame with the rig's weights fixed (SSDR's transform step).

    Each frame is independent: Dem Bones updates one bone at a time in closed form (weighted
    absolute orientation against what the other bones leave unexplained), ``iterations`` sweeps.

    Args:
        rig: the rig (rest mesh and weights).
        frames: ``(T, V, 3)`` meshes, metres; read ``chunk`` frames at a time (Zarr arrays work).
        init_rotations, init_translations: ``(T, B, 3, 3)`` / ``(T, B, 3)`` starting transforms
            (default: every bone at the identity).
        iterations: bone sweeps per frame.
        chunk: frames per native solve.
        threads: OpenMP threads of the solver.

    Returns:
        ``rotations (T, B, 3, 3)`` and ``translations (T, B, 3)`` float32.
    """
    rest = np.asarray(rig.rest_verts, np.float64)
    _, faces, shape = _check_frames(frames, rest, rig.faces)
    Tn, B = shape[0], rig.num_bones
    if (init_rotations is None) != (init_translations is None):
        raise InputError("give both initial rotations and translations, or neither")
    if init_rotations is not None and (init_rotations.shape != (Tn, B, 3, 3) or init_translations.shape != (Tn, B, 3)):
        raise InputError(f"initial transforms must be ({Tn}, {B}, 3, 3) and ({Tn}, {B}, 3)")
    W = np.ascontiguousarray(rig.dense_weights().T.astype(np.float64))  # (B, V)
    # The same regularisation as the weight solve, so that every frame's transforms are alike.
    trans_affine = float(rig.settings.get("trans_affine", DEFAULT_TRANS_AFFINE))
    rotations = np.empty((Tn, B, 3, 3), np.float32)
    translations = np.empty((Tn, B, 3), np.float32)
    for start in range(0, Tn, chunk):
        stop = min(start + chunk, Tn)
        block = np.asarray(frames[start:stop], np.float64)
        if not np.isfinite(block).all():
            raise InputError(f"frames {start}-{stop - 1} contain NaN or infinite vertices")
        solver = _native_solver(rest, block, faces, B, rig.max_influences, 0, trans_affine, 0.0, iterations, 0)
        solver.set_weights(W)
        if init_rotations is None:
            R0 = np.broadcast_to(np.eye(3), (stop - start, B, 3, 3))
            T0 = np.zeros((stop - start, B, 3))
        else:
            R0, T0 = init_rotations[start:stop], init_translations[start:stop]
        solver.m = _pack(R0, T0)
        with threadpool_limits(limits=int(threads), user_api="openmp"):
            solver.computeTranformations()
        R, T = _unpack(solver.m, stop - start, B)
        rotations[start:stop], translations[start:stop] = R, T
    return rotations, translations


def frame_errors(rig: VirtualBoneRig, frames, rotations: np.ndarray, translations: np.ndarray) -> np.ndarray:
    """``(T,)`` float64 mean squared vertex error of each frame, m^2: ``mean_i |skin(t)_i - frames(t)_i|^2``.

    The RMSE over frames of one mesh is ``sqrt(mean(frame_errors(...)))``.
    """
    out = np.empty(len(rotations))
    for start in range(0, len(rotations), TRANSFORM_CHUNK):
        stop = min(start + TRANSFORM_CHUNK, len(rotations))
        skinned = rig.skin(rotations[start:stop], translations[start:stop]).astype(np.float64)
        err = skinned - np.asarray(frames[start:stop], np.float64)
        out[start:stop] = (err**2).sum(-1).mean(-1)
    return out

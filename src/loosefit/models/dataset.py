"""Training data of one garment for the per-garment methods (VirtualBones, JointNet, body-LBS).

Everything is expressed in the heading frame of each frame (:mod:`loosefit.models.motion_features`), or in
the frame the model asks for (:mod:`loosefit.motion.heading`): the networks see
heading-invariant motion features and predict canonical garment vertices; the canonical result is put back
in the world with the frame's rotation and origin.

A :class:`GarmentSequences` holds, in memory and per sequence of one garment and split: the motion
features, the heading frames, the canonical simulated vertices and their low-frequency part, the
canonical bone transforms of the virtual-bone rig (training sequences), and the canonical collision
proxy of the posed body with its vertex normals (for collision losses). :class:`WindowDataset` cuts it
into windows of consecutive frames for recurrent training with a burn-in (truncated back-propagation
through time: the first ``burn_in`` frames of a window only warm up the recurrent state).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from scipy.spatial import cKDTree
from torch.utils.data import Dataset

from loosefit.body import AnnyBody, AnnyShape
from loosefit.data.mirror import MIRRORED, GarmentMirror
from loosefit.data.store import DatasetStore
from loosefit.errors import InputError
from loosefit.geometry.normals import vertex_normals
from loosefit.geometry.smoothing import frequency_split
from loosefit.models.motion_features import MotionHistory, motion_features
from loosefit.motion.heading import motion_frames, to_canonical
from loosefit.motion.mirror import joint_partners, mirror_motion
from loosefit.motion.motion import Motion
from loosefit.rig.prepared import load_bone_transforms, prepared_split


#: Smallest std used to normalise each feature group: root features mix metres per frame and radians
#: (1 cm / 0.01 rad), joint features are 6D rotation entries (0.05 ~ 3 degrees).
STD_FLOOR = {"root": 0.01, "joints": 0.05}


@dataclass
class SequenceData:
    """One simulated sequence, canonical (see the module doc). Shapes for ``T`` frames, ``V`` garment
    vertices, ``B`` bones, ``J`` joints, ``Vb`` proxy body vertices; float32 unless noted.

    Attributes:
        name, motion_name, body_name: store names. sim_params: the simulation parameters (JSON).
        motion: the :class:`Motion` (world). root ``(T, R)`` (R = 11, or more with a
        :class:`MotionHistory`; :func:`motion_features`), joints ``(T, J-1, 6)``: motion features.
        frame_rot ``(T, 3, 3)`` float64, frame_origin ``(T, 3)`` float64: the frames (:mod:`loosefit.motion.heading`).
        verts ``(T, V, 3)``: canonical simulated garment. lf ``(T, V, 3)``: its low-frequency part.
        bone_rot ``(T, B, 3, 3)``, bone_trans ``(T, B, 3)``: canonical virtual-bone transforms, or None.
        body ``(T, Vb, 3)``, body_normals ``(T, Vb, 3)``: canonical collision proxy, or None.
        body_nearest ``(T, V)`` int64: the proxy vertex nearest to each simulated garment vertex, or None.
    """

    name: str
    motion_name: str
    body_name: str
    sim_params: dict
    motion: Motion
    root: np.ndarray
    joints: np.ndarray
    frame_rot: np.ndarray
    frame_origin: np.ndarray
    verts: np.ndarray
    lf: np.ndarray
    bone_rot: np.ndarray | None
    bone_trans: np.ndarray | None
    body: np.ndarray | None
    body_normals: np.ndarray | None
    body_nearest: np.ndarray | None

    @property
    def num_frames(self) -> int:
        return self.verts.shape[0]


def canonical_bones(rot: np.ndarray, trans: np.ndarray, frame_rot: np.ndarray, frame_origin: np.ndarray):
    """World bone transforms ``x -> R x + T`` ``(T,B,3,3)``, ``(T,B,3)`` -> canonical ones, float32."""
    Rt = np.transpose(frame_rot, (0, 2, 1))[:, None]  # (T, 1, 3, 3)
    return (Rt @ rot).astype(np.float32), np.einsum("tbij,tbj->tbi", Rt, trans - frame_origin[:, None]).astype(np.float32)


class GarmentSequences:
    """All sequences of one garment in a split, loaded and canonicalised.

    Args:
        store: a :class:`DatasetStore` or its path.
        garment: garment name.
        split: ``"train"``, ``"val"``, ``"test"`` or None (all).
        sim_params: keep only sequences simulated with exactly these parameters (None: all).
        bones: load the rig's bone transforms (training sequences of a prepared store).
        body: load the canonical collision proxy of the posed body.
        names: restrict to these sequence names.
        history: the motion's history among the root features (:class:`MotionHistory`; None: none).
        mirror: also hold the left-right mirror of every sequence (:mod:`loosefit.data.mirror`: the motion mirrored,
            the simulated garment read back through the garment's mirror correspondence), named
            ``<sequence>=mirrored``; with ``bones``, the store must be prepared with ``mirror``.
        frame: the frame the garment is expressed in (:data:`~loosefit.motion.heading.FRAMES`).
    """

    def __init__(self, store, garment: str, split: str | None = "train", sim_params: dict | None = None,
                 bones: bool = True, body: bool = True, names: list[str] | None = None, smoothing: str | None = None,
                 history: MotionHistory | None = MotionHistory(), mirror: bool = False, frame: str = "heading"):
        self.history, self.frame = history, frame
        self.store = store if isinstance(store, DatasetStore) else DatasetStore.open(store, mode="r")
        if garment not in self.store.garment_names():
            raise InputError(f"no garment {garment!r} in the store (has {self.store.garment_names()})", self.store.path)
        self.garment_name = garment
        self.garment = self.store.garment(garment)
        self.faces = self.garment.faces
        # the split follows the rig's settings in every split, with or without bone transforms
        self.rig_settings, prepared_smoothing, self.fixed = prepared_split(self.store, garment)
        self.smoothing = smoothing or prepared_smoothing
        selected = [
            n for n in self.store.sequence_names(split=split)
            if self.store.sequence(n).garment == garment
            and (names is None or n in names)
            and (sim_params is None or self.store.sequence(n).sim_params == sim_params)
        ]
        if not selected:
            raise InputError(f"no {split or 'usable'} sequences of garment {garment!r} match", self.store.path)
        self.sequences = [self._load(n, bones, body) for n in selected]
        if mirror:
            self._mirror = GarmentMirror.build(self.garment.verts, self.faces)
            self.sequences += [self._load(n, bones, body, mirrored=True) for n in selected]

    def _load(self, name: str, bones: bool, body: bool, mirrored: bool = False) -> SequenceData:
        seq = self.store.sequence(name)
        motion = self.store.motion(seq.motion)
        world = np.asarray(seq.verts[:], np.float32)
        shape = AnnyShape.from_array(self.store.body(seq.body))
        proxy = AnnyBody(shape, resolution="low") if body or mirrored else None
        if mirrored:
            motion = mirror_motion(motion, joint_partners(proxy.joint_names, proxy.rest_joints()))
            world, name = self._mirror(world), name + MIRRORED
        rot, origin = motion_frames(motion, self.frame)
        verts = to_canonical(world, rot, origin)
        lf = frequency_split(verts, self.faces, self.smoothing, fixed=self.fixed)[0].astype(np.float32)
        feats = motion_features(motion, self.history)
        bone_rot = bone_trans = None
        if bones:
            bone_rot, bone_trans = canonical_bones(*load_bone_transforms(self.store, self.garment_name, name), rot, origin)
        body_c = body_n = nearest = None
        if body:
            posed = proxy.pose(motion)
            body_c = to_canonical(posed.verts, rot, origin)
            body_n = vertex_normals(body_c, proxy.faces).astype(np.float32)
            nearest = np.stack([cKDTree(b).query(v)[1] for b, v in zip(body_c, verts)]).astype(np.int64)
        return SequenceData(name, seq.motion + (MIRRORED if mirrored else ""), seq.body, seq.sim_params, motion,
                            feats["root"], feats["joints"], rot, origin, verts, lf, bone_rot, bone_trans, body_c,
                            body_n, nearest)

    def feature_stats(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """Mean and std of ``root (R,)`` (R root features, with the history) and ``joints (J-1, 6)`` over all frames.

        The std is floored (:data:`STD_FLOOR`): joints that barely move in the training motions (hands,
        toes) would otherwise turn any new motion into huge normalised inputs.
        """
        out = {}
        for key in ("root", "joints"):
            x = np.concatenate([getattr(s, key) for s in self.sequences]).astype(np.float64)
            out[key] = (x.mean(0).astype(np.float32), np.maximum(x.std(0), STD_FLOOR[key]).astype(np.float32))
        return out


#: The per-frame arrays of a sequence that a training window carries (those a sequence has: None ones are left out).
FRAME_KEYS = ("root", "joints", "verts", "lf", "bone_rot", "bone_trans", "body", "body_normals", "body_nearest")


def window_arrays(seq: "SequenceData", start: int, stop: int, pad: int = 0) -> dict[str, torch.Tensor]:
    """Frames ``start:stop`` of each of ``seq``'s :data:`FRAME_KEYS` arrays as tensors, the last frame repeated
    ``pad`` more times (finite inputs for frames that carry no loss)."""
    out = {}
    for key in FRAME_KEYS:
        value = getattr(seq, key)
        if value is not None:
            part = value[start:stop]
            if pad:
                part = np.concatenate([part, np.repeat(part[-1:], pad, 0)])
            out[key] = torch.from_numpy(np.ascontiguousarray(part))
    return out


class WindowDataset(Dataset):
    """Windows of ``window`` consecutive frames, starting every ``stride`` frames (frame 0 always
    included, so training sees the zero initial state used at inference). A window shorter than
    ``window`` is kept at the end of a sequence only if it has at least ``burn_in + 1`` frames.

    Each item is a dict of tensors: ``root (w, 11)``, ``joints (w, J-1, 6)``, ``verts (w, V, 3)``,
    ``lf (w, V, 3)``, optional ``bone_rot (w, B, 3, 3)``, ``bone_trans (w, B, 3)``, ``body (w, Vb, 3)``,
    ``body_normals (w, Vb, 3)``, ``body_nearest (w, V)``, and ``burn_in`` (int: frames without loss at the start, 0 for a window
    starting at frame 0), ``sequence`` (index), ``start`` (frame).
    """

    def __init__(self, data: GarmentSequences, window: int = 64, stride: int = 32, burn_in: int = 16):
        if window <= burn_in:
            raise InputError(f"window ({window}) must be longer than burn_in ({burn_in})")
        self.data, self.window, self.burn_in = data, window, burn_in
        self.index = []
        for i, s in enumerate(data.sequences):
            starts = list(range(0, max(s.num_frames - window, 0) + 1, stride))
            if starts[-1] + window < s.num_frames:
                starts.append(s.num_frames - window)
            self.index += [(i, a) for a in starts if s.num_frames - a > burn_in]

    def __len__(self) -> int:
        return len(self.index)

    def __getitem__(self, k: int) -> dict:
        i, a = self.index[k]
        s = self.data.sequences[i]
        b = min(a + self.window, s.num_frames)
        return {"sequence": i, "start": a, "burn_in": 0 if a == 0 else self.burn_in, **window_arrays(s, a, b)}

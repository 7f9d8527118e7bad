"""Body-motion features for the networks, in a heading-invariant canonical frame.

Garment networks must not have to learn every heading and position of the body separately: a spin
is a spin whichever way the body faces. So the garment and the body are expressed in the *heading
frame* of each frame ``t``: origin under the root joint on the floor plane, rotated about Z by the
root's heading (yaw) ``psi_t`` so that the body faces -Y, as at rest::

    F_t = [Rz(psi_t) | (x_t, y_t, 0)]          canonical point  p_c = Rz(psi_t)^T (p - (x_t, y_t, 0))

The per-frame motion features (all in the heading frame of that frame) are:

- ``root`` ``(T, 11)``: root height (m), root displacement since the previous frame (m, 3), heading
  change since the previous frame (rad, 1, wrapped to (-pi, pi]), root orientation without its
  heading (6D, 6). Frame 0 has zero displacement and heading change (the simulator starts from rest).
- ``joints`` ``(T, J-1, 6)``: the local rotation of every non-root joint, 6D (continuous, unlike axis-angle).

With a :class:`MotionHistory` (the per-garment methods, ours; not in the papers) ``root`` is ``(T, 11 + C K)`` for
``K`` time constants (frames; by default :data:`HISTORY_FRAMES`, ``(T, 20)``): the 11 above, then for each time
constant ``tau`` the exponential moving average of the heading change (rad per frame, 1) and of the horizontal
root displacement (m per frame, 2), the latter averaged in the world and expressed in frame ``t``'s heading
frame, and with ``vertical`` also of the vertical root displacement (m per frame, 1; ``C`` = 4, else 3)::

    m_t = a m_{t-1} + (1 - a) x_t,   a = exp(-1 / tau),   m_{-1} = 0

They say how fast and which way the body has been turning and moving over the last fraction of a second (and,
with ``vertical``, rising or falling), the motion a loose skirt still carries (it lags the body). A recurrent
network can learn such filters itself; given them, VirtualBones generalised better to a held-out spin
(``benchmarks/experiments/LOG.md``, "Motion history").

Streaming use: :class:`FeatureStream` computes the same features one frame at a time.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch

from loosefit.errors import InputError
from loosefit.geometry.lbs import forward_kinematics, linear_blend_skinning, skinning_transforms
from loosefit.geometry.rotations import axis_angle_to_matrix, matrix_to_sixd, sixd_to_matrix
from loosefit.motion.heading import heading_angles, rot_z
from loosefit.motion.motion import Motion

#: Root features without history.
ROOT_FEATURES = 11
#: The default time constants of the history features, in frames (at 30 fps: 0.2, 0.5 and 1 s).
HISTORY_FRAMES = (6.0, 15.0, 30.0)
#: Root features with the default history: three values per time constant.
HISTORY_ROOT_FEATURES = ROOT_FEATURES + 3 * len(HISTORY_FRAMES)


def check_history(history: Sequence[float]) -> tuple[float, ...]:
    """Time constants ``history`` (frames) as a tuple of floats; each must be a finite number of at least one
    frame (a shorter average is the current frame's value)."""
    frames = tuple(float(tau) for tau in history)
    bad = [tau for tau in frames if not (np.isfinite(tau) and tau >= 1.0)]
    if bad:
        raise InputError(f"history time constants must be finite and at least 1 frame, got {list(frames)}")
    return frames


@dataclass(frozen=True)
class MotionHistory:
    """The motion history among the root features (module doc): the moving averages' time constants ``frames``
    (frames, at least one) and whether the vertical root displacement is averaged too (``vertical``)."""

    frames: tuple[float, ...] = HISTORY_FRAMES
    vertical: bool = False

    def __post_init__(self):
        frames = check_history(self.frames)
        if not frames:
            raise InputError("a motion history needs at least one time constant (no history: None)")
        object.__setattr__(self, "frames", frames)

    @property
    def channels(self) -> int:
        """Averaged values per time constant: heading change, horizontal displacement (2), vertical (1)."""
        return 4 if self.vertical else 3

    @property
    def root_features(self) -> int:
        """How many root features :func:`motion_features` gives with this history."""
        return ROOT_FEATURES + self.channels * len(self.frames)


def _wrap(angle: np.ndarray) -> np.ndarray:
    return (angle + np.pi) % (2 * np.pi) - np.pi


def motion_features(motion: Motion, history: MotionHistory | None = None) -> dict[str, np.ndarray]:
    """Features of a whole motion: ``root (T, R)`` (``R`` = 11, or ``history.root_features``) and ``joints
    (T, J-1, 6)`` float32 (see module doc)."""
    R = axis_angle_to_matrix(torch.from_numpy(motion.rotations).double())  # (T, J, 3, 3)
    return _features(R, motion.translation.astype(np.float64), history=_Averages.start(history))[0]


class _Averages:
    """The moving averages of a :class:`MotionHistory`: decay ``a (K, 1)`` per time constant and the averages
    ``state (K, C)`` (heading change, world x, y and, with ``vertical``, z) after the last frame seen."""

    def __init__(self, history: MotionHistory):
        self.a = np.exp(-1.0 / np.asarray(history.frames, np.float64))[:, None]
        self.state = np.zeros((len(history.frames), history.channels))  # zero before a motion's first frame

    @classmethod
    def start(cls, history: MotionHistory | None) -> "_Averages | None":
        """The averages before a motion's first frame, or None without history."""
        return None if history is None else cls(history)


def _features(R: torch.Tensor, trans: np.ndarray, before: tuple[np.ndarray, float] | None = None,
              history: _Averages | None = None):
    """Features of frames with joint rotations ``R (T, J, 3, 3)`` (float64) and root positions ``trans
    (T, 3)``; ``before`` is the root position and heading of the frame before the first (``None``: the
    first frame is the motion's first, with no displacement). ``history``: None (no history features) or the
    moving averages after the frame before the first, updated in place. Also returns the frames' heading
    rotations ``(T, 3, 3)`` and headings ``(T,)``."""
    root_rot = R[:, 0].numpy()
    psi = heading_angles(root_rot)
    Rh = rot_z(psi)
    prev_trans, prev_psi = (trans[:1], psi[:1]) if before is None else (before[0][None], np.array([before[1]]))
    disp = trans - np.concatenate([prev_trans, trans[:-1]])
    dpsi = _wrap(psi - np.concatenate([prev_psi, psi[:-1]]))
    tilt = Rh.transpose(0, 2, 1) @ root_rot  # heading removed: Rz(psi)^T R_root
    parts = [trans[:, 2:3], (disp[:, None] @ Rh)[:, 0], dpsi[:, None], matrix_to_sixd(torch.from_numpy(tilt)).numpy()]
    if history is not None:
        x = np.concatenate([dpsi[:, None], disp], 1)[:, : history.state.shape[1]]  # the vertical with 4 channels
        parts.append(_history(x, Rh, history))
    joints = matrix_to_sixd(R[:, 1:]).numpy()
    return {"root": np.concatenate(parts, 1).astype(np.float32), "joints": joints.astype(np.float32)}, Rh, psi


def _history(x: np.ndarray, Rh: np.ndarray, averages: _Averages) -> np.ndarray:
    """The history features ``(T, C K)`` of per-frame ``x (T, C)`` (heading change, world displacement x, y and
    with ``C`` = 4 z), from the averages after the frame before (updated in place): per time constant, the averaged
    heading change, the averaged horizontal displacement turned into each frame's heading frame, and the averaged
    vertical displacement (the same in every heading frame)."""
    a, state = averages.a, averages.state
    out = np.empty((len(x), len(a), state.shape[1]))
    for t in range(len(x)):
        state *= a
        state += (1.0 - a) * x[t]
        out[t] = state
        out[t, :, 1:3] = state[:, 1:3] @ Rh[t, :2, :2]  # world -> heading frame: v R (R^T v)
    return out.reshape(len(x), -1)


class FeatureStream:
    """Motion features one frame at a time, equal to :func:`motion_features` (with the same ``history``) on
    the whole motion.

    ``step(rotations (J, 3), translation (3,))`` returns ``root (R,)`` (``R`` = 11, or ``history.root_features``),
    ``joints (J-1, 6)`` and the frame's heading frame ``(rot (3, 3), origin (3,))``.
    """

    def __init__(self, history: MotionHistory | None = None):
        self._before: tuple[np.ndarray, float] | None = None  # the previous frame's root position and heading
        self._history = _Averages.start(history)  # the averages so far

    def step(self, rotations: np.ndarray, translation: np.ndarray):
        rotations = np.asarray(rotations, np.float32)
        trans = np.asarray(translation, np.float32).astype(np.float64).reshape(1, 3)
        if not (np.isfinite(rotations).all() and np.isfinite(trans).all()):
            raise InputError("motion frame contains NaN or infinite values")
        R = axis_angle_to_matrix(torch.from_numpy(rotations[None]).double())
        feats, Rh, psi = _features(R, trans, self._before, self._history)
        self._before = (trans[0], float(psi[0]))
        origin = trans[0].copy()
        origin[2] = 0.0
        return feats["root"][0], feats["joints"][0], (Rh[0], origin)


def skin_from_features(template: torch.Tensor, weights: torch.Tensor, rest_joints: torch.Tensor, parents,
                       root: torch.Tensor, joints: torch.Tensor, frame: str = "heading"):
    """Rest points ``template (K, 3)`` skinned with ``weights (K, J)`` to the body posed from raw features alone,
    ``root (..., R)``, ``joints (..., J-1, 6)``, in a model's canonical ``frame``: the root joint at height
    ``root[..., 0]`` above the origin with the root's tilt (heading), at the origin with its tilt (raised), at the
    origin unrotated (pelvis). Returns ``(verts (..., K, 3), world (..., J, 4, 4))`` metres, the joints' transforms."""
    lead = root.shape[:-1]
    tilt = root[..., None, 5:11]
    if frame == "pelvis":
        tilt = torch.tensor([1.0, 0, 0, 0, 1, 0], dtype=root.dtype, device=root.device).expand_as(tilt)
    local = sixd_to_matrix(torch.cat([tilt, joints], -2)).reshape(-1, len(parents), 3, 3)
    height = root[..., 0].reshape(-1) * (1.0 if frame == "heading" else 0.0)
    origin = torch.stack([torch.zeros_like(height), torch.zeros_like(height), height], -1)
    world = forward_kinematics(local, origin, rest_joints, parents)
    verts = linear_blend_skinning(template, weights, skinning_transforms(world, rest_joints))
    return verts.reshape(*lead, -1, 3), world.reshape(*lead, -1, 4, 4)

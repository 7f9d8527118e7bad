"""The BodyModel interface every body (Anny, SMPL, SMPL-X) implements."""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np
import torch

from loosefit.errors import InputError
from loosefit.geometry.lbs import pose_skeleton_and_skin
from loosefit.motion.motion import Motion


@dataclass
class PosedBody:
    """A posed body sequence.

    Attributes:
        verts: ``(T, V, 3)`` float32 vertex positions, metres.
        joint_transforms: ``(T, J, 4, 4)`` float32 world transforms of the joints: accumulated
            rotation (identity at rest) and posed joint position.
        faces: ``(F, 3)`` int64 triangles.
    """

    verts: np.ndarray
    joint_transforms: np.ndarray
    faces: np.ndarray

    @property
    def joints(self) -> np.ndarray:
        """``(T, J, 3)`` posed joint positions, metres."""
        return self.joint_transforms[..., :3, 3]


class BodyModel(ABC):
    """A skinned body with a named rig, posed by :class:`~loosefit.motion.Motion`.

    Subclasses give the rest geometry for a shape; posing is shared (forward kinematics in the
    rig convention of :mod:`loosefit.geometry.lbs`, then linear blend skinning).
    ``shape`` is model specific (Anny: :class:`~loosefit.body.anny_body.AnnyShape`; SMPL: betas);
    ``None`` means the body's own shape.
    """

    name: str
    rig: str
    joint_names: list[str]
    parents: np.ndarray  # (J,) int64, -1 for the root
    faces: np.ndarray  # (F, 3) int64

    _weights: np.ndarray  # (V, J) float32 skinning weights, set by subclasses

    @abstractmethod
    def _rest_geometry(self, shape) -> tuple[np.ndarray, np.ndarray]:
        """Rest vertices ``(V, 3)`` and joints ``(J, 3)`` float32 for ``shape`` (cached by subclasses)."""

    def rest_verts(self, shape=None) -> np.ndarray:
        """``(V, 3)`` float32 rest-pose vertices, metres, Z up, feet on ``z = 0``."""
        return self._rest_geometry(shape)[0]

    def rest_joints(self, shape=None) -> np.ndarray:
        """``(J, 3)`` float32 rest-pose joint positions, metres, in the frame of :meth:`rest_verts`."""
        return self._rest_geometry(shape)[1]

    def skinning_weights(self) -> np.ndarray:
        """``(V, J)`` float32 skinning weights, rows summing to 1."""
        return self._weights

    @property
    def num_joints(self) -> int:
        return len(self.joint_names)

    @property
    def num_verts(self) -> int:
        return self.rest_verts().shape[0]

    def rest_root_position(self, shape=None) -> np.ndarray:
        """``(3,)`` the root joint's rest position: the ``Motion.translation`` of standing still."""
        return self.rest_joints(shape)[0].copy()

    def check_motion(self, motion: Motion) -> None:
        """Raise a clear error when ``motion`` is not on this body's rig."""
        if motion.rig != self.rig:
            raise InputError(f"motion {motion.name!r} is on rig {motion.rig!r}, body {self.name} uses {self.rig!r}")
        if motion.joint_names and list(motion.joint_names) != list(self.joint_names):
            missing = sorted(set(self.joint_names) - set(motion.joint_names))
            extra = sorted(set(motion.joint_names) - set(self.joint_names))
            raise InputError(
                f"motion {motion.name!r} joints do not match rig {self.rig!r}: missing {missing}, unknown {extra}"
                if missing or extra
                else f"motion {motion.name!r} joints are in a different order than rig {self.rig!r}"
            )
        if motion.num_joints != self.num_joints:
            raise InputError(f"motion {motion.name!r} has {motion.num_joints} joints, rig {self.rig!r} has {self.num_joints}")

    def pose(self, motion: Motion, shape=None, batch: int = 128) -> PosedBody:
        """Pose the body along a motion.

        Args:
            motion: a Motion on this body's rig, ``T`` frames.
            shape: body shape, ``None`` for the body's own.
            batch: frames skinned at once (bounds memory: ``batch * V * 48`` bytes).

        Returns:
            :class:`PosedBody` with ``verts (T, V, 3)`` and ``joint_transforms (T, J, 4, 4)``.
        """
        self.check_motion(motion)
        rest_v = torch.from_numpy(self.rest_verts(shape))
        rest_j = torch.from_numpy(self.rest_joints(shape))
        weights = torch.from_numpy(self.skinning_weights())
        rot = torch.from_numpy(motion.rotations)
        trans = torch.from_numpy(motion.translation)
        verts, world = [], []
        with torch.no_grad():
            for s in range(0, motion.num_frames, batch):
                v, w = pose_skeleton_and_skin(rot[s : s + batch], trans[s : s + batch], rest_j, self.parents, rest_v, weights)
                verts.append(v)
                world.append(w)
        return PosedBody(
            verts=torch.cat(verts).numpy().astype(np.float32),
            joint_transforms=torch.cat(world).numpy().astype(np.float32),
            faces=self.faces,
        )

    def rest_motion(self, num_frames: int = 1, fps: float = 30.0, shape=None) -> Motion:
        """A motion standing still in the rest pose for ``num_frames`` frames."""
        return Motion(
            rotations=np.zeros((num_frames, self.num_joints, 3), np.float32),
            translation=np.repeat(self.rest_root_position(shape)[None], num_frames, 0),
            fps=fps,
            rig=self.rig,
            joint_names=self.joint_names,
            name="rest",
        )

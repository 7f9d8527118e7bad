"""Neural collision handling (SwinGar Sec. III-D): a learned body signed distance field and the step that
moves garment vertices out of the body (SwinGar Eq. 10), with the exact and push-out references.

Sign convention: loosefit's (:mod:`loosefit.geometry.signed_distance`): negative inside the body, the gradient
pointing outwards.

- :mod:`~loosefit.models.collision.network`: the network ``S(x | code)`` (:class:`BodySDFNet`), its body codes
  and bone frames, its file.
- :mod:`~loosefit.models.collision.fast_eval`: its evaluation and gradient written out for inference
  (:class:`BoundBodySDF`, :class:`MotionBodySDF`, :class:`FramedSDF`).
- :mod:`~loosefit.models.collision.resolver`: SwinGar Eq. 10 (:class:`CollisionResolver`) and loosefit's surface
  pass beyond it (the body through a triangle or an edge between vertices), the push-out baseline and
  the exact field.
- :mod:`~loosefit.models.collision.handling`: the correction of a frame or a whole motion
  (:func:`handle_motion_collisions`).
- :mod:`~loosefit.models.collision.training`: training samples, SwinGar Eqs. 8-9, training, the margin's
  calibration and the run folder of ``loosefit train --method collision``.

Every public name of these modules is importable from this package.
"""

from loosefit.models.collision.fast_eval import (BoundBodySDF, FramedSDF, MotionBodySDF, flushed_denormals,
                                                 sdf_and_gradient, value_and_gradient_fn)
from loosefit.models.collision.network import (SOFTPLUS_BETA, BodySDFConfig, BodySDFNet, SDFFunction, body_code,
                                               bone_frame_code, bone_local_points, fold_bone_frames, load_body_sdf,
                                               motion_sdf_inputs, posed_joints, save_body_sdf)
from loosefit.models.collision.handling import (CULL_CELL, FRAME_CHUNK, POST_PROCESSES, PROXY_INFLATE,
                                                check_post_process, correct_exact_motion, correct_frame,
                                                correct_motion, handle_motion_collisions, inflated, post_process)
from loosefit.models.collision.resolver import (SURFACE_PASSES, SURFACE_TOLERANCE, CollisionResolver,
                                                ExactMotionSDF, ExactSDF, push_out, resolve_collisions,
                                                surface_sample_weights, vertex_neighbours)
from loosefit.models.collision.training import (CALIBRATION_QUANTILE, EIKONAL_WEIGHT, SDF_FILE, SDF_META,
                                                SDFRunConfig, SDFTrainConfig, body_sdf_samples, calibrate_margin,
                                                calibrate_sdf_run, calibration_set, collision_margin,
                                                random_anny_shapes, random_procedural_motions, samples_code,
                                                sdf_loss, sdf_samples, train_body_sdf, train_sdf_run)

__all__ = [
    # network
    "SOFTPLUS_BETA", "SDFFunction", "BodySDFConfig", "BodySDFNet", "bone_local_points", "fold_bone_frames",
    "bone_frame_code", "body_code", "motion_sdf_inputs", "posed_joints", "save_body_sdf", "load_body_sdf",
    # fast_eval
    "BoundBodySDF", "MotionBodySDF", "FramedSDF", "flushed_denormals", "sdf_and_gradient", "value_and_gradient_fn",
    # resolver
    "ExactSDF", "ExactMotionSDF", "vertex_neighbours", "CollisionResolver", "resolve_collisions", "push_out",
    "SURFACE_PASSES", "SURFACE_TOLERANCE", "surface_sample_weights",
    # handling
    "CULL_CELL", "correct_frame", "FRAME_CHUNK", "correct_motion", "correct_exact_motion",
    "handle_motion_collisions", "PROXY_INFLATE",
    "inflated", "POST_PROCESSES", "check_post_process", "post_process",
    # training
    "EIKONAL_WEIGHT", "sdf_loss", "sdf_samples", "SDFTrainConfig", "random_anny_shapes", "random_procedural_motions",
    "body_sdf_samples", "samples_code", "train_body_sdf", "SDF_FILE", "SDF_META", "CALIBRATION_QUANTILE",
    "calibrate_margin", "calibration_set", "calibrate_sdf_run", "collision_margin", "SDFRunConfig", "train_sdf_run",
]

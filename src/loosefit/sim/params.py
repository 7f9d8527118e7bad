"""Cloth simulation parameters: a typed config in physical units, loaded from YAML with overrides.

Fabric properties are physical and independent of the garment's mesh resolution; each backend
converts them per mesh (see :func:`loosefit.sim.blender.cloth_settings` and
:func:`loosefit.sim.newton.material`). The three
parameters varied by the VirtualBones paper map onto ``bending`` (bending stiffness), ``density``
(mass density) and ``time_scale``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from loosefit.config import apply_overrides, config_from_dict, load_yaml, read_yaml_text
from loosefit.errors import InputError

COLLIDERS = ("proxy", "full")
BACKENDS = ("blender", "newton")


@dataclass(frozen=True)
class SimParams:
    """Parameters of one cloth simulation.

    Attributes:
        density: areal mass density, kg/m^2 (silk ~0.05, cotton ~0.15, denim ~0.4).
        tension: stretch stiffness, N/m (force per unit width for unit strain). Woven cotton measures
            10^3-10^4 N/m, but Blender's implicit solver stops its linear solve at 1 % residual, and the
            stiffer the springs against the vertex masses, the larger that error per step: at 3000 N/m a
            10-micrometre change of the start state moved a 4 s walk by 114 mm, at 300 N/m by 37 mm
            (``benchmarks/chaos.py``), at 100 N/m by 32 mm. 100 N/m stretches a 0.55 m skirt by under
            1 % under its own weight.
        compression: compression stiffness, N/m. Cloth buckles instead of compressing, so a tenth of
            the tension: stiff compression with weak bending crumples like paper.
        shear: in-plane shear stiffness, N/m.
        bending: bending rigidity, N*m (silk ~1e-6, cotton ~1e-5, denim ~1e-4).
        stretch_damping: damping of stretch, compression and shear velocities, 1/s (a relative
            velocity along a spring decays at this rate).
        bending_damping: damping of folding velocities, 1/s. 20 takes the energy out of fold flutter
            without slowing the swing, which is what air drag alone would do.
        air_drag: linear air drag per unit area, N*s/m^3. Air's quadratic drag on cloth moving at
            about 1 m/s, linearised, is about 0.6 (air density 1.2 kg/m^3, drag coefficient about 1). Drag
            makes the swing repeatable (4 s walk, start-state spread: 37 mm at 0.05, 16 mm at 1.0) but at
            1.0 a 0.15 kg/m^2 skirt loses its velocity in 0.15 s and wraps round the legs on a spin
            instead of flaring; 0.3 with bending damping 20 keeps the bell (``benchmarks/README.md``).
        quality: solver steps per frame (the fewest, with ``adaptive_quality``); Newton: substeps.
        adaptive_quality: raise the steps per frame so that the body near the garment moves at most
            two collision distances per step with Blender, 0.75 with Newton (whose contact lets a
            body triangle that passes a cloth vertex within one step through;
            :func:`loosefit.sim.collider.steps_per_frame`).
        collision_quality: collision iterations per solver step.
        collision_distance: distance kept between cloth and body, m.
        friction: cloth-body friction (Blender's 0-80 scale). Kept low: with the other defaults and the
            body moved away, the start-state spread of a 4 s walk is under 1 mm, so the contact with the
            legs is what still amplifies small differences.
        self_collision: resolve cloth-cloth contacts (slower).
        self_collision_distance: distance kept between cloth layers, m.
        time_scale: simulated seconds per real second (1 = real time; smaller = slower, heavier-looking).
        preroll: seconds during which the body blends from the rest pose into the first motion
            frame and the cloth settles; not stored.
        collider: body mesh Blender collides with: ``"proxy"`` (1,229 vertices inflated to enclose
            the full body, fast; :mod:`loosefit.sim.collider`) or ``"full"``.
        gravity: m/s^2, along -Z.
        backend: the cloth simulator: ``"blender"`` (:mod:`loosefit.sim.blender`) or ``"newton"``
            (NVIDIA Newton's VBD solver, :mod:`loosefit.sim.newton`; needs ``pip install newton``).
    """

    density: float = 0.15
    tension: float = 100.0
    compression: float = 10.0
    shear: float = 100.0
    bending: float = 1e-5
    stretch_damping: float = 200.0
    bending_damping: float = 20.0
    air_drag: float = 0.3
    quality: int = 5
    adaptive_quality: bool = True
    collision_quality: int = 2
    collision_distance: float = 0.004
    friction: float = 1.0
    self_collision: bool = False
    self_collision_distance: float = 0.004
    time_scale: float = 1.0
    preroll: float = 1.0
    collider: str = "proxy"
    gravity: float = 9.81
    backend: str = "blender"

    def __post_init__(self):
        # Types, YAML parsing ("1e-5" as a number) and overrides are loosefit.config's; here the ranges.
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if f.type == "bool":
                if not isinstance(value, bool):
                    raise InputError(f"simulation parameter {f.name}={value!r} must be true or false")
            elif f.type == "int":
                if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                    raise InputError(f"simulation parameter {f.name}={value!r} must be a positive integer")
            elif f.type == "float":
                number = isinstance(value, (int, float)) and not isinstance(value, bool)
                if not number or not 0 <= value < float("inf"):
                    raise InputError(f"simulation parameter {f.name}={value!r} must be a finite number >= 0")
                object.__setattr__(self, f.name, float(value))
        for name in ("density", "tension", "time_scale"):
            if getattr(self, name) <= 0:
                raise InputError(f"simulation parameter {name} must be > 0, got {getattr(self, name)}")
        if self.collider not in COLLIDERS:
            raise InputError(f"simulation parameter collider={self.collider!r} must be one of {list(COLLIDERS)}")
        if self.backend not in BACKENDS:
            raise InputError(f"simulation parameter backend={self.backend!r} must be one of {list(BACKENDS)}")
        if self.backend == "newton":
            from loosefit.sim.newton import check_installed

            check_installed()

    @classmethod
    def names(cls) -> list[str]:
        return [f.name for f in dataclasses.fields(cls)]

    @classmethod
    def from_dict(cls, values: dict[str, Any] | None, source: str | Path | None = None) -> "SimParams":
        """Build from a mapping (:func:`loosefit.config.config_from_dict`); unknown keys and bad values raise
        :class:`InputError` naming ``source``."""
        unknown = sorted(set(values or {}) - set(cls.names()))
        if unknown:
            raise InputError(f"unknown simulation parameters {unknown}; known: {cls.names()}", source)
        return config_from_dict(cls, values, source)

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    def with_overrides(self, overrides: list[str] | dict[str, Any] | None) -> "SimParams":
        """A copy with ``["bending=1e-5", "self_collision=true"]`` (YAML scalars,
        :func:`loosefit.config.apply_overrides`) or a dict applied."""
        if not overrides:
            return self
        if isinstance(overrides, dict):
            return SimParams.from_dict({**self.to_dict(), **overrides})
        overrides = [overrides] if isinstance(overrides, str) else list(overrides)
        for item in overrides:
            key, sep, _ = item.partition("=")
            if not sep:
                raise InputError(f"bad simulation override {item!r}: expected NAME=VALUE")
            if key.strip() not in self.names():
                raise InputError(f"unknown simulation parameters {[key.strip()]}; known: {self.names()}")
        return apply_overrides(self, overrides)

    @classmethod
    def load(cls, path: str | Path, overrides: list[str] | dict[str, Any] | None = None) -> "SimParams":
        """Read a YAML mapping of parameters (missing ones keep their defaults), then apply overrides."""
        path = Path(path)
        values = load_yaml(read_yaml_text(path, "simulation parameters"), path)
        if values is not None and not isinstance(values, dict):
            raise InputError("simulation parameters must be a YAML mapping of NAME: VALUE", path)
        return cls.from_dict(values, path).with_overrides(overrides)

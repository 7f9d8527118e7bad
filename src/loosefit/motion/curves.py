"""Smooth time curves used by the procedural motion generators (numpy, float64, time in seconds)."""

from __future__ import annotations

import numpy as np
from scipy.interpolate import PchipInterpolator


def smoothstep(x) -> np.ndarray:
    """Minimum-jerk ramp ``6x^5 - 15x^4 + 10x^3`` of ``x`` clipped to ``[0, 1]``: 0 -> 1 with zero
    velocity and acceleration at both ends."""
    x = np.clip(np.asarray(x, dtype=np.float64), 0.0, 1.0)
    return x * x * x * (x * (6.0 * x - 15.0) + 10.0)


def ramp(t, start: float, duration: float) -> np.ndarray:
    """:func:`smoothstep` from 0 at ``start`` to 1 at ``start + duration`` seconds."""
    return smoothstep((np.asarray(t, dtype=np.float64) - start) / max(duration, 1e-9))


def window(t, start: float, stop: float, fade: float) -> np.ndarray:
    """1 inside ``[start, stop]``, fading in and out smoothly over ``fade`` seconds on the inside."""
    fade = min(fade, 0.5 * (stop - start))
    return ramp(t, start, fade) * (1.0 - ramp(t, stop - fade, fade))


def smooth_noise(rng: np.random.Generator, t, period: float, amplitude: float, terms: int = 4) -> np.ndarray:
    """Band-limited random curve: ``terms`` sinusoids with periods in ``[period, 3 period]`` seconds,
    random phases, scaled so that its peak over ``t`` is about ``amplitude``. Infinitely smooth."""
    t = np.asarray(t, dtype=np.float64)
    freq = 1.0 / (period * rng.uniform(1.0, 3.0, terms))
    phase = rng.uniform(0.0, 2 * np.pi, terms)
    weight = rng.uniform(0.5, 1.0, terms)
    curve = (weight[:, None] * np.sin(2 * np.pi * freq[:, None] * t[None] + phase[:, None])).sum(0)
    return amplitude * curve / weight.sum() * 1.5


def keyframes(t, times, values) -> np.ndarray:
    """Shape-preserving cubic (PCHIP) through keys ``values (K, ...)`` at increasing ``times (K,)``,
    held constant outside; never overshoots between keys, so keys inside limits stay inside."""
    t = np.asarray(t, dtype=np.float64)
    times = np.asarray(times, dtype=np.float64)
    values = np.asarray(values, dtype=np.float64)
    if len(times) == 1:
        return np.broadcast_to(values[0], t.shape + values.shape[1:]).copy()
    return PchipInterpolator(times, values, axis=0, extrapolate=False)(np.clip(t, times[0], times[-1]))


def hermite(t, t0: float, t1: float, p0, p1, v0, v1) -> np.ndarray:
    """Cubic Hermite segment from position ``p0`` with velocity ``v0`` at ``t0`` to ``p1``, ``v1`` at
    ``t1`` (velocities per second), evaluated at ``t`` (clipped to the segment)."""
    h = t1 - t0
    s = np.clip((np.asarray(t, dtype=np.float64) - t0) / h, 0.0, 1.0)
    s = s.reshape(s.shape + (1,) * np.ndim(p0))
    s2, s3 = s * s, s * s * s
    return (
        (2 * s3 - 3 * s2 + 1) * p0
        + (s3 - 2 * s2 + s) * h * np.asarray(v0, dtype=np.float64)
        + (-2 * s3 + 3 * s2) * p1
        + (s3 - s2) * h * np.asarray(v1, dtype=np.float64)
    )


def integrate(t, rate, at: float = 0.0) -> np.ndarray:
    """Trapezoid integral of ``rate (N, ...)`` sampled at increasing ``t (N,)``, zero at time ``at``."""
    t = np.asarray(t, dtype=np.float64)
    rate = np.asarray(rate, dtype=np.float64)
    flat = rate.reshape(len(t), -1)
    steps = 0.5 * (flat[1:] + flat[:-1]) * np.diff(t)[:, None]
    total = np.concatenate([np.zeros((1, flat.shape[1])), np.cumsum(steps, 0)])
    ref = np.array([np.interp(at, t, total[:, k]) for k in range(flat.shape[1])])
    return (total - ref).reshape(rate.shape)

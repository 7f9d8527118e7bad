"""Diffusion smoothing and the low/high-frequency split: hand-computed steps, presets, separation of scales."""

import numpy as np
import pytest

from loosefit.errors import InputError
from loosefit.geometry.smoothing import PRESETS, diffusion_smooth, frequency_split, get_preset
from tests.geometry.test_laplacian import grid, hexagon_fan


def test_one_step_on_a_fan_matches_hand_computation():
    verts, faces = hexagon_fan()
    rng = np.random.default_rng(0)
    verts = verts + rng.normal(0, 0.1, verts.shape)
    lam = 0.3
    ring = verts[1:]
    prev, nxt = np.roll(ring, 1, 0), np.roll(ring, -1, 0)
    centre = (1 - lam) * verts[0] + lam * ring.mean(0)

    along = diffusion_smooth(verts, faces, lam, 1, boundary="along")
    assert np.allclose(along[0], centre, atol=1e-6)
    assert np.allclose(along[1:], (1 - lam) * ring + lam * (prev + nxt) / 2, atol=1e-6)

    fixed = diffusion_smooth(verts, faces, lam, 1, boundary="fixed")
    assert np.allclose(fixed[0], centre, atol=1e-6) and np.allclose(fixed[1:], ring, atol=1e-6)

    free = diffusion_smooth(verts, faces, lam, 1, boundary="free")
    assert np.allclose(free[1:], (1 - lam) * ring + lam * (prev + nxt + verts[0]) / 3, atol=1e-6)

    # fixed vertices (a pinned waist): the centre and one ring vertex stay; the ring's neighbours of the
    # fixed one still average with it
    pinned = np.zeros(len(verts), bool)
    pinned[[0, 1]] = True
    kept = diffusion_smooth(verts, faces, lam, 1, boundary="along", fixed=pinned)
    assert np.allclose(kept[pinned], verts[pinned], atol=1e-6) and np.allclose(kept[2:], along[2:], atol=1e-6)
    low, high = frequency_split(verts, faces, "virtualbones", fixed=pinned)
    assert np.abs(high[pinned]).max() < 1e-6 and np.abs(high[~pinned]).max() > 1e-3
    with pytest.raises(InputError, match="mask"):
        diffusion_smooth(verts, faces, lam, 1, fixed=pinned[:-1])

    twice = diffusion_smooth(diffusion_smooth(verts, faces, lam, 1), faces, lam, 1)
    assert np.allclose(diffusion_smooth(verts, faces, lam, 2), twice, atol=1e-6)
    assert np.array_equal(diffusion_smooth(verts, faces, lam, 0), verts.astype(np.float32))


def test_presets_hold_the_papers_settings():
    assert (PRESETS["fitgar"].coefficient, PRESETS["fitgar"].iterations) == (0.12, 40)
    assert (PRESETS["tailornet"].coefficient, PRESETS["tailornet"].iterations) == (0.15, 80)
    assert (get_preset("virtualbones").coefficient, get_preset("virtualbones").iterations) == (0.15, 80)
    with pytest.raises(InputError, match="preset"):
        get_preset("laplace")
    verts, faces = hexagon_fan()
    with pytest.raises(InputError, match="coefficient"):
        diffusion_smooth(verts, faces, 1.5, 3)
    with pytest.raises(InputError, match="iterations"):
        diffusion_smooth(verts, faces, 0.5, -1)
    with pytest.raises(InputError, match="boundary"):
        diffusion_smooth(verts, faces, 0.5, 1, boundary="clamped")


@pytest.mark.parametrize("preset", ["virtualbones", "fitgar"])
def test_split_separates_a_smooth_bump_from_wrinkles(preset):
    verts, faces = grid(40, 1 / 40)
    relief = 0.1
    smooth = verts.copy()
    smooth[:, 2] = relief * np.sin(np.pi * verts[:, 0]) * np.sin(np.pi * verts[:, 1])
    wrinkles = 0.01 * np.sin(20 * np.pi * verts[:, 0])  # wavelength of 4 edges
    wrinkled = smooth.copy()
    wrinkled[:, 2] += wrinkles
    low, high = frequency_split(np.stack([smooth, wrinkled]), faces, preset)
    assert low.shape == high.shape == (2,) + verts.shape and high.dtype == np.float32
    # The bump is nearly all low frequency; the wrinkles are nearly all high frequency.
    inner = (np.abs(verts[:, :2] - 0.5) < 0.3).all(1)
    assert np.abs(high[0][inner]).max() < 0.05 * relief
    assert np.abs(high[1][inner, 2] - wrinkles[inner]).max() < 0.05 * relief
    assert np.corrcoef(high[1][:, 2] - high[0][:, 2], wrinkles)[0, 1] > 0.98


def test_low_plus_high_reconstructs_and_frames_are_independent():
    verts, faces = grid(8, 0.05)
    rng = np.random.default_rng(3)
    seq = (verts[None] + rng.normal(0, 0.01, (3,) + verts.shape)).astype(np.float32)
    low, high = frequency_split(seq, faces, "tailornet")
    assert np.abs(low + high - seq).max() < 1e-6
    for t in range(3):
        low_t, _ = frequency_split(seq[t], faces, "tailornet")
        assert np.abs(low_t - low[t]).max() < 1e-6

"""Mean run, floor and the two RMSEs of a prediction against closed forms on synthetic runs."""

import numpy as np
import pytest

from loosefit.errors import InputError
from loosefit.metrics.reference import BandedReferences, References, corrected_rmse, floor_m, mean_run, rmse_m

T, V = 5, 7


def synthetic_runs():
    """Runs m + e_k with e = (+a, -a, +b, -b): they sum to zero, so the mean is m exactly;
    |a| = 3 mm, |b| = 4 mm at every vertex and frame."""
    rng = np.random.default_rng(0)
    m = rng.normal(0.0, 0.3, (T, V, 3))
    a, b = np.array([0.003, 0.0, 0.0]), np.array([0.0, 0.004, 0.0])
    runs = np.stack([m + a, m - a, m + b, m - b])
    return m, runs


def test_mean_and_floor_of_runs_summing_to_their_mean():
    m, runs = synthetic_runs()
    np.testing.assert_allclose(mean_run(runs), m, atol=1e-12)
    # mean of |e_k|^2 = (9 + 9 + 16 + 16) / 4 mm^2 = 12.5 mm^2
    assert floor_m(runs) == pytest.approx(np.sqrt(12.5) * 1e-3, rel=1e-9)
    assert floor_m(runs[:1]) == 0.0  # a single run has no spread


def test_scores_against_base_and_mean():
    m, runs = synthetic_runs()
    refs = References(runs[0], runs[1:])
    c = np.array([0.0, 0.0, 0.002])
    score = refs.score(m + c)
    assert score.references == 3
    assert score.rmse_vs_mean_mm == pytest.approx(2.0, rel=1e-9)
    assert score.rmse_mm == pytest.approx(np.sqrt(4.0 + 9.0), rel=1e-9)  # |c - a| against the base m + a
    assert score.floor_mm == pytest.approx(np.sqrt(12.5), rel=1e-9)
    # The mean run itself: zero against the mean, |a| against the base.
    best = refs.score(refs.mean)
    assert best.rmse_vs_mean_mm == pytest.approx(0.0, abs=1e-9) and best.rmse_mm == pytest.approx(3.0, rel=1e-9)


def test_no_prediction_beats_the_floor_over_the_runs():
    """mean_k RMSE(p, run_k)^2 = RMSE(p, mean)^2 + floor^2 for any p, checked by brute force."""
    rng = np.random.default_rng(1)
    runs = rng.normal(0.0, 0.01, (5, T, V, 3)) + rng.normal(0.0, 0.3, (1, T, V, 3))
    refs = References(runs[0], runs[1:])
    for _ in range(3):
        p = runs.mean(0) + rng.normal(0.0, 0.005, (T, V, 3))
        over_runs = np.mean([rmse_m(p, r) ** 2 for r in runs])
        assert over_runs == pytest.approx(rmse_m(p, refs.mean) ** 2 + refs.floor_m ** 2, rel=1e-9)
        assert np.sqrt(over_runs) >= refs.floor_m


@pytest.mark.parametrize("runs", [2, 5])
def test_corrected_rmse_is_the_distance_to_the_simulators_mean(runs):
    """Runs mu + noise (sigma 10 mm a coordinate), a prediction mu + c (|c| = 6 mm): against the mean of the runs
    the prediction scores sqrt(36 + 3 sigma^2 / N) mm, and the correction takes it back to |c| = 6 mm. The true
    mean scores 0 once corrected (the plain figure says sqrt(3 / N) sigma). Many vertices make the estimate tight."""
    rng = np.random.default_rng(runs)
    mu = rng.normal(0.0, 0.3, (2, 20000, 3))
    noise = rng.normal(0.0, 0.010, (runs, 2, 20000, 3))
    refs = References(mu + noise[0], mu + noise[1:])
    c = np.array([0.006, 0.0, 0.0])
    score = refs.score(mu + c)
    assert score.rmse_vs_mean_mm == pytest.approx(np.sqrt(36.0 + 300.0 / runs), rel=0.02)
    assert score.rmse_vs_mean_corrected_mm == pytest.approx(6.0, rel=0.05)
    assert refs.score(mu).rmse_vs_mean_corrected_mm < 0.1 * refs.score(mu).rmse_vs_mean_mm
    assert score.as_dict()["rmse_vs_mean_corrected_mm"] == score.rmse_vs_mean_corrected_mm


def test_corrected_rmse_closed_form_and_its_limits():
    assert corrected_rmse(5.0, 4.0, 5) == pytest.approx(np.sqrt(25.0 - 4.0))
    assert corrected_rmse(1.0, 4.0, 5) == 0.0  # below the mean's own spread: clipped, never imaginary
    with pytest.raises(InputError, match="at least 2 runs"):
        corrected_rmse(1.0, 1.0, 1)


def vertex_mean_split(x):
    """A linear split with orthogonal bands: each frame's mean over the vertices, and the rest."""
    low = np.broadcast_to(x.mean(axis=-2, keepdims=True), x.shape)
    return low, x - low


def test_bands_split_the_error_and_the_floor():
    """The runs differ by offsets common to every vertex (all low band); a prediction off the mean by such an
    offset c and by a zero-mean pattern w: low band |c|, high band rms(w), and all^2 = low^2 + high^2."""
    m, runs = synthetic_runs()
    bands = BandedReferences(runs[0], runs[1:], vertex_mean_split)
    w = np.random.default_rng(2).normal(0.0, 0.002, (T, V, 3))
    w -= w.mean(axis=-2, keepdims=True)
    c = np.array([0.0, 0.0, 0.002])
    score = bands.score(m + c + w)
    assert score["low"].floor_mm == pytest.approx(np.sqrt(12.5), rel=1e-9)
    assert score["high"].floor_mm == pytest.approx(0.0, abs=1e-9)
    assert score["low"].rmse_vs_mean_mm == pytest.approx(2.0, rel=1e-9)
    assert score["high"].rmse_vs_mean_mm == pytest.approx(1e3 * np.sqrt(np.mean(np.sum(w * w, -1))), rel=1e-9)
    assert score["low"].rmse_mm == pytest.approx(np.sqrt(4.0 + 9.0), rel=1e-9)  # |c - a| against the base
    for target in ("rmse_mm", "rmse_vs_mean_mm"):
        whole = getattr(score["all"], target)
        assert whole ** 2 == pytest.approx(getattr(score["low"], target) ** 2 + getattr(score["high"], target) ** 2,
                                           rel=1e-9)
    assert score["all"] == References(runs[0], runs[1:]).score(m + c + w)


def test_bad_runs_are_refused():
    m, runs = synthetic_runs()
    with pytest.raises(InputError, match="match the base"):
        References(runs[0], runs[1:, :, :3])
    with pytest.raises(InputError, match="K >= 1"):
        References(runs[0], runs[:0])
    bad = runs.copy()
    bad[2, 1, 1, 0] = np.nan
    with pytest.raises(InputError, match="NaN"):
        References(bad[0], bad[1:])


def sphere_runs(frames, seed):
    """A moving icosphere: base run, 3 reference runs around it and a prediction, on its faces."""
    import trimesh

    sphere = trimesh.creation.icosphere(1, radius=0.3)
    rng = np.random.default_rng(seed)
    base = np.asarray(sphere.vertices)[None] + np.linspace(0, 0.1, frames)[:, None, None] * [0, 1.0, 0]
    refs = base[None] + rng.normal(0, 0.004, (3, *base.shape))
    pred = base + rng.normal(0, 0.006, base.shape)
    return pred, base, refs, np.asarray(sphere.faces)


def test_evaluate_reports_rmse_vs_mean_and_floor_where_runs_exist():
    from loosefit.metrics.report import SequencePair, evaluate

    (p1, g1, r1, faces), (p2, g2, r2, _), (p3, g3, _, _) = sphere_runs(6, 0), sphere_runs(4, 1), sphere_runs(3, 2)
    pairs = [SequencePair("a", p1, g1, faces, references=r1), SequencePair("b", p2, g2, faces, references=r2),
             SequencePair("c", p3, g3, faces)]
    ev = evaluate(pairs, progress=False)
    a, b, c = ev.rows
    refs_a = References(g1, r1)
    assert a["rmse_vs_mean_mm"] == pytest.approx(1000 * rmse_m(p1, refs_a.mean), rel=1e-6)
    assert a["floor_mm"] == pytest.approx(refs_a.floor_mm, rel=1e-6) and a["references"] == 3
    assert a["rmse_mm"] == pytest.approx(1000 * rmse_m(p1, g1), rel=1e-6)
    assert c["rmse_vs_mean_mm"] is None and c["floor_mm"] is None
    # pooled over the two sequences with runs: the RMSE of them concatenated
    means = np.concatenate([refs_a.mean, References(g2, r2).mean])
    assert ev.overall["rmse_vs_mean_mm"] == pytest.approx(1000 * rmse_m(np.concatenate([p1, p2]), means), rel=1e-6)
    runs = np.concatenate([np.concatenate([g1[None], r1]), np.concatenate([g2[None], r2])], axis=1)
    assert ev.overall["floor_mm"] == pytest.approx(1000 * floor_m(runs), rel=1e-6)
    assert ev.overall["references"] == 2
    # corrected, per sequence and pooled: the mean square less floor^2 / K, over both sequences' frames x vertices
    assert a["rmse_vs_mean_corrected_mm"] == pytest.approx(
        np.sqrt(max(0.0, a["rmse_vs_mean_mm"] ** 2 - a["floor_mm"] ** 2 / 3)), rel=1e-9)
    weights = np.array([p1.shape[0], p2.shape[0]]) * p1.shape[1]
    squares = np.array([r["rmse_vs_mean_mm"] ** 2 - r["floor_mm"] ** 2 / 3 for r in (a, b)])
    assert ev.overall["rmse_vs_mean_corrected_mm"] == pytest.approx(
        np.sqrt(max(0.0, (squares * weights).sum() / weights.sum())), rel=1e-9)
    assert c["rmse_vs_mean_corrected_mm"] is None
    assert "RMSE vs mean mm" in ev.table() and "floor mm" in ev.table()
    assert "floor mm" not in evaluate(pairs[2:], progress=False).table()  # no runs: the table as before

"""The simulation-parameter ensemble: weights, pivot selection, error Grams against brute force, round trips."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from loosefit.errors import InputError
from loosefit.models.ensemble import (
    EnsembleConfig,
    ParamSpace,
    RBFEnsemble,
    best_convex_weights,
    cross_validated_bandwidth,
    error_grams,
    evaluate_parameter_sets,
    fit_ensemble,
    inverse_distance_weights,
    predict_sequence,
    select_pivots,
    weighted_rmse,
)
from loosefit.models.virtualbones import VirtualBones, VirtualBonesConfig
from loosefit.train import seed_everything

TINY = VirtualBonesConfig(lf_hidden=16, hf_hidden=16, global_channels=4, edge_channels=(8,))
PARAMS = [
    {"bending": 1e-6, "density": 0.1, "time_scale": 1.0, "quality": 5, "self_collision": False},
    {"bending": 1e-4, "density": 0.3, "time_scale": 1.0, "quality": 5, "self_collision": False},
    {"bending": 1e-5, "density": 0.2, "time_scale": 1.0, "quality": 5, "self_collision": False},
    {"bending": 3e-6, "density": 0.25, "time_scale": 1.0, "quality": 5, "self_collision": False},
]


@pytest.fixture(scope="module")
def networks(tiny_train):
    """Four small VirtualBones networks of the tiny skirt, differently initialised and shaken off their rest start."""
    out = []
    for seed in range(len(PARAMS)):
        seed_everything(seed)
        model = VirtualBones.from_data(tiny_train, TINY)
        with torch.no_grad():
            for p in model.parameters():
                p.add_(0.05 * torch.randn_like(p))
        out.append(model.eval())
    return out


def test_param_space_uses_varying_numbers_with_log_scales():
    space = ParamSpace.fit(PARAMS[:3], log_params=("bending",))
    assert space.names == ("bending", "density") and space.log == (True, False)
    theta = space.transform(PARAMS[:3])
    logs = np.array([-6.0, -4.0, -5.0])
    dens = np.array([0.1, 0.3, 0.2])
    np.testing.assert_allclose(theta[:, 0], (logs - logs.mean()) / logs.std(), atol=1e-12)
    np.testing.assert_allclose(theta[:, 1], (dens - dens.mean()) / dens.std(), atol=1e-12)
    np.testing.assert_allclose(space.transform(PARAMS[0]), theta[0])
    assert ParamSpace.from_dict(space.to_dict()).transform(PARAMS[3]).tolist() == space.transform(PARAMS[3]).tolist()
    with pytest.raises(InputError, match="log scale"):
        space.transform({"bending": -1.0, "density": 0.2})
    with pytest.raises(InputError, match="do not differ"):
        ParamSpace.fit([PARAMS[0], dict(PARAMS[0])])


def test_inverse_distance_weights_closed_form():
    pivots = np.array([[1.0, 0.0], [0.0, 2.0], [-4.0, 0.0]])
    np.testing.assert_allclose(inverse_distance_weights(pivots, np.zeros(2)), [4 / 7, 2 / 7, 1 / 7], atol=1e-12)
    both = inverse_distance_weights(pivots, np.array([[0.0, 0.0], [0.0, 2.0]]))
    np.testing.assert_allclose(both, [[4 / 7, 2 / 7, 1 / 7], [0, 1, 0]], atol=1e-12)


def test_best_convex_weights_closed_forms():
    # diagonal errors: minimising sum w_k^2 a_k on the simplex gives w_k proportional to 1 / a_k
    np.testing.assert_allclose(best_convex_weights(np.diag([1.0, 2.0, 4.0])), [4 / 7, 2 / 7, 1 / 7], atol=1e-6)
    # the affine optimum (2.5, -0.5) / 2 leaves the simplex: the best convex combination is the first network
    np.testing.assert_allclose(best_convex_weights(np.array([[1.0, 1.5], [1.5, 4.0]])), [1, 0], atol=1e-6)
    assert weighted_rmse(np.diag([4.0, 9.0]), 4, np.array([1.0, 0.0])) == pytest.approx(1.0)


def test_select_pivots_on_a_hand_made_error_table():
    theta = np.array([[0, 0], [1, 0.5], [0.5, 1], [0.4, 0.4], [0.6, 0.6], [0.5, 0.2]])
    # table[i][j]: how badly network j alone fits network i's set; a pivot set fits as its best member
    table = {3: {0: 0.3, 1: 0.8, 2: 0.7, 4: 0.1, 5: 0.2},
             4: {0: 0.9, 1: 0.5, 2: 0.4, 3: 0.1, 5: 0.6},
             5: {0: 0.6, 1: 0.45, 2: 0.9, 3: 0.2, 4: 0.6}}
    calls = []

    def fit_error(pivots, i):
        calls.append((tuple(pivots), i))
        return min(table[i][j] for j in pivots)

    # extremes first (highest then lowest of each parameter), then the worst fitted: 5 (0.45), 4 (0.4), 3
    assert select_pivots(theta, 6, fit_error) == [1, 0, 2, 5, 4, 3]
    assert ((1, 0, 2), 3) in calls and ((1, 0, 2, 5), 4) in calls
    assert select_pivots(theta, 2, fit_error) == [1, 0]
    assert select_pivots(theta, 10, fit_error) == [1, 0, 2, 5, 4, 3]


def test_rbf_weights_are_normalised_and_a_sharp_kernel_reproduces_a_pivot(networks, tiny_test):
    space = ParamSpace.fit(PARAMS, ("bending",))
    loose = RBFEnsemble(networks, PARAMS, space, EnsembleConfig(sigma=1.0))
    theta = torch.randn(5, len(space.names))
    w = loose.weights(theta)
    assert w.shape == (5, 4) and (w >= 0).all() and torch.allclose(w.sum(-1), torch.ones(5))
    assert not torch.allclose(w, w[:1])  # the weights depend on the parameters

    sharp = RBFEnsemble(networks, PARAMS, space, EnsembleConfig(sigma=1e-4))
    seq = tiny_test.sequences[0]
    root, joints = torch.from_numpy(seq.root)[None, :10], torch.from_numpy(seq.joints)[None, :10]
    with torch.no_grad():
        out = sharp(root, joints, PARAMS[2])
        alone = networks[2](root, joints)["verts"]
    np.testing.assert_allclose(out["weights"].numpy(), np.eye(4)[2], atol=1e-6)
    assert (out["verts"] - alone).abs().max() < 1e-6
    assert len(out["state"]) == 4


def test_error_grams_against_brute_force(networks, tiny_train, tiny_test):
    seq = tiny_test.sequences[0]
    whole = networks[0](torch.from_numpy(seq.root)[None], torch.from_numpy(seq.joints)[None])["verts"][0].detach().numpy()
    np.testing.assert_allclose(predict_sequence(networks[0], seq, chunk=7), whole, atol=1e-5)

    grams, counts = error_grams(networks[:3], [tiny_train, tiny_test])
    assert grams.shape == (2, 3, 3) and counts.tolist() == [
        sum(s.verts.shape[0] * s.verts.shape[1] for s in d.sequences) for d in (tiny_train, tiny_test)]
    w = np.array([0.2, 0.5, 0.3])
    for s, data in enumerate((tiny_train, tiny_test)):
        sse = 0.0
        for q in data.sequences:
            mix = sum(wk * predict_sequence(m, q) for wk, m in zip(w, networks[:3]))
            sse += float(((mix.astype(np.float64) - q.verts) ** 2).sum())
        assert weighted_rmse(grams[s], counts[s], w) == pytest.approx(math.sqrt(sse / counts[s]), rel=1e-5)


def test_training_g_puts_each_set_on_its_best_pivot():
    space = ParamSpace.fit(PARAMS[:3], ("bending",))
    theta = space.transform(PARAMS[:3])
    grams = np.stack([np.diag(np.where(np.arange(3) == s, 1e-6, 1e-4)) for s in range(3)])
    counts = np.ones(3, np.int64)
    ensemble = RBFEnsemble([torch.nn.Linear(1, 1) for _ in range(3)], PARAMS[:3], space, EnsembleConfig(steps=150, lr=2e-2))
    history = ensemble.fit(grams, counts, theta)
    with torch.no_grad():
        w = ensemble.weights(torch.tensor(theta, dtype=torch.float32)).numpy()
    assert history[-1] < history[0] / 5
    assert (np.diag(w) > 0.9).all()


def test_leave_one_out_fit_learns_the_neighbours_mixture():
    # three pivots on a line of parameters; pivot 1 sits in the middle and its set is reproduced exactly
    # by the even mixture of pivots 0 and 2 (error Gram of two errors e and -e): the leave-one-out fit
    # must learn weights (1/2, 0, 1/2) there, and the weights of every set leave its own pivot out
    params = [{**PARAMS[0], "bending": b} for b in (1e-6, 1e-5, 1e-4)]
    space = ParamSpace.fit(params, ("bending",))
    theta = space.transform(params)
    middle = np.array([[1.0, 0.0, -1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 1.0]]) * 1e-4
    grams = np.stack([np.diag([0.0, 1e-4, 1e-4]), middle, np.diag([1e-4, 1e-4, 0.0])])
    counts = np.ones(3, np.int64)
    ensemble = RBFEnsemble([torch.nn.Linear(1, 1) for _ in range(3)], params, space, EnsembleConfig(steps=300, lr=2e-2))
    history = ensemble.fit(grams, counts, theta, own=[0, 1, 2])
    with torch.no_grad():
        w = ensemble.weights(torch.tensor(theta, dtype=torch.float32), torch.arange(3)).numpy()
    assert np.allclose(np.diag(w), 0) and np.allclose(w.sum(1), 1)
    assert w[1] == pytest.approx([0.5, 0.0, 0.5], abs=0.02)
    assert history[-1] == pytest.approx(np.mean([w[0] @ grams[0] @ w[0], w[1] @ middle @ w[1], w[2] @ grams[2] @ w[2]]),
                                        rel=0.05, abs=1e-9)


def test_fit_evaluate_save_and_load(networks, tiny_train, tiny_test, tmp_path):
    config = EnsembleConfig(pivots=3, steps=50)
    ensemble, report = fit_ensemble(networks, PARAMS, [tiny_train] * 4, config)
    assert report["space"] == ["bending", "density"] and len(report["pivots"]) == 3
    # bending and density are both highest in set 1 and lowest in set 0; the third is the worst fitted
    assert report["pivots"][:2] == [1, 0] and report["pivots"][2] in (2, 3) and report["loss"][1] <= report["loss"][0]
    assert ensemble.num_pivots == 3

    held_out = [{**PARAMS[0], "bending": 2e-6, "density": 0.15}, {**PARAMS[0], "bending": 5e-5, "density": 0.28}]
    result = evaluate_parameter_sets(ensemble, held_out, [tiny_train, tiny_test])
    assert len(result["sets"]) == 2
    for row, data in zip(result["sets"], (tiny_train, tiny_test)):
        assert row["best_convex_rmse_mm"] <= min(row["rbf_rmse_mm"], row["linear_rmse_mm"], row["best_pivot_rmse_mm"]) + 1e-6
        assert sum(row["rbf_weights"]) == pytest.approx(1) and sum(row["linear_weights"]) == pytest.approx(1)
        # brute force: run the ensemble itself over the sequences
        sse, n = 0.0, 0
        for q in data.sequences:
            with torch.no_grad():
                verts = ensemble(torch.from_numpy(q.root)[None], torch.from_numpy(q.joints)[None], row["params"])["verts"][0]
            sse += float(((verts.double() - torch.from_numpy(q.verts).double()) ** 2).sum())
            n += q.verts.shape[0] * q.verts.shape[1]
        assert row["rbf_rmse_mm"] == pytest.approx(math.sqrt(sse / n) * 1e3, rel=1e-4)

    path = tmp_path / "ensemble.pt"
    ensemble.save(path)
    loaded = RBFEnsemble.load(path, {"virtualbones": VirtualBones})
    q = tiny_test.sequences[0]
    x = torch.from_numpy(q.root)[None, :6], torch.from_numpy(q.joints)[None, :6]
    with torch.no_grad():
        assert torch.equal(loaded(*x, held_out[0])["verts"], ensemble(*x, held_out[0])["verts"])
    with pytest.raises(InputError, match="not among"):
        RBFEnsemble.load(path, {})
    broken = tmp_path / "broken.pt"
    broken.write_bytes(path.read_bytes()[:1000])
    with pytest.raises(InputError, match="broken.pt"):
        RBFEnsemble.load(broken, {"virtualbones": VirtualBones})


def _line_of_sets(count: int) -> tuple[list[dict], np.ndarray]:
    """``count`` parameter sets along bending (log-spaced) and density, and their normalised parameters."""
    params = [{**PARAMS[0], "bending": 10.0 ** (-6 + 2 * s / (count - 1)), "density": 0.1 + 0.05 * s} for s in range(count)]
    return params, ParamSpace.fit(params, ("bending",)).transform(params)


def test_bandwidth_cross_validation_against_closed_form_and_brute_force():
    # every set is the same garment plus its own independent noise n_s (chaos), and each pivot reproduces its own
    # set exactly (G_k = M + n_k): on a new set the error per sample is 1 + sum_k w_k^2 in units of the noise's
    # variance. Trained leave-one-out, g learns even weights, so every fold's error is the closed form's 1 + 1/5
    # (five pivots once the fold's own is left out) at every width
    S, D = 6, 20000
    params, theta = _line_of_sets(S)
    noise = np.random.default_rng(0).standard_normal((S, D))
    grams = np.stack([(noise - noise[s]) @ (noise - noise[s]).T for s in range(S)])
    counts = np.full(S, D)
    space = ParamSpace.fit(params, ("bending",))
    config = EnsembleConfig(pivots=S, steps=300, lr=2e-2, bandwidths=(4.0, 1.0, 16.0))
    ensemble = RBFEnsemble([torch.nn.Linear(1, 1) for _ in range(S)], params, space, config)
    chosen, errors = cross_validated_bandwidth(ensemble, grams, counts, theta, own=list(range(S)))
    assert set(errors) == {1.0, 4.0, 16.0} and errors[chosen] == min(errors.values())
    for b in errors:
        assert errors[b] == pytest.approx(1 + 1 / (S - 1), rel=0.03)
    # brute force: each fold's g trained on the other sets by RBFEnsemble.fit, the fold's set weighted without its pivot
    total = 0.0
    for i in range(S):
        rest = [s for s in range(S) if s != i]
        fold = RBFEnsemble([torch.nn.Linear(1, 1) for _ in range(S)], params, space, config)
        fold.fit(grams[rest], counts[rest], theta[rest], rest)
        fold.bandwidth = 16.0
        with torch.no_grad():
            w = fold.weights(torch.tensor(theta[i:i + 1], dtype=torch.float32), torch.tensor([i]))[0].double().numpy()
        assert w[i] == 0
        total += w @ grams[i] @ w / D / S
    assert errors[16.0] == pytest.approx(total, rel=1e-6)
    # the ensemble passed in keeps its own g
    assert ensemble.bandwidth == 1.0


def test_bandwidth_cross_validation_keeps_a_sharp_kernel_when_the_parameters_matter():
    # the garment moves linearly along the line of sets (Y_s = s u, pivot k gives k u, no noise): an interior set is
    # the even mix of its two neighbours (error 0), while even weights over all pivots miss it by far
    S, D = 7, 50
    params, theta = _line_of_sets(S)
    u = np.random.default_rng(1).standard_normal(D)
    grams = np.stack([np.outer(np.arange(S) - s, np.arange(S) - s) * (u @ u) for s in range(S)])
    counts = np.full(S, D)
    config = EnsembleConfig(pivots=S, steps=400, lr=2e-2, bandwidths=(1.0, 64.0))
    ensemble = RBFEnsemble([torch.nn.Linear(1, 1) for _ in range(S)], params, ParamSpace.fit(params, ("bending",)), config)
    chosen, errors = cross_validated_bandwidth(ensemble, grams, counts, theta, own=list(range(S)))
    assert chosen == 1.0 and errors[1.0] < errors[64.0] / 3
    # nearly even weights over the six other pivots: the closed form of each fold's error, averaged
    even = np.mean([(np.mean([k - s for k in range(S) if k != s])) ** 2 * (u @ u) / D for s in range(S)])
    assert errors[64.0] == pytest.approx(even, rel=0.1)


def test_bandwidth_is_chosen_by_fit_ensemble_saved_and_validated(networks, tiny_train, tmp_path):
    with pytest.raises(InputError, match="bandwidths"):
        EnsembleConfig(bandwidths=(1.0, 0.0))
    config = EnsembleConfig(pivots=3, steps=30, bandwidths=(1.0, 8.0))
    ensemble, report = fit_ensemble(networks, PARAMS, [tiny_train] * 4, config)
    assert report["bandwidth"] in (1.0, 8.0) and set(report["bandwidth_cv_rmse_mm"]) == {"1", "8"}
    assert ensemble.bandwidth == report["bandwidth"]
    # two sets leave nothing to cross-validate on: the fixed kernel, no error
    pair, pair_report = fit_ensemble(networks[:2], PARAMS[:2], [tiny_train] * 2, EnsembleConfig(pivots=2, steps=5))
    assert pair.bandwidth == 1.0 and "bandwidth_cv_rmse_mm" not in pair_report
    held_out = [{**PARAMS[0], "bending": 2e-6, "density": 0.15}]
    ensemble.bandwidth = 1.0
    fixed = evaluate_parameter_sets(ensemble, held_out, [tiny_train])
    ensemble.bandwidth = 8.0
    wide = evaluate_parameter_sets(ensemble, held_out, [tiny_train])
    assert "rbf_sigma1_rmse_mm" not in fixed and ensemble.bandwidth == 8.0
    assert wide["rbf_sigma1_rmse_mm"] == pytest.approx(fixed["rbf_rmse_mm"], rel=1e-9)
    assert wide["sets"][0]["rbf_sigma1_rmse_mm"] == pytest.approx(fixed["sets"][0]["rbf_rmse_mm"], rel=1e-9)
    path = tmp_path / "ensemble.pt"
    ensemble.save(path)
    loaded = RBFEnsemble.load(path, {"virtualbones": VirtualBones})
    assert loaded.bandwidth == 8.0
    assert torch.equal(loaded.weights_for(PARAMS[2]), ensemble.weights_for(PARAMS[2]))

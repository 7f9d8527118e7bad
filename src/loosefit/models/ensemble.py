"""Simulation-parameter variation by an RBF ensemble of pivot networks (VirtualBones, Sec. 4.4).

One network per simulation-parameter set is trained on that set's sequences (any
:class:`~loosefit.models.base.GarmentModel` of one garment: the ensemble never looks inside). For new
parameters ``theta`` the garment is a convex combination of the outputs of ``K`` *pivot* networks::

    G(theta) = sum_k w_k(theta) G_k,    w_k = exp(-|g(theta_k) - g(theta)|^2 / (2 sigma^2)) / sum_l (...)   (VirtualBones Eqs. 3-4)

where ``theta`` is the parameter vector normalised by :class:`ParamSpace` (chosen keys, log10 of the
stiffness-like ones, standardised over the training sets) and ``g`` an MLP into a latent space. The
pivot networks stay frozen; ``g`` is trained so that the combination matches the simulations of every
training parameter set. By default each set is fitted *leaving out its own network* (when that network
is a pivot): a set's own network always fits it best, so fitting with it only teaches ``g`` to put each
set on itself (one-hot weights), which says nothing about the parameters in between; left out, every
set teaches ``g`` how its neighbours combine into it, which is what a new parameter set needs.

Error Gram matrices make that cheap and exact: because the weights sum to one,
``sum_k w_k G_k - Y = sum_k w_k (G_k - Y)``, so the mean squared vertex error of any weights on a
parameter set is the quadratic form ``w^T E w / n`` with ``E_kl = sum_{frames, vertices} (G_k - Y).(G_l - Y)``
(:func:`error_grams`). The networks run once over the training motions; training ``g``, fitting a
parameter set by the pivots and evaluating any weighting (RBF, inverse-distance baseline, best convex
combination) on held-out sets then only touch ``K x K`` matrices.

Bandwidth (ours; the paper gives none and the authors' release fixes ``sigma = 1``). ``g`` is free to put
the sets wherever fits them best, and with eight sets it does so too well: trained on simulations that differ
by chaos as much as by their parameters, it learns weights peaked on one or two pivots, which fit the
training sets' own noise. With several ``bandwidths`` the kernel's width is chosen by nested
leave-one-set-out cross-validation (:func:`cross_validated_bandwidth`): for each training set, ``g`` is
trained on the other sets and the set is predicted as a new one (its own pivot left out), at each candidate
width ``sigma * b``; the width with the least mean squared error over the folds is kept. Wider kernels spread
the weights towards an even average of the pivots, the better choice when the pivots' errors are
independent; narrower ones keep what ``g`` learned. The choice uses the training sets only.

Pivot selection (:func:`select_pivots`): first the networks holding the highest or the lowest value
of some parameter among all networks, then, until ``K`` are chosen, the network whose parameter set
the current pivots fit worst (largest RMSE of the best convex combination of the pivots' outputs
against that set's simulations, :func:`convex_fit_error`).
"""

from __future__ import annotations

import dataclasses
import math
import pickle
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Mapping, Sequence

import numpy as np
import torch
from scipy.optimize import minimize
from torch import nn

from loosefit.errors import InputError
from loosefit.models.dataset import GarmentSequences, SequenceData
from loosefit.models.layers.mlp import MLP
from loosefit.paths import atomic_path
from loosefit.threads import torch_threads


@dataclass(frozen=True)
class EnsembleConfig:
    """Settings of the parameter ensemble.

    Attributes:
        pivots: pivot networks K (8 in the paper, Sec. 5; at most the number of trained networks).
        sigma: RBF bandwidth in the latent space (1 in the authors' release; ``g`` learns the latent
            scale, so sigma only fixes its unit).
        latent: size of ``g``'s latent space (not given in the paper).
        hidden: hidden widths of ``g`` (not given in the paper).
        log_params: parameters compared on a log10 scale (stiffness spans orders of magnitude).
        steps, lr: Adam steps and learning rate training ``g`` (full batch: all training sets).
        leave_one_out: fit each training set without its own pivot network (see the module doc; the
            paper does not say how its ``g`` is trained).
        bandwidths: candidate factors of ``sigma``; with more than one, the factor is chosen by nested
            leave-one-set-out cross-validation over the training sets (see the module doc); ``(1.0,)`` is
            the paper's fixed kernel. On ``simparams.yaml`` the choice (x2) lowered the held-out error on
            both sets (``benchmarks/README.md``), so choosing is the default.
        seed: seeds ``g``'s initial weights.
        threads: torch CPU threads while fitting and evaluating (restored afterwards; 1 is fastest on
            small shared machines, as for training).
    """

    pivots: int = 8
    sigma: float = 1.0
    latent: int = 8
    hidden: tuple[int, ...] = (32, 32)
    log_params: tuple[str, ...] = ("bending",)
    steps: int = 2000
    lr: float = 1e-2
    leave_one_out: bool = True
    bandwidths: tuple[float, ...] = (1.0, 2.0, 4.0, 8.0, 16.0, 64.0)
    seed: int = 0
    threads: int = 1

    def __post_init__(self):
        if min(self.pivots, self.latent, self.threads, *self.hidden) < 1 or self.steps < 0:
            raise InputError(f"pivots, latent, hidden sizes and threads must be >= 1 and steps >= 0, got {self}")
        if not (self.sigma > 0 and self.lr > 0):
            raise InputError(f"sigma and lr must be > 0, got {self.sigma}, {self.lr}")
        if not self.bandwidths or not all(math.isfinite(b) and b > 0 for b in self.bandwidths):
            raise InputError(f"bandwidths must be a non-empty list of factors > 0, got {self.bandwidths}")


# ---------------------------------------------------------------- parameter space


@dataclass
class ParamSpace:
    """Simulation parameters as normalised vectors ``(P,)``.

    Attributes:
        names: the parameter keys used, in order.
        log: per key, whether its log10 is used.
        mean, std: ``(P,)`` float64 statistics of the (log) values over the sets the space was fitted on.
    """

    names: tuple[str, ...]
    log: tuple[bool, ...]
    mean: np.ndarray
    std: np.ndarray

    @classmethod
    def fit(cls, params: Sequence[Mapping], log_params: Sequence[str] = ()) -> "ParamSpace":
        """The space of the numeric keys (booleans excluded) that vary over ``params`` (dicts of one
        parameter set each, e.g. :attr:`SequenceData.sim_params`)."""
        if len(params) < 2:
            raise InputError(f"a parameter space needs at least two parameter sets, got {len(params)}")
        common = set.intersection(*(set(p) for p in params))
        numeric = sorted(k for k in common
                         if all(isinstance(p[k], (int, float)) and not isinstance(p[k], bool) for p in params))
        varying = tuple(k for k in numeric if len({float(p[k]) for p in params}) > 1)
        if not varying:
            raise InputError(f"the parameter sets do not differ in any numeric parameter (compared {numeric})")
        space = cls(varying, tuple(k in log_params for k in varying), np.zeros(len(varying)), np.ones(len(varying)))
        raw = space._raw(params)
        space.mean, space.std = raw.mean(0), raw.std(0)
        return space

    def _raw(self, params: Sequence[Mapping]) -> np.ndarray:
        rows = []
        for p in params:
            missing = [k for k in self.names if k not in p]
            if missing:
                raise InputError(f"simulation parameters lack {missing}")
            row = np.array([float(p[k]) for k in self.names])
            log = np.array(self.log, bool)
            if (row[log] <= 0).any():
                raise InputError(f"parameters {[k for k, lg in zip(self.names, self.log) if lg]} are compared on a "
                                 f"log scale and must be positive, got {dict(zip(self.names, row))}")
            row[log] = np.log10(row[log])
            rows.append(row)
        return np.stack(rows)

    def transform(self, params: Mapping | Sequence[Mapping]) -> np.ndarray:
        """Normalised vectors: ``(P,)`` for one parameter dict, ``(N, P)`` for a sequence of them."""
        if isinstance(params, Mapping):
            return self.transform([params])[0]
        return (self._raw(params) - self.mean) / self.std

    def to_dict(self) -> dict:
        return {"names": list(self.names), "log": list(self.log), "mean": self.mean.tolist(), "std": self.std.tolist()}

    @classmethod
    def from_dict(cls, d: Mapping) -> "ParamSpace":
        return cls(tuple(d["names"]), tuple(d["log"]), np.asarray(d["mean"], np.float64), np.asarray(d["std"], np.float64))


# ---------------------------------------------------------------- weights


def inverse_distance_weights(pivot_theta: np.ndarray, theta: np.ndarray, eps: float = 1e-9) -> np.ndarray:
    """The paper's linear baseline: weights proportional to ``1 / |theta - theta_k|``, normalised.

    Args:
        pivot_theta: ``(K, P)`` normalised pivot parameters.
        theta: ``(P,)`` or ``(N, P)`` normalised parameters.
        eps: distances below it count as equal parameters: those pivots share the weight.

    Returns:
        ``(K,)`` or ``(N, K)`` float64 weights, non-negative, summing to 1.
    """
    theta = np.asarray(theta, np.float64)
    d = np.linalg.norm(np.atleast_2d(theta)[:, None, :] - np.asarray(pivot_theta, np.float64)[None], axis=-1)
    exact = d < eps
    w = np.where(exact.any(1, keepdims=True), exact.astype(np.float64), 1.0 / np.maximum(d, eps))
    w /= w.sum(1, keepdims=True)
    return w[0] if theta.ndim == 1 else w


def best_convex_weights(gram: np.ndarray) -> np.ndarray:
    """The convex weights ``w (K,)`` (non-negative, summing to 1) minimising ``w^T E w`` for an error Gram ``E (K, K)``."""
    E = np.asarray(gram, np.float64)
    K = len(E)
    if K == 1:
        return np.ones(1)
    E = E / max(np.trace(E) / K, 1e-300)  # scale-free problem for the solver
    start = np.zeros(K)
    start[np.argmin(np.diag(E))] = 1.0  # the best single network
    res = minimize(lambda w: w @ E @ w, start, jac=lambda w: 2 * E @ w, method="SLSQP", bounds=[(0.0, 1.0)] * K,
                   constraints=[{"type": "eq", "fun": lambda w: w.sum() - 1.0, "jac": lambda w: np.ones(K)}],
                   options={"ftol": 1e-12, "maxiter": 200})
    w = np.clip(res.x, 0.0, None)
    w /= w.sum()
    return w if w @ E @ w <= start @ E @ start else start


def weighted_rmse(gram: np.ndarray, count: int, weights: np.ndarray) -> float:
    """RMSE (metres) of the combination ``weights (K,)`` on a set with error Gram ``gram (K, K)`` over
    ``count`` vertex samples."""
    w = np.asarray(weights, np.float64)
    return float(math.sqrt(max(w @ np.asarray(gram, np.float64) @ w, 0.0) / count))


# ---------------------------------------------------------------- predictions and error Grams


@torch.no_grad()
def predict_outputs(model: nn.Module, seq: SequenceData, names: Sequence[str] = ("verts",), chunk: int = 64) -> dict[str, np.ndarray]:
    """Canonical vertex outputs ``{name: (T, V, 3) float32}`` a model predicts for a whole sequence from
    frame 0, ``chunk`` frames at a time with its recurrent state carried over (equal to one pass);
    ``names`` are the model's outputs (``"verts"``; ``"lf"``: VirtualBones' low-frequency mesh)."""
    model.eval()
    device = next(model.buffers()).device
    root = torch.from_numpy(seq.root).to(device)[None]
    joints = torch.from_numpy(seq.joints).to(device)[None]
    state, out = None, {name: [] for name in names}
    for a in range(0, seq.num_frames, chunk):
        step = model(root[:, a:a + chunk], joints[:, a:a + chunk], state)
        state = step["state"]
        for name in names:
            out[name].append(step[name][0].cpu().numpy())
    return {name: np.concatenate(parts).astype(np.float32) for name, parts in out.items()}


def predict_sequence(model: nn.Module, seq: SequenceData, chunk: int = 64) -> np.ndarray:
    """The garment vertices ``(T, V, 3)`` of :func:`predict_outputs`."""
    return predict_outputs(model, seq, ("verts",), chunk)["verts"]


def error_grams(models: Sequence[nn.Module], data: Sequence[GarmentSequences]) -> tuple[np.ndarray, np.ndarray]:
    """Error Gram matrices of ``N`` networks on ``S`` parameter sets.

    Args:
        models: ``N`` garment models of one garment (canonical outputs, same vertex count).
        data: ``S`` data sets, each the sequences of one parameter set.

    Returns:
        ``grams (S, N, N)`` float64 with ``grams[s, k, l] = sum (G_k - Y).(G_l - Y)`` over every frame and
        vertex of set ``s`` (``G_k``: network ``k``'s prediction, ``Y``: the simulation), and
        ``counts (S,)`` int64: the frames times vertices summed over. Each network runs once per
        distinct motion (sets that share a motion share the predictions).
    """
    by_motion: dict[str, list[tuple[int, SequenceData]]] = {}
    for s, d in enumerate(data):
        for seq in d.sequences:
            by_motion.setdefault(seq.motion_name, []).append((s, seq))
    grams = np.zeros((len(data), len(models), len(models)))
    counts = np.zeros(len(data), np.int64)
    for entries in by_motion.values():
        preds = np.stack([predict_sequence(m, entries[0][1]) for m in models])  # (N, T, V, 3)
        for s, seq in entries:
            if seq.verts.shape != preds.shape[1:]:
                raise InputError(f"sequence {seq.name!r} has vertices {seq.verts.shape}, "
                                 f"the networks predict {preds.shape[1:]}")
            D = (preds - seq.verts[None]).reshape(len(models), -1).astype(np.float64)
            grams[s] += D @ D.T
            counts[s] += seq.verts.shape[0] * seq.verts.shape[1]
    return grams, counts


def convex_fit_error(grams: np.ndarray, counts: np.ndarray) -> Callable[[Sequence[int], int], float]:
    """``fit_error(pivots, i)``: RMSE (metres) on parameter set ``i`` of the best convex combination of
    the networks ``pivots``, from :func:`error_grams` over all networks and sets (``grams (N, N, N)``)."""

    def fit_error(pivots: Sequence[int], i: int) -> float:
        E = grams[i][np.ix_(pivots, pivots)]
        return weighted_rmse(E, int(counts[i]), best_convex_weights(E))

    return fit_error


def select_pivots(theta: np.ndarray, count: int, fit_error: Callable[[list[int], int], float]) -> list[int]:
    """Pivot networks in selection order (paper Sec. 4.4).

    Args:
        theta: ``(N, P)`` parameters of the ``N`` networks (raw or normalised: only their order matters here).
        count: pivots wanted (at most ``N``).
        fit_error: ``fit_error(pivots, i)``, how badly the networks ``pivots`` fit network ``i``'s set.

    Returns:
        Indices: first those holding the highest or lowest value of some parameter (per parameter
        in order, highest then lowest, lower index first on ties), truncated to ``count`` if there
        are more; then repeatedly the worst-fitted remaining network (lower index first on ties).
    """
    theta = np.asarray(theta, np.float64)
    if theta.ndim != 2 or len(theta) == 0:
        raise InputError(f"parameters must be (N, P) with N >= 1, got shape {theta.shape}")
    if count < 1:
        raise InputError(f"at least one pivot is needed, got {count}")
    count = min(count, len(theta))
    pivots: list[int] = []
    for column in theta.T:
        for i in (int(np.argmax(column)), int(np.argmin(column))):
            if i not in pivots:
                pivots.append(i)
    pivots = pivots[:count]
    while len(pivots) < count:
        rest = [i for i in range(len(theta)) if i not in pivots]
        errors = [fit_error(list(pivots), i) for i in rest]
        pivots.append(rest[int(np.argmax(errors))])
    return pivots


# ---------------------------------------------------------------- the ensemble


class RBFEnsemble(nn.Module):
    """Pivot networks blended by RBF weights over simulation parameters (VirtualBones Eqs. 3-4).

    Args:
        pivots: the ``K`` pivot models (frozen: their parameters get ``requires_grad=False``).
        pivot_params: their simulation parameters (dicts).
        space: the parameter normalisation.
        config: the :class:`EnsembleConfig` (``sigma``, ``g``'s sizes and training).
    """

    def __init__(self, pivots: Sequence[nn.Module], pivot_params: Sequence[Mapping], space: ParamSpace,
                 config: EnsembleConfig = EnsembleConfig()):
        super().__init__()
        if len(pivots) != len(pivot_params) or not pivots:
            raise InputError(f"got {len(pivots)} pivot networks and {len(pivot_params)} parameter sets")
        self.pivots = nn.ModuleList(pivots)
        self.pivots.requires_grad_(False)
        self.pivot_params = [dict(p) for p in pivot_params]
        self.space = space
        self.config = config
        self.register_buffer("pivot_theta", torch.tensor(space.transform(self.pivot_params), dtype=torch.float32))
        self.bandwidth = 1.0  # factor of config.sigma (fit_ensemble may choose another: cross_validated_bandwidth)
        with torch.random.fork_rng():  # g's initial weights from the config's seed, global generators untouched
            torch.manual_seed(config.seed)
            self.g = MLP((len(space.names), *config.hidden, config.latent))

    @property
    def num_pivots(self) -> int:
        return len(self.pivots)

    def weights(self, theta: torch.Tensor, exclude: torch.Tensor | None = None,
                bandwidth: float | None = None) -> torch.Tensor:
        """Normalised RBF weights ``(..., K)`` of normalised parameters ``theta (..., P)`` (a softmax of
        the log-kernel: equal to VirtualBones Eq. 4 normalised, without underflow for a sharp kernel).

        ``exclude`` (``(...,)`` int64, -1 for none) names one pivot per row whose weight is forced to 0
        (the others renormalised): the leave-one-out fit. ``bandwidth``: the factor of ``sigma`` (None: the
        ensemble's own)."""
        sigma = self.config.sigma * (self.bandwidth if bandwidth is None else bandwidth)
        # the log of VirtualBones Eq. 4's kernel
        logits = -((self.g(theta)[..., None, :] - self.g(self.pivot_theta)) ** 2).sum(-1) / (2 * sigma**2)
        if exclude is not None:
            hit = torch.arange(self.num_pivots, device=logits.device) == exclude[..., None]
            logits = logits.masked_fill(hit, float("-inf"))
        return torch.softmax(logits, -1)  # VirtualBones Eq. 3's normalised weights

    def weights_for(self, params: Mapping, bandwidth: float | None = None) -> torch.Tensor:
        """RBF weights ``(K,)`` of one parameter dict (``bandwidth``: as :meth:`weights` takes it)."""
        theta = torch.tensor(self.space.transform(params), dtype=torch.float32, device=self.pivot_theta.device)
        return self.weights(theta, bandwidth=bandwidth)

    def linear_weights_for(self, params: Mapping) -> np.ndarray:
        """The inverse-distance baseline's weights ``(K,)`` of one parameter dict."""
        return inverse_distance_weights(self.pivot_theta.cpu().numpy().astype(np.float64), self.space.transform(params))

    def forward(self, root: torch.Tensor, joints: torch.Tensor, params: Mapping, state=None) -> dict:
        """``{"verts": (N,T,V,3) canonical, "weights": (K,), "state": [pivot states]}`` for parameters ``params``."""
        w = self.weights_for(params)
        states = [None] * self.num_pivots if state is None else state
        outs = [p(root, joints, s) for p, s in zip(self.pivots, states)]
        verts = sum(wk * o["verts"] for wk, o in zip(w, outs))  # VirtualBones Eq. 3
        return {"verts": verts, "weights": w, "state": [o["state"] for o in outs]}

    def fit(self, grams: np.ndarray, counts: np.ndarray, theta: np.ndarray, own: Sequence[int] | None = None) -> list[float]:
        """Train ``g`` on ``S`` parameter sets: minimise the mean over sets of the mean squared vertex
        error ``w(theta_s)^T E_s w(theta_s) / n_s``.

        Args:
            grams: ``(S, K, K)`` error Grams of the pivots on each set (:func:`error_grams`).
            counts: ``(S,)`` vertex samples per set.
            theta: ``(S, P)`` normalised parameters of the sets.
            own: ``(S,)`` the pivot trained on each set, -1 where none: left out of that set's weights
                (with more than one pivot). None: every pivot takes part everywhere.

        Returns:
            The loss (mean squared error, m^2) at every step.
        """
        device = self.pivot_theta.device
        per_sample = np.asarray(grams) / np.asarray(counts, np.float64)[:, None, None]
        E = torch.tensor(per_sample, dtype=torch.float64, device=device)
        th = torch.tensor(np.asarray(theta), dtype=torch.float32, device=device)
        if E.shape[1:] != (self.num_pivots, self.num_pivots) or len(th) != len(E):
            raise InputError(f"grams {tuple(E.shape)} and parameters {tuple(th.shape)} do not fit {self.num_pivots} pivots")
        exclude = None
        if own is not None and self.num_pivots > 1:
            exclude = torch.tensor(np.asarray(own, np.int64), device=device)
        optimizer = torch.optim.Adam(self.g.parameters(), lr=self.config.lr)
        history = []
        for _ in range(self.config.steps):
            w = self.weights(th, exclude).double()
            loss = torch.einsum("sk,skl,sl->s", w, E, w).mean()
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
            history.append(loss.item())
        return history

    def save(self, path: str | Path) -> None:
        """Write the ensemble (pivots' methods, sizes, configs and weights; ``g``; the space) atomically."""
        from loosefit.config import config_to_dict

        payload = {
            "pivots": [{"method": p.method, "sizes": p.sizes(), "config": config_to_dict(p.config), "state": p.state_dict()}
                       for p in self.pivots],
            "pivot_params": self.pivot_params,
            "space": self.space.to_dict(),
            "config": dataclasses.asdict(self.config),
            "bandwidth": self.bandwidth,
            "g": self.g.state_dict(),
        }
        with atomic_path(path) as tmp:
            torch.save(payload, tmp)

    @classmethod
    def load(cls, path: str | Path, model_classes: Mapping[str, type]) -> "RBFEnsemble":
        """Read :meth:`save`'s file; ``model_classes`` maps method names to model classes."""
        from loosefit.config import config_from_dict

        try:
            payload = torch.load(path, map_location="cpu", weights_only=True)
            pivots = []
            for entry in payload["pivots"]:
                if entry["method"] not in model_classes:
                    raise InputError(f"pivot method {entry['method']!r} is not among {sorted(model_classes)}", path)
                kind = model_classes[entry["method"]]
                model = kind(entry["sizes"], config_from_dict(kind.Config, entry["config"], path))
                model.load_state_dict(entry["state"])
                pivots.append(model)
            config = config_from_dict(EnsembleConfig, payload["config"], path)
            ensemble = cls(pivots, payload["pivot_params"], ParamSpace.from_dict(payload["space"]), config)
            ensemble.g.load_state_dict(payload["g"])
            ensemble.bandwidth = float(payload.get("bandwidth", 1.0))  # files written before it was chosen: 1
        except (OSError, RuntimeError, KeyError, TypeError, EOFError, pickle.UnpicklingError) as e:
            raise InputError(f"cannot read an RBF ensemble: {e}", path) from None
        return ensemble


# ---------------------------------------------------------------- building and evaluating


def cross_validated_bandwidth(ensemble: RBFEnsemble, grams: np.ndarray, counts: np.ndarray, theta: np.ndarray,
                              own: Sequence[int] | None) -> tuple[float, dict[float, float]]:
    """The kernel width factor among the config's ``bandwidths`` that predicts unseen parameter sets best.

    Nested leave-one-set-out over the ``S`` training sets: for each set ``i``, a fresh ``g`` (the config's
    seed) is trained on the other sets as :meth:`RBFEnsemble.fit` trains it, then set ``i`` is weighted as a
    new set would be, its own pivot left out, at every candidate width. Only ``K x K`` Grams are touched.

    Args:
        ensemble: gives the pivots, their parameters, the space and the config (its own ``g`` is not changed).
        grams, counts, theta, own: as :meth:`RBFEnsemble.fit` takes them (``S`` sets).

    Returns:
        The chosen factor (the smallest of the best on ties) and ``{factor: mean squared error over the folds,
        m^2 per vertex sample}``.
    """
    per_sample = np.asarray(grams, np.float64) / np.asarray(counts, np.float64)[:, None, None]
    S = len(per_sample)
    if S < 3:
        raise InputError(f"choosing the bandwidth needs at least 3 training parameter sets, got {S}")
    factors = sorted({float(b) for b in ensemble.config.bandwidths})
    own = [-1] * S if own is None else [int(k) for k in own]
    errors = dict.fromkeys(factors, 0.0)
    for i in range(S):
        rest = [s for s in range(S) if s != i]
        fold = RBFEnsemble(list(ensemble.pivots), ensemble.pivot_params, ensemble.space, ensemble.config)
        fold.fit(grams[rest], counts[rest], theta[rest], [own[s] for s in rest])
        exclude = torch.tensor([own[i]]) if ensemble.num_pivots > 1 else None
        for b in factors:
            with torch.no_grad():
                w = fold.weights(torch.tensor(theta[i:i + 1], dtype=torch.float32), exclude, b)[0].double().numpy()
            errors[b] += float(w @ per_sample[i] @ w) / S
    return min(factors, key=lambda b: (errors[b], b)), errors


def fit_ensemble(models: Sequence[nn.Module], params: Sequence[Mapping], data: Sequence[GarmentSequences],
                 config: EnsembleConfig = EnsembleConfig()) -> tuple[RBFEnsemble, dict]:
    """Choose pivots among networks trained per parameter set and train the RBF weights.

    Args:
        models: ``N`` trained networks, network ``i`` trained on parameter set ``i``.
        params: the ``N`` parameter sets (dicts).
        data: ``N`` data sets: the (training) sequences of each parameter set.
        config: the :class:`EnsembleConfig`.

    Returns:
        The ensemble and a report: ``space`` (names), ``pivots`` (indices in selection order),
        ``fit_rmse_mm`` (per set, the RBF ensemble after training, all pivots taking part), ``loss``
        (first and last of the fit, leave-one-out when configured), ``bandwidth`` (the factor of ``sigma``
        used) and, when it was chosen (several candidates, at least 3 sets), ``bandwidth_cv_rmse_mm`` (each
        candidate's cross-validated RMSE).
    """
    if not len(models) == len(params) == len(data):
        raise InputError(f"got {len(models)} networks, {len(params)} parameter sets and {len(data)} data sets")
    space = ParamSpace.fit(params, config.log_params)
    theta = space.transform(params)
    with torch_threads(config.threads):
        grams, counts = error_grams(models, data)
        pivots = select_pivots(theta, config.pivots, convex_fit_error(grams, counts))
        ensemble = RBFEnsemble([models[i] for i in pivots], [params[i] for i in pivots], space, config)
        sub = grams[:, pivots][:, :, pivots]
        own = [pivots.index(s) if s in pivots else -1 for s in range(len(data))] if config.leave_one_out else None
        history = ensemble.fit(sub, counts, theta, own)
        cv = None
        if len(config.bandwidths) > 1 and len(data) >= 3:  # with two sets a fold would train g on one
            ensemble.bandwidth, cv = cross_validated_bandwidth(ensemble, sub, counts, theta, own)
        with torch.no_grad():
            w = ensemble.weights(torch.tensor(theta, dtype=torch.float32, device=ensemble.pivot_theta.device)).cpu().numpy()
    report = {
        "space": list(space.names),
        "pivots": pivots,
        "fit_rmse_mm": [weighted_rmse(sub[s], int(counts[s]), w[s]) * 1e3 for s in range(len(data))],
        "loss": [history[0], history[-1]] if history else [],
        "bandwidth": ensemble.bandwidth,
    }
    if cv is not None:
        report["bandwidth_cv_rmse_mm"] = {f"{b:g}": math.sqrt(e) * 1e3 for b, e in cv.items()}
    return ensemble, report


def evaluate_parameter_sets(ensemble: RBFEnsemble, params: Sequence[Mapping], data: Sequence[GarmentSequences]) -> dict:
    """Compare the RBF ensemble with the inverse-distance baseline on (held-out) parameter sets.

    Args:
        ensemble: the trained :class:`RBFEnsemble`.
        params: ``S`` parameter sets (dicts).
        data: ``S`` data sets: the sequences simulated with each.

    Returns:
        ``{"sets": [per set: params, rbf_rmse_mm, linear_rmse_mm, best_convex_rmse_mm (the best any
        convex combination of the pivots could do), best_pivot_rmse_mm (the best single pivot),
        rbf_weights, linear_weights], "rbf_rmse_mm", "linear_rmse_mm", "best_convex_rmse_mm",
        "best_pivot_rmse_mm"}`` (the last four over all sets' frames together). With a chosen bandwidth other
        than 1, ``rbf_sigma1_rmse_mm`` (per set and overall) is the same ``g`` with the fixed kernel.
    """
    if len(params) != len(data):
        raise InputError(f"got {len(params)} parameter sets and {len(data)} data sets")
    with torch_threads(ensemble.config.threads):
        grams, counts = error_grams(list(ensemble.pivots), data)
    rbf = {"rbf": None, **({"rbf_sigma1": 1.0} if ensemble.bandwidth != 1 else {})}  # name -> bandwidth
    totals = dict.fromkeys([*rbf, "linear", "best_convex", "best_pivot"], 0.0)
    rows = []
    for p, E, n in zip(params, grams, counts):
        with torch.no_grad():
            weights = {key: ensemble.weights_for(p, b).cpu().numpy().astype(np.float64) for key, b in rbf.items()}
        w_rbf, w_lin = weights["rbf"], ensemble.linear_weights_for(p)
        weights.update(linear=w_lin, best_convex=best_convex_weights(E),
                       best_pivot=np.eye(len(E))[int(np.argmin(np.diag(E)))])
        row = {"params": dict(p)}
        for key, w in weights.items():
            rmse = weighted_rmse(E, int(n), w)
            row[f"{key}_rmse_mm"] = rmse * 1e3
            totals[key] += rmse**2 * n
        row["rbf_weights"], row["linear_weights"] = w_rbf.tolist(), w_lin.tolist()
        rows.append(row)
    out: dict = {"sets": rows}
    out.update({f"{key}_rmse_mm": math.sqrt(total / counts.sum()) * 1e3 for key, total in totals.items()})
    return out

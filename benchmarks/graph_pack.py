"""Paper-width training of FitGar and SwinGar on a GPU machine, from a compact float16 pack of the training tensors.

A lent GPU machine has torch but not loosefit's data stack (Blender, Zarr, the Anny body): ``pack`` turns a prepared
multi-garment store into every tensor training and scoring read (FitGar: each frame's inputs and targets, the
statistics the model normalises with and the fit attribute model; SwinGar: every training window with its motion
history and each held-out sequence whole, as ``swingar_gpu.py export`` makes them), floating tensors in float16
(at most 50 MB: ``--max-mb``). ``train`` runs there with nothing else: each given config (the paper's widths and
the CPU preset's) for the same wall-clock budget on the same pack, and writes the training curve of each (held-out
and training errors against steps and seconds), so the two can be read against each other.

    # here
    .venv/bin/python benchmarks/graph_pack.py pack --method fitgar --data FG.zarr --out .gpu/fitgar-pack.pt
    .venv/bin/python benchmarks/graph_pack.py pack --method swingar --data SG.zarr --config configs/models/swingar.yaml \
        --out .gpu/swingar-pack.pt
    # there (or here, with --seconds small, to check the path)
    python3 benchmarks/graph_pack.py train --pack .gpu/fitgar-pack.pt --configs fitgar.yaml,fitgar-cpu.yaml \
        --seconds 60 --save $OUT/weights --out $OUT/fitgar-curve.json
    # here again: SwinGar weights from --save, animated by the library on the store's test sequences beside body-LBS
    .venv/bin/python benchmarks/graph_pack.py score --weights W/swingar.pt --config swingar.yaml \
        --template A_SWINGAR_RUN_ON_SG --data SG.zarr --run /tmp/scored --out score.json

Both stages of each model train in turn, each for half the budget (FitGar: coarse then detail with the coarse
frozen, the paper's order; SwinGar: its ``supervised`` then ``all`` stage), Adam from the config's rate. The budget
is wall clock (``--seconds``) or optimiser steps (``--steps``, with ``--seconds`` as a cap: processes sharing one GPU
then compare at equal steps); ``--schedule cosine`` lowers the rate to 0 over each stage.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "benchmarks"))
sys.path.insert(0, str(ROOT / "benchmarks" / "experiments"))  # capacity and swingar_attention (pack, score)
sys.path.insert(0, str(ROOT / "src"))


def halve(x):
    """Floating arrays and tensors (nested in dicts, lists, tuples) to float16 tensors; other values as they are."""
    if isinstance(x, dict):
        return {k: halve(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return type(x)(halve(v) for v in x)
    if isinstance(x, np.ndarray):
        x = torch.from_numpy(x if x.flags.c_contiguous else x.copy())  # (ascontiguousarray makes 0-d arrays 1-d)
    if torch.is_tensor(x) and x.is_floating_point():
        return x.half()
    return x


def widen(x, device=None):
    """The inverse of :func:`halve` (float16 back to float32 numpy arrays or, with ``device``, tensors there)."""
    if isinstance(x, dict):
        return {k: widen(v, device) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return type(x)(widen(v, device) for v in x)
    if torch.is_tensor(x):
        x = x.float() if x.dtype == torch.float16 else x
        return x.to(device) if device is not None else x.numpy()
    return x


class PackedFrames:
    """FitGar's training frames read back from a pack: what :class:`~loosefit.models.fitgar_data.GarmentFrames`
    gives the model (items, ``sizes``, ``anchor``, ``feature_stats()``, ``fit_model``)."""

    def __init__(self, part: dict, common: dict):
        from loosefit.rig.fit_attribute import FitAttributeModel

        shared = {key: t.long().numpy() for key, t in common["shared"].items()}
        self.items = [{k: shared[v] if k in SHARED else v for k, v in widen(it).items()} for it in part["items"]]
        self.sizes, self.anchor, self._stats = common["sizes"], common["anchor"], widen(common["stats"])
        self.fit_model = FitAttributeModel(**widen(common["fit_model"]))

    def __len__(self):
        return len(self.items)

    def __getitem__(self, k):
        return self.items[k]

    def feature_stats(self):
        return self._stats


#: FitGar item keys that are the same for every frame of a garment: packed once, as int32, named by their digest.
SHARED = ("edges", "faces")


def pack_fitgar(data: Path, stride: int, test_stride: int) -> dict:
    import hashlib
    from dataclasses import asdict

    from loosefit.models.fitgar_data import GarmentFrames

    train = GarmentFrames(data, "train", frame_stride=stride)
    test = GarmentFrames(data, "test", frame_stride=test_stride)
    shared: dict[str, torch.Tensor] = {}

    def packed(item):
        out = {}
        for key, value in item.items():
            if key in SHARED:
                digest = hashlib.sha1(np.ascontiguousarray(value).tobytes()).hexdigest()
                shared.setdefault(digest, torch.from_numpy(np.asarray(value, np.int32)))
                out[key] = digest
            else:
                out[key] = halve(value)
        return out

    stats = train.feature_stats()
    fit = train.fit_model
    fit_fields = asdict(fit) if hasattr(fit, "__dataclass_fields__") else dict(vars(fit))
    return {"method": "fitgar", "sizes": train.sizes, "anchor": train.anchor, "stats": halve(stats),
            "fit_model": {k: (torch.from_numpy(np.asarray(v, np.float64)) if isinstance(v, np.ndarray) else v)
                          for k, v in fit_fields.items()},
            "train": {"names": train.sequence_names, "items": [packed(train[k]) for k in range(len(train))]},
            "test": {"names": test.sequence_names, "items": [packed(test[k]) for k in range(len(test))]},
            "shared": shared}


def pack_swingar(data: Path, config: Path, overrides: list[str]) -> dict:
    import tempfile

    from swingar_gpu import export

    with tempfile.TemporaryDirectory() as tmp:
        export(data, Path(tmp) / "w.pt", config, overrides)
        payload = torch.load(Path(tmp) / "w.pt", weights_only=False)
    return {"method": "swingar", **halve(payload)}


class Budget:
    """How long each stage trains, its learning rate at each step, and when it is evaluated.

    Each of the run's stages (their count given to :meth:`begin`) gets an equal share: of ``steps`` optimiser steps
    when given (``seconds`` is then a wall-clock cap on the whole run, so that processes sharing a GPU compare at
    equal steps), else of ``seconds``.
    ``schedule``: ``constant`` (the config's rate throughout) or ``cosine`` (from the config's rate to 0 over each
    stage: the papers' schedule, and the end of the curve is not the noise of a constant rate's last step)."""

    def __init__(self, seconds: float, steps: int | None, schedule: str, evals: int):
        self.seconds, self.steps, self.schedule, self.evals = seconds, steps, schedule, evals
        self.start, self.total_steps = time.perf_counter(), 0

    def begin(self, stage: int, stages: int) -> None:
        """Stage ``stage`` of ``stages`` starts (the clock starts with the first one, not with the model's set-up)."""
        if stage == 0:
            self.start = time.perf_counter()
        self.stage, self.stages = stage, stages
        self.stage_start, self.stage_steps, self.evaluated = time.perf_counter(), 0, -1

    def progress(self) -> float:
        """Share of the current stage done, in [0, 1]."""
        if self.steps:
            return self.stage_steps / max(self.steps // self.stages, 1)
        return (time.perf_counter() - self.stage_start) / (self.seconds / self.stages)

    def done(self) -> bool:
        return self.progress() >= 1.0 or time.perf_counter() - self.start >= self.seconds * (
            1.0 if self.steps else (self.stage + 1) / self.stages)

    def set_rate(self, optimiser: torch.optim.Optimizer, base: float) -> None:
        """The schedule's rate for the next step, from the config's ``base``."""
        rate = base * 0.5 * (1.0 + math.cos(math.pi * min(self.progress(), 1.0))) if self.schedule == "cosine" else base
        for group in optimiser.param_groups:
            group["lr"] = rate

    def stepped(self) -> bool:
        """Count one step; True when it is time to evaluate (``evals`` times a stage, and at its end)."""
        self.stage_steps += 1
        self.total_steps += 1
        mark = int(self.progress() * self.evals)
        if mark > self.evaluated or self.done():
            self.evaluated = mark
            return True
        return False

    def seconds_in(self) -> float:
        return time.perf_counter() - self.start


def fitgar_curve(pack: dict, config: Path, overrides: list[str], budget: Budget, device) -> dict:
    from capacity import errors_mm

    from loosefit.config import load_config
    from loosefit.models.fitgar import Config, FitGar
    from loosefit.models.fitgar_data import collate_frames

    train, test = PackedFrames(pack["train"], pack), PackedFrames(pack["test"], pack)
    cfg = load_config(Config, config, overrides)
    torch.manual_seed(cfg.train.seed)
    model = FitGar.from_data(train, cfg.model).to(device)
    size = cfg.train.batch_size
    rng = np.random.default_rng(0)
    on = lambda b: {k: (v.to(device) if torch.is_tensor(v) else v) for k, v in b.items()}  # noqa: E731
    picked = train.items[:: max(len(train) // len(test), 1)]  # as many training frames as held-out ones
    seen = [on(collate_frames(picked[i:i + 8])) for i in range(0, len(picked), 8)]
    held = [on(collate_frames(test.items[i:i + 8])) for i in range(0, len(test), 8)]
    curve, stages = [], ("coarse", "detail")
    for n, stage in enumerate(stages):
        params = list(model.stage_parameters(stage))
        for p in model.parameters():
            p.requires_grad_(False)
        for p in params:
            p.requires_grad_(True)
        opt = torch.optim.Adam(params, lr=cfg.train.lr)
        budget.begin(n, len(stages))
        while not budget.done():
            order = rng.permutation(len(train))
            for a in range(0, len(order), size):
                budget.set_rate(opt, cfg.train.lr)
                loss, _ = model.training_loss(on(collate_frames([train.items[k] for k in order[a:a + size]])), stage)
                opt.zero_grad()
                loss.backward()
                if cfg.train.grad_clip:
                    torch.nn.utils.clip_grad_norm_(params, cfg.train.grad_clip)
                opt.step()
                if budget.stepped():
                    row = {"stage": stage, "step": budget.total_steps, "seconds": budget.seconds_in(), "loss": float(loss.detach()),
                           **{f"train_{k}": v for k, v in errors_mm(model, seen).items()},
                           **{f"test_{k}": v for k, v in errors_mm(model, held).items()}}
                    curve.append(row)
                    print({k: round(v, 2) if isinstance(v, float) else v for k, v in row.items()}, flush=True)
                if budget.done():
                    break
    return {"train_frames": len(train), "test_frames": len(test), "parameters": sum(p.numel() for p in model.parameters()),
            "curve": curve, "model": model}


def swingar_curve(pack: dict, config: Path, overrides: list[str], budget: Budget, device) -> dict:
    from swingar_gpu import model_from_payload, window_errors

    from loosefit.config import load_config
    from loosefit.models.multi_garment import collate_by_graph
    from loosefit.models.swingar import Config

    payload = widen({k: v for k, v in pack.items() if k != "method"})
    payload = {**payload, "stats": {k: [torch.as_tensor(a) for a in v] for k, v in payload["stats"].items()}}
    cfg = load_config(Config, config, [*payload["overrides"], *overrides])
    torch.manual_seed(cfg.train.seed)
    model = model_from_payload(payload, cfg).to(device)

    def graphs(gs):
        return [{k: torch.as_tensor(v).to(device) for k, v in g.items()} for g in gs]

    train_graphs, test_graphs = graphs(payload["train_graphs"]), graphs(payload["test_graphs"])

    history = cfg.model.motion_frames - 1 + cfg.model.corrective_frames - 1
    if history > payload["train"][0]["history_root"].shape[0]:
        raise SystemExit(f"graph_pack: {config.name} needs {history} frames of history, the pack has fewer: pack with it")

    def on(item, gs):  # the last ``history`` frames before a window are the history of a model that needs fewer
        out = {k: (torch.as_tensor(v[-history:] if k.startswith("history_") else v).to(device)
                   if isinstance(v, np.ndarray) else v) for k, v in item.items()}
        out["graph_tensors"] = gs[item["graph"]]
        return out

    items = [on(it, train_graphs) for it in payload["train"]]
    held = collate_by_graph([on(it, test_graphs) for it in payload["test"]])
    seen = collate_by_graph(items[:: max(len(items) // 16, 1)])
    opt = torch.optim.Adam(model.parameters(), cfg.train.lr)
    rng = np.random.default_rng(0)
    curve = []
    for n, stage in enumerate(cfg.train.stages):
        budget.begin(n, len(cfg.train.stages))
        while not budget.done():
            order = rng.permutation(len(items))
            for a in range(0, len(order), cfg.train.batch_size):
                budget.set_rate(opt, cfg.train.lr)
                loss, _ = model.training_loss(collate_by_graph([items[k] for k in order[a:a + cfg.train.batch_size]]), stage)
                opt.zero_grad()
                loss.backward()
                opt.step()
                if budget.stepped():
                    model.eval()
                    row = {"stage": stage, "step": budget.total_steps, "seconds": budget.seconds_in(), "loss": float(loss.detach()),
                           **{f"train_{k}": v for k, v in window_errors(model, seen).items()},
                           **{f"test_{k}": v for k, v in window_errors(model, held).items()}}
                    model.train()
                    curve.append(row)
                    print({k: round(v, 2) if isinstance(v, float) else v for k, v in row.items()}, flush=True)
                if budget.done():
                    break
    return {"train_windows": len(items), "test_sequences": len(payload["test"]),
            "parameters": sum(p.numel() for p in model.parameters()), "curve": curve, "model": model}


def score_swingar(weights: Path, config: Path, overrides: list[str], template: Path, data: Path, run: Path) -> dict:
    """SwinGar weights trained from a pack, scored here as every SwinGar run is (``accuracy_graph.py``): a run
    folder made from ``template`` (a SwinGar run on the same store: its ``model.json`` and checkpoint layout) with
    ``config`` and the weights, each test sequence animated from the garment's rest mesh, beside body-LBS; and the
    layers' attention entropy on the held-out garments (``attention_entropy``: per layer, its ratio to uniform)."""
    import shutil

    from accuracy_graph import swingar_errors
    from swingar_attention import held_out_entropy

    from loosefit.config import load_config, save_config
    from loosefit.data.store import DatasetStore
    from loosefit.models.swingar import Config
    from loosefit.train.run import RunDir, load_checkpoint, save_checkpoint
    from loosefit.training import METHOD_CONFIG

    if run.exists():
        shutil.rmtree(run)
    shutil.copytree(template, run, ignore=shutil.ignore_patterns("best.pt", "metrics.csv", "run.json"))
    save_config(run / METHOD_CONFIG, load_config(Config, config, overrides))
    state = load_checkpoint(RunDir(run).last_checkpoint)
    state["model"] = torch.load(weights, weights_only=True)
    save_checkpoint(RunDir(run).last_checkpoint, state)
    store = DatasetStore.open(data)
    rows = swingar_errors(run, store, store.sequence_names(split="test"))
    mean = lambda key: float(np.mean([r[key] for r in rows]))  # noqa: E731
    return {"weights": str(weights), "config": config.name, "overrides": overrides, "rows": rows,
            "rmse_mm": mean("rmse_mm"), "body_lbs_rmse_mm": mean("body_lbs_rmse_mm"),
            "over_body_lbs": mean("rmse_mm") / mean("body_lbs_rmse_mm"),
            "attention_entropy": held_out_entropy(data, run, "last")}


def config_path(name: str) -> Path:
    """A config file given as a path, or by its name in ``configs/models/``."""
    return Path(name) if Path(name).is_file() else ROOT / "configs" / "models" / name


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="command", required=True)
    p = sub.add_parser("pack")
    p.add_argument("--method", choices=("fitgar", "swingar"), required=True)
    p.add_argument("--data", required=True)
    p.add_argument("--out", required=True)
    p.add_argument("--config", help="SwinGar: the config whose windows and history are packed (default: the paper's)")
    p.add_argument("--set", action="append", default=[])
    p.add_argument("--frame-stride", type=int, default=1, help="FitGar: every n-th training frame")
    p.add_argument("--test-stride", type=int, default=3, help="FitGar: every n-th held-out frame")
    p.add_argument("--max-mb", type=float, default=50.0)
    p = sub.add_parser("train")
    p.add_argument("--pack", required=True)
    p.add_argument("--configs", required=True, help="comma-separated config files (names in configs/models/ or paths)")
    p.add_argument("--seconds", type=float, default=60.0, help="training wall-clock per config")
    p.add_argument("--steps", type=int, help="optimiser steps per config (then --seconds is only a cap)")
    p.add_argument("--schedule", choices=("constant", "cosine"), default="constant", help="learning rate over each stage")
    p.add_argument("--evals", type=int, default=8, help="evaluations per stage")
    p.add_argument("--set", action="append", default=[])
    p.add_argument("--save", help="folder for each config's trained weights (CONFIG.pt: the model's state dict)")
    p.add_argument("--out", required=True)
    p = sub.add_parser("score", help="SwinGar weights from train --save, scored on the store by the library's animation")
    p.add_argument("--weights", type=Path, required=True)
    p.add_argument("--config", required=True, help="the config the weights were trained with (name or path)")
    p.add_argument("--set", action="append", default=[])
    p.add_argument("--template", type=Path, required=True, help="a SwinGar run folder on the same store")
    p.add_argument("--data", type=Path, required=True)
    p.add_argument("--run", type=Path, required=True, help="the run folder to write")
    p.add_argument("--out", required=True)
    a = ap.parse_args()
    if a.command == "score":
        result = score_swingar(a.weights, config_path(a.config), a.set, a.template, a.data, a.run)
        Path(a.out).write_text(json.dumps(result, indent=1))
        print(f"SwinGar {result['rmse_mm']:.1f} mm, body-LBS {result['body_lbs_rmse_mm']:.1f} mm: "
              f"{result['over_body_lbs']:.3f}x")
        return
    if a.command == "pack":
        if a.method == "fitgar":
            payload = pack_fitgar(Path(a.data), a.frame_stride, a.test_stride)
        else:
            payload = pack_swingar(Path(a.data), Path(a.config or ROOT / "configs" / "models" / "swingar.yaml"), a.set)
        out = Path(a.out)
        out.parent.mkdir(parents=True, exist_ok=True)
        torch.save(payload, out)
        mb = out.stat().st_size / 2**20
        print(f"{a.method} pack: {out} {mb:.1f} MB")
        if mb > a.max_mb:
            out.unlink()
            sys.exit(f"graph_pack: the pack is {mb:.1f} MB, above --max-mb {a.max_mb:g}: pack fewer frames (--frame-stride)")
        return
    from swingar_gpu import stub_missing

    stubbed = stub_missing()
    pack = torch.load(a.pack, weights_only=False)
    device = torch.device("cuda" if torch.cuda.is_available() else "cpu")
    curve_of = fitgar_curve if pack["method"] == "fitgar" else swingar_curve
    result = {"method": pack["method"], "device": torch.cuda.get_device_name() if device.type == "cuda" else "cpu",
              "pack": str(a.pack), "pack_mb": Path(a.pack).stat().st_size / 2**20, "stubbed": stubbed,
              "seconds_per_config": a.seconds, "steps_per_config": a.steps,
              "schedule": a.schedule, "overrides": a.set, "runs": {}}
    for name in a.configs.split(","):
        config = config_path(name)
        print(f"== {pack['method']} {config.name}", flush=True)
        if device.type == "cuda":
            torch.cuda.reset_peak_memory_stats()
        run = curve_of(pack, config, a.set, Budget(a.seconds, a.steps, a.schedule, a.evals), device)
        model = run.pop("model")
        if device.type == "cuda":
            run["peak_memory_mib"] = torch.cuda.max_memory_allocated() / 2**20
        if a.save:  # the weights, to be scored here by the library's own animation (a run folder's checkpoint)
            Path(a.save).mkdir(parents=True, exist_ok=True)
            torch.save({k: v.cpu() for k, v in model.state_dict().items()}, Path(a.save) / f"{config.stem}.pt")
        result["runs"][config.name] = run
        Path(a.out).parent.mkdir(parents=True, exist_ok=True)
        Path(a.out).write_text(json.dumps(result, indent=1))  # after every config: a cut-off run keeps what it did


if __name__ == "__main__":
    main()

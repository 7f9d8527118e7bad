"""SwinGar's alpha curve on a GPU machine that has torch but not loosefit's data stack (Blender, Zarr, Anny,
libigl): the store's windows are exported here as tensors, and the training and scoring run there on them.

    # here: every training window and every held-out sequence whole, as tensors
    .venv/bin/python benchmarks/swingar_gpu.py export --data STORE.zarr --out gpu/windows.pt
    # there (plain python3 with torch; loosefit's own modules from src/, its third-party imports stubbed)
    python3 benchmarks/swingar_gpu.py curve --windows gpu/windows.pt --out $OUT/curve.json

``curve`` trains each variant (alpha 0, 1, 2, 3, plain GAT; ``--seeds``) as ``loosefit train`` does (Adam, the
config's stages and epochs, cosine per stage over its epochs, batches of ``train.batch_size`` windows
shuffled each epoch) and scores it on the held-out garments' sequences whole, from their first frame (what
animating the rest garment gives, in the canonical frame), with each GAT-LN layer's attention entropy there.
The held-out RMSE is then put beside body-LBS by ``swingar_attention.py`` (which needs the body model).
"""

from __future__ import annotations

import argparse
import importlib
import json
import sys
import time
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parent.parent
ALPHAS = {"alpha-0": 0.0, "alpha-1": 1.0, "alpha-2": 2.0, "alpha-3": 3.0, "plain-gat": None}
#: Third-party modules loosefit imports at module level that a torch-only machine may lack; stubbed there
#: (the model never calls them: the exported windows carry everything it reads).
OPTIONAL = ("igl", "zarr", "anny", "bpy", "potpourri3d", "trimesh", "pyvista", "dem_bones", "py_dem_bones", "ray",
            "newton", "warp", "pygltflib", "pxr", "imageio", "imageio_ffmpeg", "numcodecs", "roma", "smplx", "tqdm",
            "rich", "tensorboard")


class _Stubs:
    """Finds every module under the stubbed top-level names and makes each a ``MagicMock`` (any attribute,
    callable, importable from)."""

    def __init__(self, roots):
        self.roots = set(roots)

    def find_spec(self, name, path=None, target=None):
        import importlib.util

        return importlib.util.spec_from_loader(name, self) if name.split(".")[0] in self.roots else None

    def create_module(self, spec):
        from unittest import mock

        module = mock.MagicMock(name=spec.name)
        module.__path__ = []  # a package: its submodules import too
        return module

    def exec_module(self, module):
        pass


def stub_missing() -> list[str]:
    """Stand-ins for each of :data:`OPTIONAL` that does not import here (and all its submodules)."""
    stubbed = []
    for name in OPTIONAL:
        try:
            importlib.import_module(name)
        except Exception:  # noqa: BLE001 (missing, or broken against this numpy)
            sys.modules.pop(name, None)
            stubbed.append(name)
    sys.meta_path.insert(0, _Stubs(stubbed))
    return stubbed


def export(store: Path, out: Path, config: Path, overrides: list[str]) -> None:
    from loosefit.config import load_config
    from loosefit.models.multi_garment import MultiGarmentData, MultiWindowDataset
    from loosefit.models.swingar import Config, SwinGar

    cfg = load_config(Config, config, overrides)
    history = cfg.model.motion_frames - 1 + cfg.model.corrective_frames - 1
    train = MultiGarmentData(store, "train", **cfg.model.graph_settings())
    test = MultiGarmentData(store, "test", body=False, **cfg.model.graph_settings())
    sizes = SwinGar.data_sizes(train)
    stats = train.feature_stats()
    windows = MultiWindowDataset(train, cfg.data.window, cfg.data.stride, history)
    whole = MultiWindowDataset(test, 10_000, 10_000, history)  # every held-out sequence as one window

    def plain(item):  # the body meshes are left out (their size): the collision term is then 0
        return {k: v for k, v in item.items() if k not in ("graph_tensors", "body", "body_normals", "body_nearest")}

    payload = {"sizes": sizes, "stats": {k: [torch.from_numpy(np.asarray(v)) for v in stats[k]] for k in ("root", "joints")},
               "train_graphs": [g.tensors() for g in train.graphs], "test_graphs": [g.tensors() for g in test.graphs],
               "test_names": [g.name for g in test.graphs],
               "train": [plain(windows[k]) for k in range(len(windows))],
               "test": [plain(whole[k]) for k in range(len(whole))],
               "config": str(config), "overrides": overrides}
    out.parent.mkdir(parents=True, exist_ok=True)
    torch.save(payload, out)
    print(f"{len(payload['train'])} training windows, {len(payload['test'])} held-out sequences -> {out}")


def model_from_payload(payload: dict, cfg):
    """A SwinGar of the exported sizes with the exported input statistics (``payload["stats"]``: root and joints,
    each ``[mean, std]`` tensors), untrained, on the CPU."""
    from loosefit.models.swingar import SwinGar

    model = SwinGar(payload["sizes"], cfg.model)
    with torch.no_grad():
        for key in ("root", "joints"):
            getattr(model, f"{key}_mean").copy_(payload["stats"][key][0])
            getattr(model, f"{key}_std").copy_(payload["stats"][key][1])
    return model


def train_and_score(payload: dict, cfg, device: torch.device, seed: int) -> dict:
    from loosefit.models.layers.gat_ln import recording_attention
    from loosefit.models.multi_garment import collate_by_graph

    torch.manual_seed(seed)
    model = model_from_payload(payload, cfg).to(device)

    def on_device(item, graphs):
        out = {k: (v.to(device) if torch.is_tensor(v) else v) for k, v in item.items()}
        out["graph_tensors"] = graphs[item["graph"]]
        return out

    train_graphs = [{k: v.to(device) for k, v in g.items()} for g in payload["train_graphs"]]
    test_graphs = [{k: v.to(device) for k, v in g.items()} for g in payload["test_graphs"]]
    items = [on_device(it, train_graphs) for it in payload["train"]]
    opt = torch.optim.Adam(model.parameters(), cfg.train.lr)
    rng = np.random.default_rng(seed)
    curve, t0 = [], time.time()
    for stage, stage_cfg in cfg.train.stages.items():
        sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, T_max=max(stage_cfg.epochs, 1), eta_min=cfg.train.min_lr)
        for g in opt.param_groups:
            g["lr"] = cfg.train.lr
        for epoch in range(stage_cfg.epochs):
            order, total, count = rng.permutation(len(items)), 0.0, 0
            for a in range(0, len(order), cfg.train.batch_size):
                batch = collate_by_graph([items[k] for k in order[a:a + cfg.train.batch_size]])
                loss, logged = model.training_loss(batch, stage)
                opt.zero_grad()
                loss.backward()
                opt.step()
                total, count = total + float(loss), count + 1
            sched.step()
            curve.append({"stage": stage, "epoch": epoch, "train_loss": total / count, "seconds": time.time() - t0})
    model.eval()
    rows = {}
    with torch.no_grad(), recording_attention(model) as log:
        for item in payload["test"]:
            group = collate_by_graph([on_device(item, test_graphs)])[0]
            err = model.predict_batch(group) - group["verts"]
            name = f"{payload['test_names'][item['graph']]}/{item['sequence']}"
            rows[name] = float(err.square().sum(-1).mean().sqrt()) * 1e3
    entropy = {k: {"entropy": float(np.mean([v[0] for v in vals])), "uniform": float(np.mean([v[1] for v in vals]))}
               for k, vals in log.items() if vals}
    for v in entropy.values():
        v["ratio"] = v["entropy"] / v["uniform"]
    return {"rmse_mm": rows, "mean_rmse_mm": float(np.mean(list(rows.values()))), "entropy": entropy,
            "train_curve": curve}


#: Memorisation hypotheses: name -> (overrides, module constants of models/swingar.py patched, lr).
MEMORISE = {
    "base": ([], {}, 1e-3),
    "first-attention": (["model.gate_attention=shared", "model.attention_norm=graph", "model.attention_centred=false",
                         "model.concat_heads=false"], {}, 1e-3),
    "skinning-prior": (["model.skinning_prior=true"], {}, 1e-3),
    "lr-3e-3": ([], {}, 3e-3),
    "lr-1e-2": ([], {}, 1e-2),
    "output-init-1": ([], {"OUTPUT_INIT": 1.0}, 1e-3),
    "plain-gat": (["model.alpha=null"], {}, 1e-3),
    "prior-lr-3e-3": (["model.skinning_prior=true"], {}, 3e-3),
}


def window_errors(model, batch: list[dict]) -> dict[str, float]:
    """RMSE (mm) of ``model`` on the collated windows ``batch`` (groups by garment graph), and of its coarse
    mesh, in the same frame as the output: the output less its correction."""
    with torch.no_grad():
        sq = csq = n = 0.0
        for g in batch:
            out = model(g["graph_tensors"], g["root"], g["joints"],
                        state={"root": g["history_root"], "joints": g["history_joints"]})
            err = out["verts"] - g["verts"]
            sq += float(err.square().sum(-1).mean(-1).sum())
            csq += float((err - out["correction"]).square().sum(-1).mean(-1).sum())
            n += err.shape[0] * err.shape[1]
    return {"rmse_mm": (sq / n) ** 0.5 * 1e3, "coarse_rmse_mm": (csq / n) ** 0.5 * 1e3}


def memorise(windows: Path, out: Path, names: list[str], steps: int, count: int, overrides: list[str]) -> None:
    """Each hypothesis of :data:`MEMORISE` on the first ``count`` training windows of the first garment: Adam at a
    constant rate for ``steps`` steps on them alone (vertex term), the RMSE on them (and of the coarse mesh)."""
    stubbed = stub_missing()
    import loosefit.models.swingar as sw
    from loosefit.config import load_config
    from loosefit.models.multi_garment import collate_by_graph

    payload = torch.load(windows, weights_only=False)
    device = torch.device("cuda" if torch.cuda.is_available() else "cpu")
    graphs = [{k: v.to(device) for k, v in g.items()} for g in payload["train_graphs"]]
    picked = [it for it in payload["train"] if it["graph"] == 0][:count]
    batch = collate_by_graph([{**{k: (v.to(device) if torch.is_tensor(v) else v) for k, v in it.items()},
                               "graph_tensors": graphs[0]} for it in picked])
    results = {"device": str(device), "stubbed": stubbed, "frames": sum(int(b["root"].shape[0] * b["root"].shape[1])
                                                                          for b in batch), "steps": steps, "runs": {}}
    for name in names:
        extra, patch, lr = MEMORISE[name]
        saved = {k: getattr(sw, k) for k in patch}
        for k, v in patch.items():
            setattr(sw, k, v)
        try:
            cfg = load_config(sw.Config, ROOT / "configs" / "models" / "swingar-cpu.yaml",
                              [*payload["overrides"], *extra, *overrides])
            torch.manual_seed(0)
            model = model_from_payload(payload, cfg).to(device)  # the patched module constants apply
            opt = torch.optim.Adam(model.parameters(), lr)
            curve, t0 = [], time.time()
            for step in range(steps + 1):
                loss, _ = model.training_loss(batch, "supervised")
                if step % max(steps // 20, 1) == 0 or step == steps:
                    curve.append({"step": step, **window_errors(model, batch), "seconds": time.time() - t0})
                if step == steps:
                    break
                opt.zero_grad()
                loss.backward()
                opt.step()
            results["runs"][name] = {"overrides": extra, "patch": patch, "lr": lr, "curve": curve,
                                     "final_rmse_mm": curve[-1]["rmse_mm"], "final_coarse_rmse_mm": curve[-1]["coarse_rmse_mm"]}
            print(name, round(curve[-1]["rmse_mm"], 2), round(curve[-1]["coarse_rmse_mm"], 2), f"{curve[-1]['seconds']:.0f} s",
                  flush=True)
        finally:
            for k, v in saved.items():
                setattr(sw, k, v)
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps(results, indent=1))


def curve(windows: Path, out: Path, designs: list[str], variants: list[str], seeds: list[int], overrides: list[str]):
    stubbed = stub_missing()
    from loosefit.config import load_config
    from loosefit.models.swingar import Config

    sys.path.insert(0, str(ROOT / "benchmarks" / "experiments"))  # swingar_attention
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from swingar_attention import design_overrides

    payload = torch.load(windows, weights_only=False)
    device = torch.device("cuda" if torch.cuda.is_available() else "cpu")
    config = ROOT / "configs" / "models" / "swingar-cpu.yaml"
    results = {"device": torch.cuda.get_device_name() if device.type == "cuda" else "cpu", "stubbed": stubbed,
               "export_overrides": payload["overrides"], "overrides": overrides, "runs": {}}
    for design in designs:
        for variant in variants:
            alpha = "null" if ALPHAS[variant] is None else str(ALPHAS[variant])
            for seed in seeds:
                cfg = load_config(Config, config, [*payload["overrides"], *design_overrides(design),
                                                   f"model.alpha={alpha}", f"train.seed={seed}", *overrides])
                t0 = time.time()
                scores = train_and_score(payload, cfg, device, seed)
                scores["seconds"] = time.time() - t0
                results["runs"][f"{design}/{variant}/seed-{seed}"] = scores
                print(design, variant, seed, round(scores["mean_rmse_mm"], 2), f"{scores['seconds']:.0f} s", flush=True)
                out.parent.mkdir(parents=True, exist_ok=True)
                out.write_text(json.dumps(results, indent=1))  # after every run: a cut-off call keeps what it did


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    sp = sub.add_parser("export")
    sp.add_argument("--data", required=True)
    sp.add_argument("--out", required=True)
    sp.add_argument("--config", default=str(ROOT / "configs" / "models" / "swingar-cpu.yaml"))
    sp.add_argument("--set", action="append", default=[])
    sp = sub.add_parser("curve")
    sp.add_argument("--windows", required=True)
    sp.add_argument("--out", required=True)
    sp.add_argument("--designs", default="node-centred")
    sp.add_argument("--variants", default=",".join(ALPHAS))
    sp.add_argument("--seeds", default="0,1")
    sp.add_argument("--set", action="append", default=[])
    sp = sub.add_parser("memorise")
    sp.add_argument("--windows", required=True)
    sp.add_argument("--out", required=True)
    sp.add_argument("--runs", default=",".join(MEMORISE))
    sp.add_argument("--steps", type=int, default=1500)
    sp.add_argument("--count", type=int, default=1)
    sp.add_argument("--set", action="append", default=[])
    args = parser.parse_args()
    sys.path.insert(0, str(ROOT / "src"))
    if args.command == "export":
        export(Path(args.data), Path(args.out), Path(args.config), args.set)
    elif args.command == "memorise":
        memorise(Path(args.windows), Path(args.out), args.runs.split(","), args.steps, args.count, args.set)
    else:
        curve(Path(args.windows), Path(args.out), args.designs.split(","), args.variants.split(","),
              [int(s) for s in args.seeds.split(",")], args.set)


if __name__ == "__main__":
    main()

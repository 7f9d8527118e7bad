"""Outputs that used to be silently wrong: a 60 fps motion animated frame for frame as if at 30 fps, a
checkpoint with an infinite statistic accepted, ``evaluate --out RUN`` replacing the run's training log,
``report.md`` carrying a run name's raw HTML."""

from __future__ import annotations

import hashlib
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch

from loosefit.cli import main
from loosefit.report.build import markdown_text
from tests.robustness.cases_pipeline import GARMENT, TINY_TRAIN


@pytest.fixture(scope="module")
def run(tiny_store, tmp_path_factory):
    """A tiny virtualbones run trained to the end."""
    folder = tmp_path_factory.mktemp("silent") / "run"
    assert main(["train", "--method", "virtualbones", "--data", str(tiny_store), "--garment", GARMENT, "--out",
                 str(folder), *TINY_TRAIN]) == 0
    return folder


def _motion(tmp_path: Path, fps: float) -> Path:
    path = tmp_path / f"walk{fps:g}.npz"
    assert main(["motion", "generate", "--kind", "walk", "--seconds", "1", "--fps", f"{fps:g}", "--out", str(path)]) == 0
    return path


def test_a_60_fps_motion_is_resampled_to_the_models_rate(run, tmp_path, capsys):
    at60, at30 = _motion(tmp_path, 60), _motion(tmp_path, 30)
    outs = {}
    for name, motion in (("60", at60), ("30", at30)):
        outs[name] = tmp_path / f"anim{name}.npz"
        assert main(["animate", str(run), "--motion", str(motion), "--collision", "none", "--out", str(outs[name])]) == 0
    err = capsys.readouterr().err
    assert f"{at60}: 60 frames at 60 fps, resampled to the model's 30 fps (30 frames)" in err, err
    assert str(at30) not in err
    a60, a30 = (np.load(outs[k]) for k in ("60", "30"))
    # the same second of walking at the model's rate: as many frames as the 30 fps motion, not twice as many
    assert float(a60["fps"]) == float(a30["fps"]) == 30.0
    assert a60["verts"].shape[0] == a30["verts"].shape[0] == 30


def test_a_checkpoint_with_an_infinite_statistic_is_refused_naming_the_tensor(run, tmp_path, capsys):
    bad = Path(shutil.copytree(run, tmp_path / "run"))
    name = None
    for ckpt in sorted((bad / "checkpoints").glob("*.pt")):
        state = torch.load(ckpt, map_location="cpu", weights_only=True)
        floats = [k for k, v in state["model"].items() if v.is_floating_point() and v.numel()]
        name = next((k for k in floats if "mean" in k or "std" in k or "stat" in k), floats[0])
        state["model"][name].view(-1)[0] = float("inf")
        torch.save(state, ckpt)
    motion = _motion(tmp_path, 30)
    out = tmp_path / "anim.npz"
    assert main(["animate", str(bad), "--motion", str(motion), "--collision", "none", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"checkpoint tensor {name!r}" in err and "holds 1 NaN or infinite value(s)" in err, err
    assert "/checkpoints/" in err and not out.exists()


def test_evaluate_keeps_a_runs_training_log_unless_forced(run, tmp_path, capsys):
    folder = Path(shutil.copytree(run, tmp_path / "run"))
    log = folder / "metrics.csv"
    before = hashlib.sha256(log.read_bytes()).hexdigest()
    anim = tmp_path / "anim.npz"
    assert main(["animate", str(folder), "--motion", str(_motion(tmp_path, 30)), "--out", str(anim)]) == 0
    assert main(["evaluate", str(anim), str(anim), "--out", str(folder)]) == 2
    err = capsys.readouterr().err
    assert f"loosefit evaluate: error: {log}: this is the training log of the training run folder {folder}" in err \
           and "--force" in err, err
    assert hashlib.sha256(log.read_bytes()).hexdigest() == before
    assert main(["evaluate", str(anim), str(anim), "--out", str(folder), "--force"]) == 0
    assert hashlib.sha256(log.read_bytes()).hexdigest() != before
    other = tmp_path / "scores"  # any other folder is written as before
    assert main(["evaluate", str(anim), str(anim), "--out", str(other)]) == 0 and (other / "metrics.csv").is_file()


def test_report_md_escapes_names():
    name = "<img src=x onerror=alert(1)>|run`x`\nnext"
    text = markdown_text(name)
    assert "<" not in text and ">" not in text and "\n" not in text
    assert text == "&lt;img src=x onerror=alert(1)&gt;\\|run\\`x\\` next"


def test_report_md_template_filters_every_name():
    template = (Path(__import__("loosefit.report", fromlist=["x"]).__file__).parent / "templates" / "report.md.j2")
    text = template.read_text()
    for field in ("s.name", "s.garment", "m.label", "r.name", "p.sequence"):
        uses = text.count("{{ " + field + " ") + text.count("{{ " + field + "}}") + text.count("{{ " + field + "|")
        assert uses and uses == text.count("{{ " + field + "|md }}"), field

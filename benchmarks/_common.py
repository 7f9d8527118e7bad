"""Shared helpers for benchmark scripts: machine description and atomic JSON results."""

from __future__ import annotations

import json
import os
import platform
import time
from pathlib import Path

from loosefit.paths import atomic_path

RESULTS = Path(__file__).resolve().parent / "results"


def machine() -> dict:
    """What the numbers were measured on."""
    import torch

    return {
        "platform": platform.platform(),
        "python": platform.python_version(),
        "cpus": os.cpu_count(),
        "torch_threads": torch.get_num_threads(),
        "date": time.strftime("%Y-%m-%d %H:%M:%S"),
    }


def save_results(name: str, results: dict) -> Path:
    """Write ``benchmarks/results/<name>.json`` atomically and print it."""
    path = RESULTS / f"{name}.json"
    payload = {"benchmark": name, "machine": machine(), "results": results}
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(payload, indent=2))
    print(json.dumps(payload, indent=2))
    return path

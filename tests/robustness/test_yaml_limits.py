"""Hostile YAML (plans, training configs, joint maps, parameter files): a "billion laughs" bomb, deep nesting,
self-referring aliases and huge documents are refused quickly, in little memory, naming the file and the limit."""

from __future__ import annotations

import time
import tracemalloc

import pytest

from loosefit.cli import main
from loosefit.config import MAX_YAML_CHARS, MAX_YAML_DEPTH, MAX_YAML_VALUES, load_config, load_yaml
from loosefit.errors import InputError
from loosefit.motion.joint_map import load_joint_map
from loosefit.sim.params import SimParams
from tests.robustness.craft import yaml_bomb, yaml_deep


def _refused_quickly(call, *match: str) -> InputError:
    tracemalloc.start()
    start = time.perf_counter()
    try:
        with pytest.raises(InputError) as info:
            call()
        seconds = time.perf_counter() - start
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert seconds < 1.0, seconds
    assert peak < 200e6, peak
    for text in match:
        assert text in str(info.value), str(info.value)
    return info.value


def test_billion_laughs_is_refused_in_under_a_second_and_little_memory(tmp_path):
    text = yaml_bomb()
    assert len(text) < 800  # a plan of 0.7 KB
    path = tmp_path / "bomb.yaml"
    path.write_text(text)
    _refused_quickly(lambda: load_yaml(text, path), str(path), f"{MAX_YAML_VALUES:,} values", "MAX_YAML_VALUES")


def test_a_bomb_below_the_limit_still_reads():
    data = load_yaml(yaml_bomb(levels=4))  # 10,000 values: an ordinary use of aliases
    assert len(data["l3"]) == 10 and data["l3"][0][0][0] == ["lol"] * 10


def test_aliases_chained_deeper_than_the_limit_are_refused(tmp_path):
    # each line one level deeper than the one before, though the text itself is shallow
    lines = ["a0: &a0 [1]"] + [f"a{k}: &a{k} [*a{k - 1}]" for k in range(1, MAX_YAML_DEPTH + 5)]
    path = tmp_path / "chain.yaml"
    _refused_quickly(lambda: load_yaml("\n".join(lines), path), str(path), f"{MAX_YAML_DEPTH} levels")


def test_self_referring_alias_is_refused(tmp_path):
    path = tmp_path / "loop.yaml"
    _refused_quickly(lambda: load_yaml("a: &a [1, *a]\n", path), str(path), "contains itself")


@pytest.mark.parametrize("text", [yaml_deep(MAX_YAML_DEPTH + 1), yaml_deep(100_000), "a: " + "{a: " * 100_000 + "1" + "}" * 100_000,
                                  "- " * 1_000_000 + "1\n", "".join(" " * k + f"k{k}:\n" for k in range(2000))],
                         ids=["flow-65", "flow-100k", "mapping-100k", "block-1M", "indent-2k"])
def test_deep_nesting_is_refused_without_recursion_error(tmp_path, text):
    path = tmp_path / "deep.yaml"
    _refused_quickly(lambda: load_yaml(text, path), str(path), f"more than {MAX_YAML_DEPTH} levels")


def test_nesting_at_the_limit_reads():
    value = load_yaml(yaml_deep(MAX_YAML_DEPTH - 2))
    for _ in range(MAX_YAML_DEPTH - 2):
        value = value["a"] if isinstance(value, dict) else value[0]
    assert value == [1] or value == 1


def test_document_longer_than_the_limit_is_refused(tmp_path):
    path = tmp_path / "big.yaml"
    path.write_text("a: [" + "1, " * (MAX_YAML_CHARS // 3 + 10) + "1]\n")
    from loosefit.train.settings import TrainConfig

    _refused_quickly(lambda: load_config(TrainConfig, path), str(path), "MAX_YAML_CHARS")


def test_every_yaml_reader_refuses_a_bomb(tmp_path):
    path = tmp_path / "bomb.yaml"
    path.write_text(yaml_bomb())
    from loosefit.train.settings import TrainConfig

    for read in (lambda: load_config(TrainConfig, path), lambda: SimParams.load(path), lambda: load_joint_map(path)):
        _refused_quickly(read, str(path), "YAML bomb")


def test_cli_refuses_a_bomb_plan_naming_it(tmp_path, capsys):
    plan = tmp_path / "bomb.yaml"
    plan.write_text(yaml_bomb())
    start = time.perf_counter()
    assert main(["simulate", str(plan), "--out", str(tmp_path / "d.zarr")]) == 2
    assert time.perf_counter() - start < 5.0  # imports included
    err = capsys.readouterr().err
    assert f"loosefit simulate: error: {plan}: YAML document refused" in err and "Traceback" not in err
    assert not (tmp_path / "d.zarr").exists()


def test_cli_refuses_a_deep_training_config(tmp_path, capsys):
    config = tmp_path / "deep.yaml"
    config.write_text("train:\n  stages: " + "{a: " * 5000 + "1" + "}" * 5000 + "\n")
    assert main(["train", "--method", "virtualbones", "--data", str(tmp_path / "none.zarr"), "--garment", "g",
                 "--config", str(config), "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err
    assert f"{config}: YAML document refused: nested more than {MAX_YAML_DEPTH} levels deep" in err, err
    assert not (tmp_path / "run").exists()

"""Typed configs: YAML onto nested dataclasses, overrides, type errors naming file and key, round trips."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal, Optional

import pytest

from loosefit.config import (
    apply_overrides,
    config_from_dict,
    config_to_dict,
    load_config,
    load_yaml,
    parse_override,
    save_config,
)
from loosefit.errors import InputError
from loosefit.train import StageConfig, TrainConfig


@dataclass(frozen=True)
class Inner:
    a: int = 1
    b: float = 2.0
    tags: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class Outer:
    name: str
    inner: Inner = field(default_factory=Inner)
    extra: Optional[Inner] = None
    sizes: tuple[int, ...] = (64, 64)
    pair: tuple[int, float] = (1, 0.5)
    table: dict[str, Inner] = field(default_factory=dict)
    out: Path = Path("out")
    flag: bool = False
    maybe: int | None = 3
    mode: Literal["fast", "slow"] = "fast"
    either: int | str = 0


def _write(tmp_path, text: str) -> Path:
    path = tmp_path / "cfg.yaml"
    path.write_text(text)
    return path


def test_yaml_fills_nested_fields_and_keeps_defaults(tmp_path):
    path = _write(
        tmp_path,
        "name: run\ninner: {b: 3, tags: [x, y]}\nextra: {a: 7}\nsizes: [1, 2, 3]\npair: [4, 5]\n"
        "table: {low: {a: 2}, high: {b: 1e-3}}\nout: /tmp/o\nflag: true\nmaybe: null\nmode: slow\neither: abc\n",
    )
    cfg = load_config(Outer, path)
    assert cfg == Outer(
        name="run",
        inner=Inner(a=1, b=3.0, tags=["x", "y"]),
        extra=Inner(a=7),
        sizes=(1, 2, 3),
        pair=(4, 5.0),
        table={"low": Inner(a=2), "high": Inner(b=0.001)},
        out=Path("/tmp/o"),
        flag=True,
        maybe=None,
        mode="slow",
        either="abc",
    )
    assert isinstance(cfg.inner.b, float) and isinstance(cfg.pair[1], float)
    assert isinstance(cfg.table["high"].b, float)  # "1e-3" (YAML 1.1 would give a string)


@pytest.mark.parametrize(
    "text, message",
    [
        ("name: x\ninner: {c: 1}\n", r"unknown key 'inner\.c'"),
        ("name: x\nspeed: 1\n", r"unknown key 'speed'"),
        ("name: x\ninner: {a: 1.5}\n", r"'inner\.a': expected an integer, got float 1\.5"),
        ("name: x\ninner: {a: true}\n", r"'inner\.a': expected an integer"),
        ("name: x\nflag: 1\n", r"'flag': expected true or false"),
        ("name: 12\n", r"'name': expected a string, got int 12 \(quote it"),
        ("name: x\ninner: {tags: [a, 3]}\n", r"'inner\.tags\[1\]': expected a string"),
        ("name: x\npair: [1, 2, 3]\n", r"'pair': expected a list of 2 items, got 3"),
        ("name: x\nmode: medium\n", r"'mode': must be one of \['fast', 'slow'\]"),
        ("name: x\ntable: {low: {a: x}}\n", r"'table\.low\.a': expected an integer"),
        ("name: x\ninner: 5\n", r"'inner': expected a mapping of Inner fields"),
        ("name: x\neither: [1]\n", r"'either': expected int \| str"),
        ("inner: {}\n", r"'name': missing"),
        ("- a\n- b\n", r"must be a YAML mapping"),
        ("name: [unclosed\n", r"invalid YAML"),
    ],
)
def test_bad_files_name_file_and_key(tmp_path, text, message):
    path = _write(tmp_path, text)
    with pytest.raises(InputError, match=message) as info:
        load_config(Outer, path)
    assert info.value.path == path and str(path) in str(info.value)


def test_missing_file(tmp_path):
    with pytest.raises(InputError, match="cannot read config") as info:
        load_config(Outer, tmp_path / "nope.yaml")
    assert info.value.path == tmp_path / "nope.yaml"


def test_overrides_walk_dataclasses_and_dicts(tmp_path):
    path = _write(tmp_path, "name: run\ntable: {low: {a: 2}}\n")
    cfg = load_config(
        Outer,
        path,
        ["inner.a=5", "table.low.b=1e-4", "table.new.tags=[p, q]", "extra.b=0.5", "sizes=[8]", "maybe=null",
         "name=other", "out=runs/x"],
    )
    assert cfg.inner == Inner(a=5)
    assert cfg.table == {"low": Inner(a=2, b=1e-4), "new": Inner(tags=["p", "q"])}
    assert cfg.extra == Inner(b=0.5)
    assert cfg.sizes == (8,) and cfg.maybe is None and cfg.name == "other" and cfg.out == Path("runs/x")
    # later overrides win, earlier ones stay
    assert apply_overrides(cfg, ["inner.a=6", "inner.b=7"]).inner == Inner(a=6, b=7.0)


@pytest.mark.parametrize(
    "override, message",
    [
        ("inner.a", r"expected KEY=VALUE"),
        ("=3", r"expected KEY=VALUE"),
        ("inner..a=3", r"expected KEY=VALUE"),
        ("inner.zz=3", r"override 'inner\.zz=3'.*unknown key 'inner\.zz'"),
        ("inner.a=abc", r"override 'inner\.a=abc'.*'inner\.a': expected an integer, got str 'abc'"),
        ("flag=[1", r"invalid YAML"),
    ],
)
def test_bad_overrides(override, message):
    with pytest.raises(InputError, match=message):
        apply_overrides(Outer(name="x"), [override])


def test_parse_override_values():
    assert parse_override("a.b=1e-3") == (["a", "b"], 0.001)
    assert parse_override("a=1.5e3") == (["a"], 1500.0) and parse_override("a=-2E+2") == (["a"], -200.0)
    assert parse_override("a=") == (["a"], None)
    assert parse_override(" a = [1, 2] ") == (["a"], [1, 2])
    assert parse_override("a=x=y") == (["a"], "x=y")
    assert parse_override("a=2") == (["a"], 2) and isinstance(parse_override("a=2")[1], int)


def test_save_load_round_trip(tmp_path):
    cfg = Outer(name="run", extra=Inner(a=3, tags=["t"]), table={"k": Inner(b=1e-7)}, out=Path("/x/y"), flag=True)
    path = save_config(tmp_path / "sub" / "saved.yaml", cfg)
    assert load_config(Outer, path) == cfg
    assert config_to_dict(cfg)["sizes"] == [64, 64] and config_to_dict(cfg)["out"] == "/x/y"
    assert not list(path.parent.glob(".saved.yaml*"))  # no temporary file left by the atomic write


def test_no_file_gives_defaults_and_overrides():
    assert load_config(TrainConfig) == TrainConfig()
    cfg = load_config(TrainConfig, None, ["stages.low.epochs=20", "stages.low.lr=1e-4", "lr=3e-3", "grad_clip=1"])
    assert cfg.stages == {"low": StageConfig(epochs=20, lr=1e-4)} and cfg.lr == 0.003 and cfg.grad_clip == 1.0
    assert cfg.stage("low") == StageConfig(
        epochs=20, lr=1e-4, weight_decay=0.0, batch_size=8, schedule="cosine", grad_clip=1.0
    )
    assert cfg.stage("high").epochs == 10 and cfg.stage("high").lr == 0.003


def test_value_checks_of_the_dataclass_name_the_file(tmp_path):
    path = _write(tmp_path, "stages: {low: {batch_size: 0}}\n")
    with pytest.raises(InputError, match=r"stages\.low\.epochs must be >= 0 and stages\.low\.batch_size >= 1") as info:
        load_config(TrainConfig, path)
    assert info.value.path == path
    with pytest.raises(InputError, match="threads must be >= 1"):
        load_config(TrainConfig, None, ["threads=0"])
    with pytest.raises(InputError, match=r"'schedule': must be one of \['cosine', 'step', 'none'\]"):
        load_config(TrainConfig, None, ["schedule=linear"])


@pytest.mark.parametrize(
    "text, key, line, first",
    [
        ("name: x\nflag: true\nname: y\n", "name", 3, 1),
        ("name: x\ninner:\n  a: 1\n  b: 2.0\n  a: 5\n", "a", 5, 3),
        ("name: x\ntable: {low: {a: 1}, low: {a: 2}}\n", "low", 2, 2),
        ("name: x\n1: a\n1: b\n", 1, 3, 2),
    ],
)
def test_duplicate_keys_are_refused_with_their_lines(tmp_path, text, key, line, first):
    path = _write(tmp_path, text)
    with pytest.raises(InputError) as info:
        load_config(Outer, path)
    assert str(info.value).startswith(f"{path}: duplicate key {key!r} on line {line} (first on line {first})")


def test_merge_keys_may_be_overridden_and_override_values_are_checked(tmp_path):
    text = "name: x\nbase: &base {a: 1, b: 2.0}\n"
    cfg = config_from_dict(Outer, {k: v for k, v in load_yaml(text + "inner: {<<: *base, a: 7}\n").items() if k != "base"})
    assert cfg.inner == Inner(a=7, b=2.0)
    with pytest.raises(InputError, match=r"override 'inner=\{a: 1, a: 2\}': duplicate key 'a'"):
        apply_overrides(Outer(name="x"), ["inner={a: 1, a: 2}"])

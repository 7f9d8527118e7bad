"""Command-line values that used to pass silently: NaN / infinite numeric options, a shape key given twice,
an unbounded procedural motion length or frame rate. Each is refused, exit 2, naming the option or the limit."""

from __future__ import annotations

import pytest

from loosefit.cli import main
from loosefit.motion.procedural import MAX_FPS, MAX_SECONDS


def _usage_error(argv: list[str], capsys) -> str:
    with pytest.raises(SystemExit) as info:
        main(argv)
    assert info.value.code == 2
    return capsys.readouterr().err


@pytest.mark.parametrize("option", ["--sted-c", "--sted-dt", "--tolerance"])
@pytest.mark.parametrize("value", ["nan", "inf", "-inf"])
def test_evaluate_refuses_non_finite_numbers(tmp_path, capsys, option, value):
    out = tmp_path / "scores"
    err = _usage_error(["evaluate", "pred.npz", "gt.npz", "--out", str(out), f"{option}={value}"], capsys)
    assert f"argument {option}: must be a finite number, got {value}" in err, err
    assert not out.exists()


@pytest.mark.parametrize("option", ["--length", "--flare"])
def test_garment_make_refuses_nan(tmp_path, capsys, option):
    err = _usage_error(["garment", "make", "--kind", "skirt", option, "nan", "--out", str(tmp_path / "g.obj")], capsys)
    assert f"argument {option}: must be a finite number, got nan" in err, err


def test_repeated_shape_key_is_refused(tmp_path, capsys):
    out = tmp_path / "body.obj"
    assert main(["body", "--shape", "height=0.1,height=0.9", "--resolution", "low", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "height is given twice" in err and "'height=0.1,height=0.9'" in err, err
    assert not out.exists()


def test_a_shape_key_once_each_still_works(tmp_path, capsys):
    out = tmp_path / "body.obj"
    assert main(["body", "--shape", "height=0.1,weight=0.9", "--resolution", "low", "--out", str(out)]) == 0
    assert out.is_file()


@pytest.mark.parametrize("extra,limit", [(["--seconds", "1000000"], f"({MAX_SECONDS:g} s: "),
                                         (["--start", "3599", "--seconds", "2"], f"({MAX_SECONDS:g} s: "),
                                         (["--fps", "100000"], f"to {MAX_FPS:g}: ")])
def test_motion_generate_is_bounded(tmp_path, capsys, extra, limit):
    out = tmp_path / "m.npz"
    assert main(["motion", "generate", "--kind", "walk", *extra, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("loosefit motion: error: ") and limit in err and "loosefit.motion.procedural." in err, err
    assert not out.exists()

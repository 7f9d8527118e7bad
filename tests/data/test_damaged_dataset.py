"""A simulated and prepared dataset (the session's ``tiny_store``), damaged on disk: the stages that
read it (train, prepare, view, report) stop with an InputError naming the damaged file, and running
the plan again simulates the damaged sequence again, exactly as before."""

from __future__ import annotations

import re
import shutil

import numpy as np
import pytest

from loosefit.data import DatasetStore
from loosefit.errors import InputError
from tests.conftest import TINY_PLAN
from tests.data.test_integrity import truncate

WALK, SWAY = "skirt+average+walk+default", "skirt+average+sway+default"


@pytest.fixture
def copy(tiny_store, tmp_path):
    shutil.copytree(tiny_store, tmp_path / "tiny.zarr")
    return tmp_path / "tiny.zarr"


def test_damaged_chunk_stops_train_and_view_and_resume_simulates_it_again(copy, tiny_store, tmp_path):
    from loosefit.models.dataset import GarmentSequences
    from loosefit.simulate import run_plan
    from loosefit.viz.inputs import dataset_panel

    chunk = copy / "sequences" / WALK / "verts" / "0.0.0"
    truncate(chunk)
    with pytest.raises(InputError, match="checksum mismatch") as err:
        GarmentSequences(copy, "skirt+average", "train")
    assert err.value.path == chunk
    with pytest.raises(InputError, match="checksum mismatch") as err:
        dataset_panel(copy, WALK)
    assert err.value.path == chunk

    plan = tmp_path / "tiny.yaml"
    plan.write_text(TINY_PLAN)
    summary = run_plan(plan, copy, progress=False)
    assert (summary["skipped"], summary["ok"], list(summary["sequences"])) == (2, 1, [WALK])
    resumed, reference = DatasetStore.open(copy), DatasetStore.open(tiny_store)
    assert resumed.problems() == {}
    np.testing.assert_array_equal(resumed.sequence(WALK).verts[:], reference.sequence(WALK).verts[:])


def test_garbage_attributes_stop_prepare_and_report(copy):
    from loosefit.report.predictions import load_sequences
    from loosefit.rig.prepare import prepare

    attrs = copy / "sequences" / SWAY / ".zattrs"
    attrs.write_text("\x00" * 40)
    for read in (lambda: prepare(copy, bones=8, progress=False), lambda: load_sequences(copy, split="test")):
        with pytest.raises(InputError, match=re.escape(f"corrupt sequence '{SWAY}': .zattrs is not valid JSON")) as err:
            read()
        assert err.value.path == attrs

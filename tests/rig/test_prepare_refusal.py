"""A refused ``prepare`` (a bone count the garment cannot have, a damaged training sequence) leaves a
prepared store exactly as it was: its rig stays usable."""

import hashlib
import re
import shutil

import pytest

from loosefit.data import DatasetStore
from loosefit.errors import InputError
from loosefit.rig.prepare import prepare
from loosefit.rig.prepared import load_rig


def digest(root):
    """Every file's name and bytes under ``root`` (the write lock's file left out)."""
    h = hashlib.sha256()
    for p in sorted(root.rglob("*")):
        if p.is_file() and p.name != ".lock":
            h.update(str(p.relative_to(root)).encode() + b"\0" + p.read_bytes())
    return h.hexdigest()


@pytest.fixture
def prepared_copy(tiny_store, tmp_path):
    return shutil.copytree(tiny_store, tmp_path / "data.zarr")


@pytest.mark.parametrize("bones", [0, -3, 10**6])
def test_impossible_bone_count_changes_nothing(prepared_copy, bones):
    before = digest(prepared_copy)
    with pytest.raises(InputError, match=rf"bones={bones}: garment 'skirt\+average' has \d+ vertices") as err:
        prepare(prepared_copy, bones=bones, force=True, progress=False)
    assert err.value.path == prepared_copy
    assert digest(prepared_copy) == before
    assert load_rig(DatasetStore.open(prepared_copy), "skirt+average").num_bones == 8


def test_damaged_training_sequence_changes_nothing(prepared_copy):
    store = DatasetStore.open(prepared_copy)
    name = store.sequence_names(split="train")[0]
    chunk = next(p for p in sorted((prepared_copy / "sequences" / name / "verts").iterdir())
                 if not p.name.startswith("."))
    chunk.write_bytes(chunk.read_bytes()[: chunk.stat().st_size // 2])
    before = digest(prepared_copy)
    with pytest.raises(InputError, match=rf"training sequence '{re.escape(name)}' is damaged \(verts/0\.0\.0: ") as err:
        prepare(prepared_copy, bones=6, force=True, progress=False)
    assert err.value.path == prepared_copy / "sequences" / name and "--repair" in str(err.value)
    assert digest(prepared_copy) == before
    assert load_rig(DatasetStore.open(prepared_copy), "skirt+average").num_bones == 8

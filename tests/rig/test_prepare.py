"""The prepare stage on a small dataset: what it stores against brute force, test data untouched, resume."""

from __future__ import annotations

import inspect
import shutil

import numpy as np
import pytest

import loosefit.rig.prepare as prep
from loosefit.data.store import DatasetStore
from loosefit.errors import InputError
from loosefit.geometry.smoothing import frequency_split
from loosefit.rig.prepare import prepare
from loosefit.rig.prepared import load_bone_transforms, load_descriptor, load_fit_attribute, load_rig, read_stats
from loosefit.rig.spectral import spectral_descriptor

SETTINGS = {"bones": 5, "iterations": 5, "max_solve_frames": 20, "descriptor_samples": 64, "progress": False}


@pytest.fixture(scope="module")
def dataset(tmp_path_factory, body, simulated_skirt):
    """A store: the simulated skirt (train: spin simulated, walk skinned; test: jump), a loose skirt
    (train: walk), a dress with only a test sequence; one body. Returned unprepared."""
    from loosefit.garment import make_garment
    from loosefit.motion.procedural import generate
    from loosefit.sim.attach import garment_weights, skin_garment

    skirt, frames, spin = simulated_skirt
    store = DatasetStore.create(tmp_path_factory.mktemp("prepare") / "data.zarr")
    store.add_body("default", body.shape.to_array())
    garments = {
        "skirt": skirt,
        "loose": make_garment("skirt", body, seed=1, edge_length=0.06, flare=30.0, hip_ease=0.08),
        "dress": make_garment("dress", body, seed=2, edge_length=0.06),
    }
    for name, g in garments.items():
        store.add_garment(name, g)
    motions = {"spin": spin, "walk": generate("walk", 1.0, 1, body), "jump": generate("jump", 0.7, 2, body)}
    for name, m in motions.items():
        store.add_motion(name, m)
    store.write_sequence("skirt-spin", frames, "skirt", "default", "spin", {}, {}, "train")
    for g, m, split in (
        ("skirt", "walk", "train"), ("skirt", "jump", "test"), ("loose", "walk", "train"), ("dress", "walk", "test")
    ):
        verts = skin_garment(garments[g].verts, garment_weights(garments[g].verts, body), body, motions[m])
        store.write_sequence(f"{g}-{m}", verts, g, "default", m, {}, {}, split)
    return store.path


@pytest.fixture(scope="module")
def prepared(dataset, tmp_path_factory, body):
    path = tmp_path_factory.mktemp("prepared") / "data.zarr"
    shutil.copytree(dataset, path)
    summary = prepare(path, body=body, **SETTINGS)
    return path, summary


def test_rig_transforms_reproduce_the_training_frames(prepared):
    path, summary = prepared
    store = DatasetStore.open(path)
    rig = load_rig(store, "skirt")
    assert rig.num_bones == summary["garments"]["skirt"]["bones"] <= 5
    np.testing.assert_allclose(rig.weight_values.sum(1), 1.0, atol=1e-5)
    garment = store.garment("skirt")
    faces = garment.faces
    sq, n = 0.0, 0
    translations = []
    for name in ("skirt-spin", "skirt-walk"):
        frames = store.sequence(name).verts[:]
        R, T = load_bone_transforms(store, "skirt", name)
        assert R.shape == (len(frames), rig.num_bones, 3, 3) and T.shape == (len(frames), rig.num_bones, 3)
        low = frequency_split(frames, faces, fixed=garment.pinned)[0]  # keep_pinned, the default
        sq += ((rig.skin(R, T) - low) ** 2).sum(-1).sum()
        n += low.shape[0] * low.shape[1]
        translations.append(T)
    assert np.sqrt(sq / n) * 1e3 == pytest.approx(summary["garments"]["skirt"]["rmse_lf_mm"], rel=1e-4)
    stats = read_stats(store, "skirt")
    T = np.concatenate(translations).astype(np.float64)
    np.testing.assert_allclose(stats["bone_translation"].mean, T.mean(0), atol=1e-6)
    np.testing.assert_allclose(stats["bone_translation"].std, T.std(0), atol=1e-6)
    # only training frames: spin (45) and walk (30), all vertices
    assert stats["garment_verts"].count == 75 * rig.num_verts
    with pytest.raises(InputError, match="not a training sequence"):
        load_bone_transforms(store, "skirt", "skirt-jump")
    with pytest.raises(InputError, match="not prepared"):
        load_rig(store, "dress")


def test_descriptors_fit_attributes_and_dataset_statistics(prepared, body):
    path, summary = prepared
    store = DatasetStore.open(path)
    for name in ("skirt", "loose", "dress"):
        g = store.garment(name)
        np.testing.assert_array_equal(load_descriptor(store, name), spectral_descriptor(g.verts, g.faces, samples=64))
    model, alpha = load_fit_attribute(store)
    assert sorted(alpha) == [("dress", "default"), ("loose", "default"), ("skirt", "default")]
    assert summary["fit_attribute"]["training_pairs"] == 2
    dress = store.garment("dress")
    expected = model.attribute(dress.verts, dress.faces, body.rest_verts())
    np.testing.assert_allclose(alpha[("dress", "default")], expected, atol=1e-6)
    assert alpha[("loose", "default")][0] > alpha[("skirt", "default")][0]
    stats = read_stats(store)
    rotations = np.concatenate([store.motion(m).rotations for m in ("spin", "walk", "walk")]).astype(np.float64)
    np.testing.assert_allclose(stats["body_rotation"].mean, rotations.mean(0), atol=1e-6)
    assert stats["body_rotation"].count == len(rotations)
    pooled = read_stats(store, "skirt")["garment_verts"].count + read_stats(store, "loose")["garment_verts"].count
    assert stats["garment_verts"].count == pooled
    assert stats["spectral_descriptor"].count == 2 and stats["fit_attribute"].count == 2


def test_resume_skips_finished_work_and_redoes_interrupted_garments(dataset, prepared, tmp_path, body, monkeypatch):
    path, _ = prepared
    again = prepare(path, body=body, **SETTINGS)
    assert all(entry.get("skipped") for entry in again["garments"].values() if "bones" in entry)
    # interrupted in the middle of the skirt's bone transforms
    fresh = tmp_path / "data.zarr"
    shutil.copytree(dataset, fresh)
    calls = []
    real = prep.solve_bone_transforms

    def crash(*args, **kwargs):
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real(*args, **kwargs)

    monkeypatch.setattr(prep, "solve_bone_transforms", crash)
    with pytest.raises(KeyboardInterrupt):
        prepare(fresh, body=body, **SETTINGS)
    monkeypatch.setattr(prep, "solve_bone_transforms", real)
    store = DatasetStore.open(fresh)
    # garments run in name order: loose (one chunk of transforms) finished, skirt interrupted
    assert store.read_attrs("garments/loose/rig")["status"] == "done"
    assert store.read_attrs("garments/skirt/rig")["status"] == "writing"
    with pytest.raises(InputError, match="not prepared"):
        load_rig(store, "skirt")
    prepare(fresh, body=body, **SETTINGS)
    done = DatasetStore.open(path)
    for garment, sequence in (("loose", "loose-walk"), ("skirt", "skirt-spin")):
        for a, b in zip(load_bone_transforms(store, garment, sequence), load_bone_transforms(done, garment, sequence)):
            np.testing.assert_array_equal(a, b)


def test_bad_input(tmp_path):
    with pytest.raises(InputError, match="no such dataset store"):
        prepare(tmp_path / "missing.zarr", progress=False)
    store = DatasetStore.create(tmp_path / "data.zarr")
    with pytest.raises(InputError, match="unknown prepare settings"):
        prepare(store.path, bone=3, progress=False)
    with pytest.raises(InputError, match="not prepared"):
        read_stats(store.path)


def test_settings_are_a_typed_config_with_one_bone_default():
    from loosefit.rig.prepare import PrepareSettings, prepare_settings
    from loosefit.rig.virtual_bones import DEFAULT_BONES, fit_virtual_bones

    assert prepare_settings() == PrepareSettings() and PrepareSettings().bones == DEFAULT_BONES == 80
    assert inspect.signature(fit_virtual_bones).parameters["bones"].default == DEFAULT_BONES
    assert prepare_settings({"bones": 12, "trans_affine": 1}).trans_affine == 1.0
    with pytest.raises(InputError, match=r"unknown prepare settings \['bone'\]; known: \['bones', 'influences'"):
        prepare_settings({"bone": 3})
    with pytest.raises(InputError, match="'influences': expected an integer"):
        prepare_settings({"influences": "many"})


def test_mirror_rigs_the_mirrored_training_sequences(dataset, prepared, tmp_path, body):
    """With ``mirror``, each training sequence's mirror joins the rig: its bone transforms skin its low-frequency
    frames with the error the summary reports over all frames, the statistics count both, test data stays out. A
    rig prepared without it names the setting when asked for a mirror."""
    from loosefit.data.mirror import GarmentMirror

    with pytest.raises(InputError, match="mirror=true"):
        load_bone_transforms(DatasetStore.open(prepared[0]), "skirt", "skirt-spin=mirrored")
    path = tmp_path / "data.zarr"
    shutil.copytree(dataset, path)
    summary = prepare(path, body=body, mirror=True, **SETTINGS)
    store = DatasetStore.open(path)
    rig, garment = load_rig(store, "skirt"), store.garment("skirt")
    mirror = GarmentMirror.build(garment.verts, garment.faces)
    sq = n = 0.0
    for name in ("skirt-spin", "skirt-walk"):
        frames = store.sequence(name).verts[:]
        for frames, key in ((frames, name), (mirror(frames), name + "=mirrored")):
            low = frequency_split(frames, garment.faces, fixed=garment.pinned)[0]
            sq += ((rig.skin(*load_bone_transforms(store, "skirt", key)) - low) ** 2).sum()
            n += low.shape[0] * low.shape[1]
    assert np.sqrt(sq / n) * 1e3 == pytest.approx(summary["garments"]["skirt"]["rmse_lf_mm"], rel=1e-4)
    assert read_stats(store, "skirt")["garment_verts"].count == 2 * 75 * rig.num_verts
    with pytest.raises(InputError, match="not a training sequence"):
        load_bone_transforms(store, "skirt", "skirt-jump=mirrored")

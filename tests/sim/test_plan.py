import pytest
import yaml

from loosefit.errors import InputError
from loosefit.sim.plan import load_plan

PLAN = {
    "name": "t",
    "shapes": {"average": {}, "tall": {"height": 0.8}},
    "garments": {"skirt": {"template": "skirt", "seed": 1, "edge_length": 0.04}, "mine": {"file": "g.obj", "shape": "average"}},
    "motions": {"walk": {"procedural": "walk", "seconds": 2}, "clip": {"file": "c.bvh", "joint_map": "cc", "start": 1}},
    "sim_params": {"default": {}, "stiff": {"bending": 1e-4}},
    "sequences": [{"garments": ["skirt"], "sim_params": ["default", "stiff"]}, {"garments": ["mine"], "sim_params": ["default"]}],
    "split": {"test": {"motions": ["clip"]}, "val": {"sim_params": ["stiff"]}},
}


def _write(tmp_path, plan, name="plan.yaml"):
    path = tmp_path / name
    path.write_text(yaml.safe_dump(plan))
    return path


def test_expansion_ids_and_splits(tmp_path):
    plan = load_plan(_write(tmp_path, PLAN))
    ids = {job.id: job for job in plan.jobs}
    # skirt: 2 shapes x 2 motions x 2 parameter sets; mine: its own shape only x 2 motions.
    assert len(ids) == 8 + 2
    job = ids["skirt+tall+walk+stiff"]
    assert (job.garment_entry, job.split) == ("skirt+tall", "val")
    assert ids["skirt+tall+clip+stiff"].split == "test"  # test wins over val
    assert ids["mine+average+walk+default"].split == "train"
    assert "mine+tall+walk+default" not in ids
    assert plan.resolve("g.obj") == tmp_path / "g.obj"
    assert plan.sim_params["stiff"].bending == 1e-4
    # Stable ids and hashes; the hash follows the content.
    again = load_plan(_write(tmp_path, PLAN, "copy.yaml"))
    assert [(j.id, j.hash) for j in again.jobs] == [(j.id, j.hash) for j in plan.jobs]
    changed = load_plan(_write(tmp_path, {**PLAN, "sim_params": {"default": {"density": 0.3}, "stiff": {"bending": 1e-4}}}))
    new = {j.id: j.hash for j in changed.jobs}
    assert new["skirt+tall+walk+stiff"] == job.hash and new["skirt+tall+walk+default"] != ids["skirt+tall+walk+default"].hash


def test_everything_by_default(tmp_path):
    plan = load_plan(_write(tmp_path, {"garments": {"g": {"template": "dress"}}, "motions": {"m": {"procedural": "spin", "seconds": 1}}}))
    assert [j.id for j in plan.jobs] == ["g+average+m+default"] and plan.name == "plan"


@pytest.mark.parametrize(
    "change, message",
    [
        ({"extra": 1}, "unknown keys \\['extra'\\]"),
        ({"garments": {"a+b": {"template": "skirt"}}}, "'a\\+b' must be"),
        ({"garments": {"g": {"template": "skirt", "file": "x.obj"}}}, "exactly one of"),
        ({"motions": {"m": {"procedural": "walk"}}}, "'seconds' must be a positive number"),
        ({"motions": {"m": {"file": "x.bvh", "start": -1}}}, "'start' must be an integer"),
        ({"shapes": {"s": {"heigth": 0.5}}}, "unknown values \\['heigth'\\]"),
        ({"sim_params": {"p": {"density": -1}}}, "density"),
        ({"sequences": [{"motions": ["run"]}]}, "motion 'run' is not defined"),
        ({"split": {"test": {"garments": ["coat"]}}}, "garments 'coat' is not defined"),
        ({"split": {"holdout": {}}}, "unknown keys \\['holdout'\\]"),
        ({"garments": {"mine": {"file": "g.obj", "shape": "huge"}}}, "shape 'huge' is not in shapes"),
        ({"gate": {"max_penetraton": 0.1}}, "unknown quality gate limits"),
    ],
)
def test_errors_name_the_plan(tmp_path, change, message):
    with pytest.raises(InputError, match=message) as err:
        load_plan(_write(tmp_path, {**PLAN, **change}))
    assert "plan.yaml" in str(err.value)


def test_unreadable_plan(tmp_path):
    with pytest.raises(InputError, match="missing.yaml.*cannot read"):
        load_plan(tmp_path / "missing.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("[1, 2]")
    with pytest.raises(InputError, match="bad.yaml.*mapping"):
        load_plan(bad)


def test_shipped_plans():
    from pathlib import Path

    root = Path(__file__).parents[2] / "configs" / "datasets"
    plans = {p.stem: load_plan(p) for p in root.glob("*.yaml")}
    assert set(plans) >= {"demo", "bench", "bench-mocap", "simparams", "garments"}
    bench = plans["bench"]
    assert len(bench.garments) == 2 and len(bench.sim_params) == 1 and set(bench.shapes) == {"average"}
    assert len(bench.motions) >= 16 and all(m["seconds"] * 30 >= 300 for m in bench.motions.values())
    kinds = {m["procedural"] for m in bench.motions.values()}
    assert kinds >= {"walk", "run", "spin", "jump", "kick", "sway", "mix"}
    assert len({j.motion for j in bench.jobs if j.split == "test"}) >= 4
    mocap = plans["bench-mocap"]
    assert mocap.garments == bench.garments
    assert all(mocap.resolve(m["file"]).is_file() for m in mocap.motions.values())
    assert {j.motion for j in mocap.jobs if j.split == "test"} and {j.motion for j in mocap.jobs if j.split == "train"}
    sim = plans["simparams"]
    assert len(sim.garments) == 1 and len(sim.sim_params) == 10
    assert len({j.sim_params for j in sim.jobs if j.split == "test"}) == 2
    for name in ("bending", "density", "time_scale"):
        assert len({getattr(p, name) for p in sim.sim_params.values()}) >= 4
    garments = plans["garments"]
    assert len(garments.garments) >= 30 and len(garments.shapes) == 3
    assert {g["template"] for g in garments.garments.values()} == {"skirt", "dress", "long_shirt", "jumpsuit"}

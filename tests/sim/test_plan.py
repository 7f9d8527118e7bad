import pytest
import yaml

from loosefit.errors import InputError
from loosefit.motion.procedural import KINDS
from loosefit.sim.plan import FileMotion, Hold, ProceduralMotion, TemplateGarment, load_plan

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


def test_optional_file_motions_leave_the_plan_when_their_files_are_missing(tmp_path):
    """An optional file motion whose file is missing takes its sequences out of every group and split (listed in
    ``missing_motions``); one whose file is there, or a required one, stays."""
    (tmp_path / "here.bvh").write_text("not read when the plan loads")
    plan = {"garments": {"g": {"template": "skirt"}},
            "motions": {"walk": {"procedural": "walk", "seconds": 1},
                        "here": {"file": "here.bvh", "optional": True},
                        "gone": {"file": "gone.bvh", "optional": True},
                        "needed": {"file": "needed.bvh"}},
            "sequences": [{"motions": ["walk", "gone"]}, {"motions": ["here", "needed"]}, {"motions": ["gone"]}],
            "split": {"test": {"motions": ["gone", "here"]}, "val": {"motions": ["needed"]}}}
    loaded = load_plan(_write(tmp_path, plan))
    assert loaded.missing_motions == ["gone"] and "gone" not in loaded.motions
    assert {j.motion: j.split for j in loaded.jobs} == {"walk": "train", "here": "test", "needed": "val"}
    with pytest.raises(InputError, match="select no sequence"):
        load_plan(_write(tmp_path, {**plan, "sequences": [{"motions": ["gone"]}]}))
    with pytest.raises(InputError, match="optional"):
        load_plan(_write(tmp_path, {**plan, "motions": {**plan["motions"], "gone": {"file": "x", "optional": "yes"}}}))


def test_unreadable_plan(tmp_path):
    with pytest.raises(InputError, match="missing.yaml.*cannot read"):
        load_plan(tmp_path / "missing.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("[1, 2]")
    with pytest.raises(InputError, match="bad.yaml.*mapping"):
        load_plan(bad)


def test_shipped_plans_name_clips_of_the_collection():
    """Every motion file of a shipped plan is a CMU clip of the collection kept beside the repository
    (``../shared/mocap/cmu-cc``, where the plans' relative paths lead): its name is in the collection's
    ``clips.csv`` (a copy in tests/data) and its path ends in that folder (optional clips absent there are dropped
    by the plan, as the demo's are without the folder)."""
    import csv
    from pathlib import Path

    from tests.conftest import TEST_MOCAP

    with open(TEST_MOCAP / "clips.csv", newline="") as f:
        names = {f"{int(r['Subject']):03d}_{int(r['Trial #']):02d}.bvh" for r in csv.DictReader(f)}
    assert len(names) == 49
    root = Path(__file__).parents[2] / "configs" / "datasets"
    clips = 0
    for path in sorted(root.glob("*.yaml")):
        plan = load_plan(path)
        files = [plan.resolve(m["file"]) for m in plan.motions.values() if "file" in m]
        clips += len(files)
        for f in files:
            assert f.name in names and f.parent.parts[-3:] == ("shared", "mocap", "cmu-cc"), (path.name, f)
    assert clips > 49  # bench-real alone names all 49


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
    real = plans["bench-real"]  # whole subjects per split, pieces of at most 10 s, the floor of every test piece
    assert real.garments == bench.garments and real.references.count >= 4
    subject = {name: m["file"].split("/")[-1][:3] for name, m in real.motions.items() if "file" in m}
    by_split = {s: {subject[j.motion] for j in real.jobs if j.split == s and j.motion in subject} for s in ("train", "val", "test")}
    assert by_split == {"train": {"001", "005", "007"}, "val": {"006"}, "test": {"002", "003"}}
    assert all(1 <= m["frames"] <= 300 for m in real.motions.values() if "file" in m)
    assert {m["procedural"] for m in real.motions.values() if "procedural" in m} == set(KINDS)
    assert {j.garment for j in real.jobs} == {"skirt", "dress"}
    mocap = plans["bench-mocap"]
    assert mocap.garments == bench.garments
    assert {j.motion for j in mocap.jobs if j.split == "test"} and {j.motion for j in mocap.jobs if j.split == "train"}
    sim = plans["simparams"]
    assert len(sim.garments) == 1 and len(sim.sim_params) == 10
    assert len({j.sim_params for j in sim.jobs if j.split == "test"}) == 2
    for name in ("bending", "density", "time_scale"):
        assert len({getattr(p, name) for p in sim.sim_params.values()}) >= 4
    # SwinGar/FitGar's store: >= 24 training and >= 6 held-out garments (every kind held out), >= 3 shapes,
    # >= 6 motions of 6-10 s with real clips; nothing of the test split in training.
    garments = plans["garments"]
    kinds = {"skirt", "dress", "long_shirt", "jumpsuit"}
    kind = lambda name: garments.garments[name]["template"]  # noqa: E731
    train = [j for j in garments.jobs if j.split == "train"]
    test = [j for j in garments.jobs if j.split == "test"]
    train_garments = {j.garment for j in train}
    held_out = {j.garment for j in test} - train_garments
    assert len(train_garments) >= 24 and {kind(g) for g in train_garments} == kinds
    assert len(held_out) >= 6 and {kind(g) for g in held_out} == kinds
    assert len(garments.shapes) >= 3 and {j.shape for j in test} - {j.shape for j in train}
    assert {j.motion for j in test} - {j.motion for j in train}
    assert len(garments.motions) >= 6 and any("file" in m for m in garments.motions.values())
    for name, m in garments.motions.items():
        seconds = m["seconds"] if "procedural" in m else m["frames"] / 30
        assert 6 <= seconds <= 10, name  # that the files are there: test_shipped_plans_find_their_clips


def test_specs_are_typed_configs_and_yaml_exponents_are_numbers(tmp_path):
    """Plans read through loosefit.config: ``1e-5`` (no dot, a string to plain YAML 1.1) is a number, each
    garment and motion entry is a typed spec whose defaults live in one place, and a wrong type or an
    unknown key is named with the allowed keys."""
    path = tmp_path / "plan.yaml"
    path.write_text("garments:\n  g: {template: skirt, params: {length: 0.5}}\n"
                    "motions:\n  m: {procedural: walk, seconds: 2}\n  f: {file: c.bvh}\n"
                    "sim_params:\n  soft: {bending: 1e-6, density: 5e-2}\n")
    plan = load_plan(path)
    assert (plan.sim_params["soft"].bending, plan.sim_params["soft"].density) == (1e-6, 0.05)
    garment = plan.garment_spec("g")
    assert isinstance(garment, TemplateGarment) and garment.make_kwargs() == {"length": 0.5}  # make_garment's defaults
    assert plan.motion_spec("m") == ProceduralMotion("walk", 2.0, 0)
    assert plan.motion_spec("f") == FileMotion("c.bvh", None, 0, None)
    assert plan.garments["g"] == {"template": "skirt", "params": {"length": 0.5}}  # as written: hashes unchanged
    for change, message in [({"motions": {"m": {"procedural": "walk", "seconds": 1, "speed": 2}}},
                             r"motion 'm': unknown keys \['speed'\]; allowed: \['hold', 'procedural', 'seconds', 'seed', 'slowdown'\]"),
                            ({"garments": {"g": {"template": "skirt", "seed": "one"}}},
                             r"garment 'g': config key 'seed': expected an integer"),
                            ({"motions": {"m": {"file": "c.bvh", "frames": 0}}}, r"'frames' must be an integer >= 1")]:
        with pytest.raises(InputError, match=message) as err:
            load_plan(_write(tmp_path, {**PLAN, **change}))
        assert "plan.yaml" in str(err.value)


def test_slowdown_is_checked(tmp_path):
    for value in (0.5, "fast", True):
        with pytest.raises(InputError, match="'slowdown'.*(>= 1|expected a number)"):
            load_plan(_write(tmp_path, {**PLAN, "motions": {"walk": {"procedural": "walk", "seconds": 2, "slowdown": value}}}))
    plan = load_plan(_write(tmp_path, {**PLAN, "motions": {"walk": {"procedural": "walk", "seconds": 2, "slowdown": 4}, "clip": PLAN["motions"]["clip"]}}))
    assert plan.motion_spec("walk").slowdown == 4 and plan.motion_spec("clip").slowdown == 1


def test_hold_is_checked(tmp_path):
    walk = {"procedural": "walk", "seconds": 2}
    for hold, message in [({"every": 0}, r"'hold.every' must be an integer >= 1"),
                          ({"transition": 5}, r"'hold.every'.*missing"),
                          ({"every": 5, "frames": "long"}, r"'hold.frames': expected an integer"),
                          ({"every": 5, "order_seed": -3}, r"'hold.order_seed' must be an integer >= 0"),
                          ({"every": 5, "from_rest": "yes"}, r"'hold.from_rest': expected true or false"),
                          (3, r"'hold': expected a mapping of Hold fields")]:
        with pytest.raises(InputError, match=message):
            load_plan(_write(tmp_path, {**PLAN, "motions": {"walk": {**walk, "hold": hold}}}))
    plan = load_plan(_write(tmp_path, {**PLAN, "motions": {"walk": {**walk, "hold": {"every": 15}},
                                                           "clip": PLAN["motions"]["clip"]}}))
    assert plan.motion_spec("walk").hold == Hold(15, 10, 30, False) and plan.motion_spec("clip").hold is None

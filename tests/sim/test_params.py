import pytest

from loosefit.errors import InputError
from loosefit.sim.params import SimParams


def test_defaults_are_fabric_like():
    p = SimParams()
    assert 0.05 <= p.density <= 0.4  # kg/m^2, silk to denim
    assert 1e-6 <= p.bending <= 1e-4  # N*m
    assert p.time_scale == 1.0 and p.collider == "proxy" and not p.self_collision


def test_overrides_parse_yaml_scalars():
    p = SimParams().with_overrides(["bending=1e-4", "self_collision=true", "quality=8", "density=0.3"])
    assert (p.bending, p.self_collision, p.quality, p.density) == (1e-4, True, 8, 0.3)
    assert SimParams().with_overrides({"time_scale": 0.5}).time_scale == 0.5
    assert SimParams.from_dict(p.to_dict()) == p


def test_load_yaml(tmp_path):
    path = tmp_path / "fabric.yaml"
    path.write_text("bending: 2e-5\ndensity: 0.2\n")
    p = SimParams.load(path, overrides=["density=0.25"])
    assert (p.bending, p.density, p.tension) == (2e-5, 0.25, SimParams().tension)


@pytest.mark.parametrize(
    "values, message",
    [
        ({"bendin": 1.0}, "unknown simulation parameters \\['bendin'\\]"),
        ({"density": -1.0}, "density"),
        ({"density": 0}, "density must be > 0"),
        ({"quality": 0}, "quality"),
        ({"quality": 2.5}, "quality"),
        ({"self_collision": "yes"}, "self_collision"),
        ({"collider": "mesh"}, "collider"),
        ({"bending": "stiff"}, "bending"),
    ],
)
def test_bad_values_name_the_file(tmp_path, values, message):
    with pytest.raises(InputError, match=message) as err:
        SimParams.from_dict(values, source=tmp_path / "p.yaml")
    assert "p.yaml" in str(err.value)


def test_bad_yaml_file(tmp_path):
    path = tmp_path / "list.yaml"
    path.write_text("- 1\n- 2\n")
    with pytest.raises(InputError, match="list.yaml.*mapping"):
        SimParams.load(path)
    with pytest.raises(InputError, match="NAME=VALUE"):
        SimParams().with_overrides(["bending"])


def test_one_config_mechanism_for_files_and_overrides(tmp_path):
    """YAML files and overrides go through loosefit.config: exponents without a dot are numbers, integers
    are accepted for floats, an unknown name lists the known ones, a wrong type names the key."""
    path = tmp_path / "fabric.yaml"
    path.write_text("bending: 1e-5\ntension: 300\n")
    p = SimParams.load(path, ["air_drag=3e-1"])
    assert (p.bending, p.tension, p.air_drag) == (1e-5, 300.0, 0.3) and isinstance(p.tension, float)
    with pytest.raises(InputError, match=r"unknown simulation parameters \['drag'\]; known: \['density', "):
        SimParams().with_overrides(["drag=1"])
    with pytest.raises(InputError, match="override 'quality=fast'.*'quality': expected an integer"):
        SimParams().with_overrides(["quality=fast"])

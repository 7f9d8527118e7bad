"""Optional dependencies: a missing one is an InputError naming the extra that installs it."""

import json
import subprocess
import sys

import pytest

from loosefit.errors import InputError
from loosefit.extras import EXTRA_OF, require


def test_require_returns_the_module_or_names_the_extra():
    assert require("json", "reading JSON") is json
    with pytest.raises(InputError, match=r"writing things needs 'no_such_module_xyz'.*pip install no_such_module_xyz"):
        require("no_such_module_xyz", "writing things")
    assert EXTRA_OF["bpy"] == "sim" and EXTRA_OF["pyvista"] == "viz" and EXTRA_OF["smplx"] == "smpl"


def test_rendering_without_the_viz_extra_names_it():
    """With imageio unimportable (as after `pip install loosefit`), writing a PNG says which extra to install."""
    code = ("import sys; sys.modules['imageio'] = None; sys.modules['imageio.v3'] = None\n"
            "import numpy as np\nfrom loosefit.viz.writers import save_png\n"
            "try:\n    save_png('x.png', np.zeros((8, 8, 3), np.uint8))\nexcept Exception as e:\n    print(e)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120).stdout
    assert "writing PNG images needs 'imageio'" in out and "pip install 'loosefit[viz]'" in out

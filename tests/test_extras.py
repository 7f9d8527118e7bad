"""Optional dependencies: a missing one is an InputError naming the extra that installs it."""

import json
import subprocess
import sys

import pytest

from loosefit.errors import InputError
from loosefit.extras import EXTRA_OF, require, require_installed


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


def test_require_installed_checks_without_importing():
    with pytest.raises(InputError, match=r"simulating needs 'no_such_module_xyz'.*pip install no_such_module_xyz"):
        require_installed("no_such_module_xyz", "simulating")


def test_a_process_whose_workers_simulate_never_imports_bpy(tmp_path):
    """Importing bpy puts Blender's script folders first on sys.path, and a process spawned afterwards (the demo's
    held-out simulation beside training) then finds Blender's own `bpy` package instead of the module. So checking
    the backend of a run whose workers simulate must not import it, and after a real import a spawned child fails."""
    code = ("import multiprocessing, sys\n"
            "def child():\n    import bpy\n    return bpy.app.version_string\n"
            "if __name__ == '__main__':\n"
            "    from loosefit.sim.sequence import check_backend\n    check_backend('blender')\n"
            "    ctx = multiprocessing.get_context('spawn')\n"
            "    with ctx.Pool(1) as pool:\n        print('checked', 'bpy' in sys.modules, pool.apply(child))\n"
            "    import bpy\n"
            "    with ctx.Pool(1) as pool:\n"
            "        try:\n            pool.apply(child)\n        except ImportError as e:\n            print('shadowed', e)\n")
    script = tmp_path / "spawn_bpy.py"
    script.write_text(code)
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=300).stdout
    assert "checked False 5." in out
    assert "shadowed No module named '_bpy'" in out

"""The fused CPU kernel of GAT-LN (``gat_ln_cpu.c`` through :mod:`loosefit.models.layers.native`): the layer it
computes is the design written out by hand and the eager layer's, in batches, groups and saturated activations; it
serves inference only; a bad table is refused; without a working compiler the eager layer runs, after a warning."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from loosefit.errors import InputError
from loosefit.models.layers import native
from loosefit.models.layers.gat_ln import GATLN, attention_table, head_columns
from tests.models.layers.test_gat_ln_designs import by_hand
from tests.models.layers.test_gat_ln_signs import FACES, IN, V
from tests.rig.conftest import tube


@pytest.fixture
def fresh_library():
    """``native.library`` rebuilt for the test (its cache emptied before and after)."""
    native.library.cache_clear()
    yield native.library
    native.library.cache_clear()


def layer_and_graph(heads: int, out: int, groups: int = 1, activation: str | None = "tanh", inputs: int = IN,
                    faces=FACES, verts: int = V, seed: int = 0):
    torch.manual_seed(seed)
    layer = GATLN(inputs, out, heads=heads, alpha=2.0, norm="node", centred=True, concat=True, groups=groups,
                  activation=activation)
    with torch.no_grad():
        layer.bias.normal_()
    return layer, tuple(map(torch.from_numpy, attention_table(faces, verts)))


@pytest.mark.parametrize("heads, out", [(1, 5), (3, 7), (4, 9)])
def test_the_kernel_is_the_design_by_hand(heads, out):
    """float32 through the kernel against the float64 loops of the design (per-node norm, centred, concatenated)."""
    layer, (table, valid) = layer_and_graph(heads, out)
    x = torch.randn(V, IN, generator=torch.Generator().manual_seed(1)) * 2.0 + 1.0
    with torch.no_grad():
        assert layer._native_applies(x[None])
        got = layer(x[None], table, valid)[0]
    torch.testing.assert_close(got.double(), by_hand(layer, x.double()), rtol=0, atol=2e-6)


@pytest.mark.parametrize("groups, heads, out, activation, scale", [(4, 32, 256, None, 1.0), (1, 24, 128, "tanh", 1.0),
                                                                   (1, 3, 256, "tanh", 30.0), (2, 2, 6, "tanh", 1e-3)])
def test_the_kernel_is_the_eager_layer(monkeypatch, groups, heads, out, activation, scale):
    """SwinGar's layer shapes on a tube, two batches: the kernel against the eager layer (LOOSEFIT_NATIVE=0), from
    tiny inputs to inputs that saturate the tanh."""
    verts, faces = tube(rings=12, around=16)
    layer, (table, valid) = layer_and_graph(heads, out, groups, activation, inputs=34, faces=faces, verts=len(verts))
    x = torch.randn(2, len(verts), 34, generator=torch.Generator().manual_seed(2)) * scale
    with torch.no_grad():
        got = layer(x, table, valid)
        monkeypatch.setenv("LOOSEFIT_NATIVE", "0")
        assert not layer._native_applies(x)
        eager = layer(x, table, valid)
    assert got.shape == eager.shape == (2, len(verts), out)
    # float32 round-off of sums over up to 10 slots (the eager layer sums in another order)
    torch.testing.assert_close(got, eager, rtol=0, atol=3e-6 * max(1.0, float(eager.abs().max())))
    if activation == "tanh" and scale > 1:
        assert float(eager.abs().max()) > 0.999  # saturated


def test_training_and_other_designs_keep_the_eager_layer():
    """With a gradient wanted, in float64, or for the designs the kernel does not cover, the eager layer runs."""
    layer, (table, valid) = layer_and_graph(3, 7)
    x = torch.randn(1, V, IN)
    assert not layer._native_applies(x)  # autograd on, the weights want gradients
    assert layer(x, table, valid).requires_grad
    with torch.no_grad():
        assert layer._native_applies(x)
        assert not layer._native_applies(x.double())
        for other in (GATLN(IN, 7, 3, norm="graph", centred=True, concat=True),
                      GATLN(IN, 7, 3, norm="node", centred=False, concat=True),
                      GATLN(IN, 7, 3, norm="node", centred=True, concat=False),
                      GATLN(IN, 7, 3, alpha=None, norm="node", centred=True, concat=True)):
            assert not other._native_applies(x)


def test_a_table_outside_the_vertices_or_without_its_vertex_is_refused():
    layer, (table, valid) = layer_and_graph(3, 7)
    bad = table.clone()
    bad[2, 1] = V
    with torch.no_grad(), pytest.raises(InputError, match="outside"):
        layer(torch.randn(1, V, IN), bad, valid)
    empty = valid.clone()
    empty[3] = False
    with torch.no_grad(), pytest.raises(InputError, match="first slot"):
        layer(torch.randn(1, V, IN), table, empty)


def test_head_channels_are_blocks_in_head_order():
    """The kernel reads each head's channels as one block, heads in order: what head_columns gives."""
    for out, heads, groups in [(128, 24, 1), (256, 32, 4), (256, 3, 1), (7, 3, 1), (64, 8, 4)]:
        assert np.all(np.diff(head_columns(out, heads, groups)) >= 0)


def test_the_build_is_cached_and_a_failed_build_falls_back(fresh_library, monkeypatch, tmp_path):
    """A build lands in the cache directory; a compiler that fails, or none at all, gives a warning and the eager
    layer (no half-written library left behind)."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "ok"))
    assert fresh_library() is not None  # the machines have a C compiler (gcc)
    assert len(list((tmp_path / "ok" / "loosefit" / "native").glob("gat_ln_cpu-*.so"))) == 1
    layer, (table, valid) = layer_and_graph(3, 7)
    x = torch.randn(1, V, IN)
    with torch.no_grad():
        fused = layer(x, table, valid)
    for compiler, message in [("false", "could not build"), (str(tmp_path / "no-such-cc"), "no C compiler")]:
        native.library.cache_clear()
        monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / compiler.replace("/", "_")))
        monkeypatch.setenv("CC", compiler)
        monkeypatch.setenv("PATH", str(tmp_path / "empty") if compiler != "false" else "/usr/bin:/bin")
        with pytest.warns(RuntimeWarning, match=message):
            assert native.library() is None
        with torch.no_grad():
            assert not layer._native_applies(x)
            torch.testing.assert_close(layer(x, table, valid), fused, rtol=0, atol=1e-6)
        left = tmp_path / compiler.replace("/", "_") / "loosefit" / "native"
        assert not left.exists() or not any(left.iterdir())

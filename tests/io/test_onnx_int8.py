"""Int8 weights (``loosefit.io.onnx_int8``): every weight within half a quantization step of the value it stands
for, and onnxruntime multiplying exactly those values (``MatMulNBits``' float path) or within the bound that
rounding its input to int8 allows (its integer path, per block; ``DynamicQuantizeMatMul``, per tensor), for a
plain, a per-group (batched), a ``Gemm`` and a many-row product."""

import numpy as np
import onnx
import onnxruntime as ort
import pytest
from onnx import TensorProto, helper, numpy_helper

from loosefit.io.onnx_int8 import (BLOCK_SIZE, COLUMN_LEVELS, DYNAMIC_MIN_ROWS, block_size_for, dequantize_blocks,
                                   quantize_blocks, quantize_columns, quantize_model)

K, N, G = 300, 24, 3  # K not a multiple of the block: the last block is padded
R = DYNAMIC_MIN_ROWS + 4  # rows of the many-row product


def test_blocks_round_trip_within_half_a_step():
    rng = np.random.default_rng(0)
    w = rng.normal(size=(K, N)).astype(np.float32) * np.logspace(-3, 1, N, dtype=np.float32)
    w[:, 5] = 0.0  # an all-zero column: scale 0, dequantized exactly
    stored, scales = quantize_blocks(w)
    blocks = -(-K // BLOCK_SIZE)
    assert stored.shape == (N, blocks, BLOCK_SIZE) and stored.dtype == np.uint8 and scales.shape == (N, blocks)
    back = dequantize_blocks(stored, scales, K)
    step = np.repeat(scales.T, BLOCK_SIZE, axis=0)[:K]  # (K, N): each weight's block scale
    assert np.all(np.abs(back - w) <= step / 2 * (1 + 1e-6))
    assert np.abs(back - w).max() > 0  # not a float copy
    np.testing.assert_array_equal(back[:, 5], 0.0)
    # each block's largest weight is +-127 steps: stored exactly
    for n in (0, N - 1):
        for b in range(blocks):
            block = w[b * BLOCK_SIZE:(b + 1) * BLOCK_SIZE, n]
            k = b * BLOCK_SIZE + int(np.abs(block).argmax())
            assert back[k, n] == pytest.approx(w[k, n], rel=1e-6)
            assert abs(int(stored[n, b, k - b * BLOCK_SIZE]) - 128) == 127
    assert np.all(stored[:, -1, K - (blocks - 1) * BLOCK_SIZE:] == 128)  # the padding is zero weights


def test_columns_round_trip_within_half_a_step():
    rng = np.random.default_rng(2)
    w = rng.normal(size=(K, N)).astype(np.float32) * np.logspace(-3, 1, N, dtype=np.float32)
    w[:, 3] = 0.0
    q, scales = quantize_columns(w)
    assert q.dtype == np.int8 and scales.shape == (N,)
    back = q.astype(np.float32) * scales
    assert np.all(np.abs(back - w) <= scales / 2 * (1 + 1e-6)) and np.abs(back - w).max() > 0
    np.testing.assert_array_equal(back[:, 3], 0.0)
    assert np.all(np.abs(q).max(0)[scales > 0] == COLUMN_LEVELS)  # each column's largest weight is the top step
    assert COLUMN_LEVELS == 63  # 7 bits: onnxruntime's AVX2 kernel sums pairs of uint8 x int8 products in int16


def _graph(rng):
    """``y1 = a @ W1``, ``y2 = Gemm(a, W2^T (stored (N, K)), c)``, ``y3 = b @ W3`` (per group), ``y4 = a @ small``,
    ``y5 = m @ W5`` over ``R`` rows."""
    w1 = rng.normal(size=(K, N)).astype(np.float32)
    w2 = rng.normal(size=(N, K)).astype(np.float32)
    c = rng.normal(size=(N,)).astype(np.float32)
    w3 = rng.normal(size=(G, K, N)).astype(np.float32)
    small = rng.normal(size=(K, 2)).astype(np.float32)
    w5 = rng.normal(size=(K, N)).astype(np.float32)
    nodes = [helper.make_node("MatMul", ["a", "w1"], ["y1"]),
             helper.make_node("Gemm", ["a", "w2", "c"], ["y2"], transB=1),
             helper.make_node("MatMul", ["b", "w3"], ["y3"]),
             helper.make_node("MatMul", ["a", "small"], ["y4"]),
             helper.make_node("MatMul", ["m", "w5"], ["y5"])]
    inputs = [helper.make_tensor_value_info("a", TensorProto.FLOAT, [1, K]),
              helper.make_tensor_value_info("b", TensorProto.FLOAT, [G, 1, K]),
              helper.make_tensor_value_info("m", TensorProto.FLOAT, [R, K])]
    outputs = [helper.make_tensor_value_info(y, TensorProto.FLOAT, None) for y in OUTPUTS]
    inits = [numpy_helper.from_array(v, n) for n, v in (("w1", w1), ("w2", w2), ("c", c), ("w3", w3),
                                                           ("small", small), ("w5", w5))]
    model = helper.make_model(helper.make_graph(nodes, "g", inputs, outputs, inits),
                              opset_imports=[helper.make_opsetid("", 17)])
    return model, {"w1": w1, "w2": w2.T, "c": c, "w3": w3, "small": small, "w5": w5}


OUTPUTS = ("y1", "y2", "y3", "y4", "y5")


def _run(model, feeds):
    options = ort.SessionOptions()
    options.intra_op_num_threads = 1
    sess = ort.InferenceSession(model.SerializeToString(), options, providers=["CPUExecutionProvider"])
    return dict(zip(OUTPUTS, sess.run(None, feeds)))


def _deq(w):
    return dequantize_blocks(*quantize_blocks(w), w.shape[0])


def _dynamic_reference(m, w):
    """``m @ W`` as ``DynamicQuantizeMatMul`` computes it: ``m`` rounded to uint8 as ONNX's DynamicQuantizeLinear
    specifies (scale: the range, zero included, over 255; zero point ``round(-min / scale)``; ties to even), an
    exact integer product with the int8 columns, then both scales."""
    m = m.astype(np.float32)
    s = np.float32((max(m.max(), 0.0) - min(m.min(), 0.0)) / 255)
    zp = np.clip(np.rint(-min(m.min(), 0.0) / s), 0, 255)
    mq = np.clip(np.rint(m / s) + zp, 0, 255)
    q, scales = quantize_columns(w)
    return ((mq - zp).astype(np.int64) @ q.astype(np.int64)) * (np.float64(s) * scales.astype(np.float64))


def _input_rounding_bound(a, w):
    """``sum_k |W_kn| * s_k / 2``: the most that rounding ``a``'s blocks of BLOCK_SIZE to int8 (scale ``s`` =
    block max / 127) can move ``a @ W``."""
    a = np.asarray(a, np.float64).reshape(-1)
    s = np.concatenate([np.full(min(BLOCK_SIZE, len(a) - i), np.abs(a[i:i + BLOCK_SIZE]).max() / 127)
                        for i in range(0, len(a), BLOCK_SIZE)])
    return (np.abs(w) * s[:, None] / 2).sum(0)


def _dynamic_rounding_bound(m, w):
    """``sum_k |W_kn| * s / 2``: the most that rounding ``m`` to uint8 with one scale ``s`` (its range / 255) can
    move ``m @ W``."""
    s = (max(m.max(), 0.0) - min(m.min(), 0.0)) / 255
    return (np.abs(w) * s / 2).sum(0)


def _deq_columns(w):
    q, scales = quantize_columns(w)
    return q.astype(np.float64) * scales


@pytest.mark.parametrize("accuracy_level", [0, 4])
def test_onnxruntime_multiplies_the_stored_weights(accuracy_level):
    """One rounding of the input (``residual=False``): the products of the dequantized weights, within what
    rounding the input moves them."""
    rng = np.random.default_rng(1)
    model, w = _graph(rng)
    feeds = {"a": rng.normal(size=(1, K)).astype(np.float32), "b": rng.normal(size=(G, 1, K)).astype(np.float32),
             "m": rng.normal(size=(R, K)).astype(np.float32)}
    quantized, summary = quantize_model(model, min_elements=K * N, accuracy_level=accuracy_level, residual=False)
    onnx.checker.check_model(quantized)
    ops = [n.op_type for n in quantized.graph.node]
    assert ops.count("MatMulNBits") == 2 + G and ops.count("MatMul") == 1  # the small product stays float
    assert ops.count("DynamicQuantizeMatMul") == 1  # the many-row product
    assert summary["matrices"] == 3 + G and summary["dynamic"] == 1 and summary["weights_int8"] == (3 + G) * K * N
    assert {t.name for t in quantized.graph.initializer} & {"w1", "w2", "w3", "w5"} == set()

    got, exact = _run(quantized, feeds), _run(model, feeds)
    a, b = feeds["a"].astype(np.float64), feeds["b"].astype(np.float64)
    expected = {"y1": a @ _deq(w["w1"]), "y2": a @ _deq(w["w2"]) + w["c"],
                "y3": np.stack([b[g] @ _deq(w["w3"][g]) for g in range(G)]), "y4": exact["y4"]}
    np.testing.assert_array_equal(got["y4"], exact["y4"])
    np.testing.assert_allclose(got["y5"], _dynamic_reference(feeds["m"], w["w5"]), rtol=1e-5, atol=1e-4)
    for y in ("y1", "y2", "y3", "y5"):
        assert got[y].shape == exact[y].shape
        assert np.abs(got[y] - exact[y]).max() > 1e-4  # the weights really are rounded
        if accuracy_level == 0 and y != "y5":  # MatMulNBits' float arithmetic on the dequantized weights
            np.testing.assert_allclose(got[y], expected[y], atol=1e-4, rtol=1e-5)
    if accuracy_level == 4:  # int8 inputs too: within the rounding of each input block
        for y, x, weights in (("y1", a, [w["w1"]]), ("y2", a, [w["w2"]]), ("y3", b, list(w["w3"]))):
            for g, weight in enumerate(weights):
                bound = _input_rounding_bound(x[g] if y == "y3" else x, _deq(weight))
                err = np.abs(got[y][g] - expected[y][g]).reshape(-1) if y == "y3" else np.abs(got[y] - expected[y])[0]
                assert np.all(err <= bound * 1.01 + 1e-5), (y, g, (err / bound).max())


def test_the_residual_makes_the_products_those_of_the_rounded_weights():
    """The default (``residual=True``): every integer product also multiplies what rounding its input left over,
    so it is the product of the dequantized weights and the exact input to a hundredth of the one-rounding bound
    (the theory: 1/254 of it), for several rows, a vector, a per-group batch of two rows and a many-row product;
    a product of constants stays float; ``rounded`` holds the dequantized weights in each initializer's layout."""
    rng = np.random.default_rng(3)
    w1, w3, w5, w6 = (rng.normal(size=s).astype(np.float32) for s in ((K, N), (G, K, N), (K, N), (K, N)))
    w2 = rng.normal(size=(N, K)).astype(np.float32)
    constant = rng.normal(size=(R, K)).astype(np.float32)
    nodes = [helper.make_node("MatMul", ["a", "w1"], ["y1"]),
             helper.make_node("Gemm", ["a", "w2"], ["y2"], transB=1),
             helper.make_node("MatMul", ["b", "w3"], ["y3"]),
             helper.make_node("MatMul", ["v", "w1"], ["y4"]),
             helper.make_node("MatMul", ["m", "w5"], ["y5"]),
             helper.make_node("MatMul", ["constant", "w6"], ["y6"])]
    inputs = [helper.make_tensor_value_info("a", TensorProto.FLOAT, [3, K]),
              helper.make_tensor_value_info("b", TensorProto.FLOAT, [G, 2, K]),
              helper.make_tensor_value_info("v", TensorProto.FLOAT, [K]),
              helper.make_tensor_value_info("m", TensorProto.FLOAT, [R, K])]
    outputs = [helper.make_tensor_value_info(f"y{i}", TensorProto.FLOAT, None) for i in range(1, 7)]
    inits = [numpy_helper.from_array(v, n) for n, v in (("w1", w1), ("w2", w2), ("w3", w3), ("w5", w5), ("w6", w6),
                                                           ("constant", constant))]
    model = helper.make_model(helper.make_graph(nodes, "g", inputs, outputs, inits),
                              opset_imports=[helper.make_opsetid("", 17)])
    feeds = {"a": rng.normal(size=(3, K)), "b": rng.normal(size=(G, 2, K)), "v": rng.normal(size=K),
             "m": rng.normal(size=(R, K)) * np.linspace(0.1, 3, K)}
    feeds = {k: v.astype(np.float32) for k, v in feeds.items()}
    rounded: dict = {}
    quantized, summary = quantize_model(model, min_elements=K * N, rounded=rounded)
    single, _ = quantize_model(model, min_elements=K * N, residual=False)
    onnx.checker.check_model(quantized)
    ops = [n.op_type for n in quantized.graph.node]
    assert ops.count("MatMulNBits") == 3 + G and ops.count("DynamicQuantizeMatMul") == 2  # the input, the residual
    assert ops.count("MatMul") == 1 and summary["matrices"] == 4 + G  # the product of constants stays float

    deq = {"w1": _deq(w1), "w2": _deq(w2.T).T, "w3": np.stack([_deq(w) for w in w3]), "w5": _deq_columns(w5)}
    assert set(rounded) == set(deq)
    for name, values in deq.items():
        assert rounded[name].shape == values.shape
        np.testing.assert_allclose(rounded[name], values, rtol=1e-6, atol=1e-7)

    names = [f"y{i}" for i in range(1, 7)]
    sess = {k: ort.InferenceSession(p.SerializeToString(), providers=["CPUExecutionProvider"])
            for k, p in (("residual", quantized), ("single", single))}
    got = {k: dict(zip(names, s.run(None, feeds))) for k, s in sess.items()}
    x = {k: v.astype(np.float64) for k, v in feeds.items()}
    cases = [("y1", x["a"][i], deq["w1"], _input_rounding_bound, (i,)) for i in range(3)]
    cases += [("y2", x["a"][i], deq["w2"].T, _input_rounding_bound, (i,)) for i in range(3)]
    cases += [("y3", x["b"][g, i], deq["w3"][g], _input_rounding_bound, (g, i)) for g in range(G) for i in range(2)]
    cases += [("y4", x["v"], deq["w1"], _input_rounding_bound, ())]
    cases += [("y5", x["m"], deq["w5"], lambda m, w: _dynamic_rounding_bound(m, w), ())]
    worst = {"residual": 0.0, "single": 0.0}
    for y, inp, weight, bound_of, index in cases:
        bound = bound_of(inp, weight)
        expected = inp @ weight
        for k in worst:
            err = np.abs(got[k][y][index] - expected)
            worst[k] = max(worst[k], float((err / bound).max()))
    assert worst["residual"] <= 1e-2, worst  # a hundredth of one rounding's bound
    assert worst["single"] > 10 * worst["residual"], worst  # the control: one rounding is far coarser
    np.testing.assert_allclose(got["residual"]["y6"], constant.astype(np.float64) @ w6, rtol=1e-5, atol=1e-4)


def test_a_short_matrix_gets_the_power_of_two_block_that_holds_it():
    assert [block_size_for(k) for k in (5, 16, 17, 50, 64, 65, 300, 4096)] == [16, 16, 32, 64, 64, 128, 128, 128]
    assert block_size_for(300, 32) == 32

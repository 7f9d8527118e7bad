"""Int8 weights for an ONNX model: the large constant matrices of ``MatMul`` and ``Gemm`` nodes stored as 8-bit
integers with float scales, multiplied by onnxruntime's integer kernels (domain ``com.microsoft``).

A step model at the papers' sizes reads every weight once per frame, so on one CPU thread it is bound by memory
traffic and, for JointNet's bone MLP, by arithmetic: a quarter of the bytes and int8 products are the speed-up
(``benchmarks/onnx_speed.py``). Activations stay float32 between nodes. Two kernels, by the rows of the input:

- a matrix-vector product (fewer than :data:`DYNAMIC_MIN_ROWS` input rows: the GRUs, VirtualBones' global layer,
  the pose-space basis): ``MatMulNBits``, symmetric blocks of the weights. For output column ``n`` and block ``b``
  of ``block_size`` consecutive input indices ``k``, ``scale[n, b] = max_k |W[k, n]| / 127`` and ``q[k, n] =
  round(W[k, n] / scale[n, b])`` in [-127, 127], stored as ``q + 128`` (its default zero point for 8 bits): every
  weight within ``scale / 2`` of its dequantized value ``(stored - 128) * scale``. With ``accuracy_level=4`` the
  kernel also rounds each block of the input to int8 (scale: the block's largest magnitude / 127);
- a product over many rows (JointNet's bone MLP on its 80 bones): ``DynamicQuantizeMatMul``, the weights symmetric
  per output column (``scale[n] = max_k |W[k, n]| / 127``, int8, zero point 0), the input rounded at run time to
  uint8 with one scale and zero point for the whole tensor: 3.5x faster than the block kernel at 80 rows, coarser
  in its input (a recurrent state never goes through it).

The tests bound both against the dequantized weights and the input's rounding.
"""

from __future__ import annotations

import numpy as np

#: Input rows per quantization block of ``MatMulNBits`` (one scale each).
BLOCK_SIZE = 32
#: Matrices with fewer elements stay float32: they are a small share of the bytes and often the most sensitive.
MIN_ELEMENTS = 16384
#: ``MatMulNBits``' integer kernels (inputs rounded to int8 per block): about 25x faster than its float path for 8 bits.
ACCURACY_LEVEL = 4
#: Products over at least this many input rows go to ``DynamicQuantizeMatMul`` (module doc).
DYNAMIC_MIN_ROWS = 16
DOMAIN = "com.microsoft"


def quantize_blocks(weight: np.ndarray, block_size: int = BLOCK_SIZE) -> tuple[np.ndarray, np.ndarray]:
    """Symmetric int8 blocks of a ``(K, N)`` float matrix (module doc).

    Returns:
        ``(stored, scales)``: ``(N, ceil(K / block_size), block_size)`` uint8 (``q + 128``; rows past ``K`` are
        zero weights) and ``(N, ceil(K / block_size))`` float32 scales.
    """
    K, N = weight.shape
    blocks = -(-K // block_size)
    padded = np.zeros((blocks * block_size, N), np.float32)
    padded[:K] = weight
    w = padded.T.reshape(N, blocks, block_size)
    scales = np.abs(w).max(-1) / 127.0
    safe = np.where(scales > 0, scales, 1.0)
    q = np.clip(np.rint(w / safe[..., None]), -127, 127)
    return (q + 128).astype(np.uint8), scales.astype(np.float32)


def dequantize_blocks(stored: np.ndarray, scales: np.ndarray, K: int) -> np.ndarray:
    """The ``(K, N)`` float32 matrix that :func:`quantize_blocks`' output stands for."""
    N, blocks, size = stored.shape
    w = (stored.astype(np.float32) - 128.0) * scales[..., None]
    return w.reshape(N, blocks * size)[:, :K].T.copy()


def quantize_columns(weight: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Symmetric int8 columns of a ``(K, N)`` float matrix: ``(q (K, N) int8, scales (N,) float32)``, every weight
    within ``scale / 2`` of ``q * scale``."""
    scales = (np.abs(weight).max(0) / 127.0).astype(np.float32)
    safe = np.where(scales > 0, scales, 1.0)
    return np.clip(np.rint(weight / safe), -127, 127).astype(np.int8), scales


def quantize_model(model, block_size: int = BLOCK_SIZE, min_elements: int = MIN_ELEMENTS,
                   accuracy_level: int = ACCURACY_LEVEL,
                   dynamic_min_rows: int = DYNAMIC_MIN_ROWS) -> tuple[object, dict]:
    """``model`` (an ``onnx.ModelProto``) with its large constant weights in int8 (module doc).

    Rewritten: ``MatMul(A, W)`` with ``W`` a ``(K, N)`` initializer; ``MatMul(A, W)`` with ``W`` a ``(G, K, N)``
    initializer and ``A`` of static shape ``(G, M, K)`` (a batch of per-group matrices, JointNet's per-joint GRUs):
    split into ``G`` multiplications and concatenated back; ``Gemm(A, W, C)`` with ``alpha = beta = 1`` and ``A``
    not transposed, ``W`` an initializer (either orientation), ``C`` added after. Other nodes, and matrices under
    ``min_elements``, are left as they are.

    Returns:
        ``(model, summary)``: a new ModelProto and ``{"matrices", "dynamic", "weights_int8", "weights_float"}``
        (counts of rewritten matrices, of those multiplied by ``DynamicQuantizeMatMul``, and of the weight elements
        stored in int8 and left in float32).
    """
    import onnx
    from onnx import helper, numpy_helper

    model = onnx.shape_inference.infer_shapes(model)
    graph = model.graph
    inits = {t.name: t for t in graph.initializer}
    shapes = {v.name: [d.dim_value if d.HasField("dim_value") else None for d in v.type.tensor_type.shape.dim]
              for v in list(graph.value_info) + list(graph.input) + list(graph.output)}
    new_inits: list = []
    nodes: list = []
    done = {"matrices": 0, "dynamic": 0, "weights_int8": 0}
    counter = iter(range(1 << 30))

    def matmul_int8(a: str, weight: np.ndarray, out: str) -> None:
        """``out = a @ weight`` for a ``(K, N)`` float matrix, in int8 (the kernel by ``a``'s rows)."""
        K, N = weight.shape
        tag = f"int8_{next(counter)}"
        shape = shapes.get(a)
        rows = int(np.prod(shape[:-1])) if shape and None not in shape[:-1] else 1  # unknown: a vector
        if rows >= dynamic_min_rows:
            q, scales = quantize_columns(weight)
            new_inits.extend([numpy_helper.from_array(q, f"{tag}_weight"),
                              numpy_helper.from_array(scales, f"{tag}_scales"),
                              numpy_helper.from_array(np.zeros(N, np.int8), f"{tag}_zero")])
            nodes.append(helper.make_node("DynamicQuantizeMatMul", [a, f"{tag}_weight", f"{tag}_scales",
                                                                    f"{tag}_zero"], [out], name=tag, domain=DOMAIN))
            done["dynamic"] += 1
        else:
            stored, scales = quantize_blocks(weight, block_size)
            new_inits.extend([numpy_helper.from_array(stored, f"{tag}_weight"),
                              numpy_helper.from_array(scales.reshape(-1), f"{tag}_scales")])
            nodes.append(helper.make_node("MatMulNBits", [a, f"{tag}_weight", f"{tag}_scales"], [out], name=tag,
                                          domain=DOMAIN, K=K, N=N, bits=8, block_size=block_size,
                                          accuracy_level=accuracy_level))
        done["matrices"] += 1
        done["weights_int8"] += K * N

    def weight_of(node, index: int):
        name = node.input[index] if len(node.input) > index else ""
        if name not in inits:
            return None
        w = numpy_helper.to_array(inits[name])
        return w if w.dtype == np.float32 and w.size >= min_elements else None

    for node in graph.node:
        w = weight_of(node, 1) if node.op_type in ("MatMul", "Gemm") else None
        attrs = {a.name: helper.get_attribute_value(a) for a in node.attribute}
        if w is not None and node.op_type == "MatMul" and w.ndim == 2:
            matmul_int8(node.input[0], w, node.output[0])
        elif w is not None and node.op_type == "MatMul" and w.ndim == 3 and _batched(shapes.get(node.input[0]), w):
            G = w.shape[0]
            tag = f"int8_split_{next(counter)}"
            parts = [f"{tag}_in{g}" for g in range(G)]
            new_inits.append(numpy_helper.from_array(np.ones(G, np.int64), f"{tag}_sizes"))
            nodes.append(helper.make_node("Split", [node.input[0], f"{tag}_sizes"], parts, axis=0, name=tag))
            for g in range(G):
                shapes[parts[g]] = [1, *shapes[node.input[0]][1:]]
                matmul_int8(parts[g], w[g], f"{tag}_out{g}")
            nodes.append(helper.make_node("Concat", [f"{tag}_out{g}" for g in range(G)], [node.output[0]], axis=0,
                                          name=f"{tag}_concat"))
        elif (w is not None and node.op_type == "Gemm" and w.ndim == 2 and attrs.get("transA", 0) == 0
              and attrs.get("alpha", 1.0) == 1.0 and attrs.get("beta", 1.0) == 1.0):
            weight = w.T if attrs.get("transB", 0) else w
            if len(node.input) > 2 and node.input[2]:
                matmul_int8(node.input[0], weight, node.output[0] + "_int8_product")
                nodes.append(helper.make_node("Add", [node.output[0] + "_int8_product", node.input[2]],
                                              [node.output[0]], name=node.name + "_bias"))
            else:
                matmul_int8(node.input[0], weight, node.output[0])
        else:
            nodes.append(node)

    used = {i for n in nodes for i in n.input} | {o.name for o in graph.output}
    kept = [t for t in graph.initializer if t.name in used] + new_inits
    del graph.node[:]
    graph.node.extend(nodes)
    del graph.initializer[:]
    graph.initializer.extend(kept)
    if not any(o.domain == DOMAIN for o in model.opset_import):
        model.opset_import.append(helper.make_opsetid(DOMAIN, 1))
    floats = sum(int(np.prod(t.dims)) for t in graph.initializer if t.data_type == onnx.TensorProto.FLOAT)
    return model, {**done, "weights_float": floats}


def _batched(shape, weight: np.ndarray) -> bool:
    """Whether a MatMul input of ``shape`` times a ``(G, K, N)`` weight is one product per group: ``(G, M, K)``."""
    return (shape is not None and len(shape) == 3 and shape[0] == weight.shape[0] and shape[2] == weight.shape[1]
            and shape[1] is not None)

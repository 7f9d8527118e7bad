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
  per output column on 7 bits (``scale[n] = max_k |W[k, n]| / 63``, :data:`COLUMN_LEVELS`, int8, zero point 0),
  the input rounded at run time to uint8 with one scale and zero point for the whole tensor: 3.5x faster than the
  block kernel at 80 rows, coarser in its input (a recurrent state never goes through it).

Rounding the inputs, not the weights, is what moves a model's vertices most (measured on the shipped JointNet
skirt: 2.7 mm from the inputs, 0.5 mm from the weights). So by default each product is made twice, by the same
kernel and weights: once on the input and once on its *residual*, the input minus its int8 rounding (computed in
the graph as the kernel rounds: per block, or by ``DynamicQuantizeLinear`` per tensor), and the two added. The
residual is at most half a rounding step ``s / 2``, and the kernel's own rounding of it 254 times finer, so each input
of the sum is within ``s / 508`` of its exact value (one rounding: ``s / 2``): the product of the dequantized weights
and the input as it was, the vertices within 0.02 mm of the float model with the rounded weights
(:mod:`loosefit.quantize` makes a run of those weights), for about 1.25x the time of a single rounding (still more
than twice the float model's speed at the papers' sizes). A product whose input depends on no graph input
(JointNet's garment prior) stays float: onnxruntime folds it when it loads the model.

The tests bound both kernels against the dequantized weights and the input's rounding, with and without the
residual.
"""

from __future__ import annotations

import numpy as np

#: Input rows per quantization block of ``MatMulNBits`` (one scale each; a matrix with fewer rows gets the
#: smallest power of two, at least 16, that holds them: :func:`block_size_for`). Measured at the papers' sizes
#: (JointNet, 4.2k-vertex dress, one thread, the median of five interleaved passes): blocks of 32 / 64 / 128 weights
#: 10.4 / 9.7 / 9.1 ms a frame, the scale arithmetic being a share of the kernel's time.
BLOCK_SIZE = 128
#: Matrices with fewer elements stay float32: they are a small share of the bytes and often the most sensitive.
MIN_ELEMENTS = 16384
#: ``MatMulNBits``' integer kernels (inputs rounded to int8 per block): about 25x faster than its float path for 8 bits.
ACCURACY_LEVEL = 4
#: Products over at least this many input rows go to ``DynamicQuantizeMatMul`` (module doc).
DYNAMIC_MIN_ROWS = 16
DOMAIN = "com.microsoft"
#: Largest magnitude of ``DynamicQuantizeMatMul``'s int8 weights: 63, 7 bits (onnxruntime's ``reduce_range``).
#: Its x86 kernel without VNNI (AVX2 only) multiplies the uint8 input by the int8 weights in pairs summed in int16
#: (``vpmaddubsw``): ``2 * 255 * 127`` overflows and saturates, ``2 * 255 * 63`` fits. Measured on an AMD EPYC with
#: AVX2: products of 96 inputs up to 4.9 off with 127 levels (JointNet's int8 skirt 2.3 mm from its own weights),
#: within 3e-6 of the exact integer product with 63.
COLUMN_LEVELS = 63


def block_size_for(K: int, block_size: int = BLOCK_SIZE) -> int:
    """The block of a ``(K, N)`` matrix: ``block_size``, or for fewer rows the power of two (>= 16, as
    ``MatMulNBits`` requires) that holds them, so that a short matrix is not mostly padding."""
    return max(16, min(block_size, 1 << (K - 1).bit_length()))


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


def quantize_columns(weight: np.ndarray, levels: int = COLUMN_LEVELS) -> tuple[np.ndarray, np.ndarray]:
    """Symmetric int8 columns of a ``(K, N)`` float matrix: ``(q (K, N) int8 in [-levels, levels], scales (N,)
    float32)``, ``scale = max |column| / levels``, every weight within ``scale / 2`` of ``q * scale``."""
    scales = (np.abs(weight).max(0) / float(levels)).astype(np.float32)
    safe = np.where(scales > 0, scales, 1.0)
    return np.clip(np.rint(weight / safe), -levels, levels).astype(np.int8), scales


def quantize_model(model, block_size: int = BLOCK_SIZE, min_elements: int = MIN_ELEMENTS,
                   accuracy_level: int = ACCURACY_LEVEL, dynamic_min_rows: int = DYNAMIC_MIN_ROWS,
                   residual: bool = True, rounded: dict | None = None) -> tuple[object, dict]:
    """``model`` (an ``onnx.ModelProto``) with its large constant weights in int8 (module doc).

    Rewritten: ``MatMul(A, W)`` with ``W`` a ``(K, N)`` initializer; ``MatMul(A, W)`` with ``W`` a ``(G, K, N)``
    initializer and ``A`` of static shape ``(G, M, K)`` (a batch of per-group matrices, JointNet's per-joint GRUs):
    split into ``G`` multiplications and concatenated back; ``Gemm(A, W, C)`` with ``alpha = beta = 1`` and ``A``
    not transposed, ``W`` an initializer (either orientation), ``C`` added after. Other nodes, and matrices under
    ``min_elements``, are left as they are.

    Args:
        residual: the integer kernels also multiply what rounding their input to int8 left over
            (:func:`_residual_rows`): each input of the product is then within 1/508 of its rounding step of its
            exact value instead of 1/2 (a model's vertices 0.001-0.02 mm from the dequantized model's instead of
            1.6-2.7 mm), at the cost of twice the integer arithmetic.
        rounded: when given, filled with ``{initializer name: its dequantized values, in its own layout}`` for
            every rewritten weight (:mod:`loosefit.quantize` puts them back into the run's parameters).

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
    rounded = {} if rounded is None else rounded

    def constant(values, dtype=np.int64) -> str:
        name = f"int8_const_{next(counter)}"
        new_inits.append(numpy_helper.from_array(np.asarray(values, dtype), name))
        return name

    def node(op: str, inputs: list[str], **attrs) -> str:
        out = f"int8_{op.lower()}_{next(counter)}"
        nodes.append(helper.make_node(op, inputs, [out], name=out, **({"domain": DOMAIN} if op in (
            "MatMulNBits", "DynamicQuantizeMatMul") else {}), **attrs))
        return out

    def rows_of(a: str) -> int:
        shape = shapes.get(a)
        return int(np.prod(shape[:-1])) if shape and None not in shape[:-1] else 1  # unknown: a vector

    def dynamic_product(a: str, weight: np.ndarray) -> tuple[str, np.ndarray]:
        q, scales = quantize_columns(weight)
        names = [constant(q, np.int8), constant(scales, np.float32), constant(np.zeros(len(scales)), np.int8)]
        product = node("DynamicQuantizeMatMul", [a, *names])
        if residual:  # the same kernel on what its rounding of ``a`` (DynamicQuantizeLinear's) left over
            low = node("Sub", [a, node("DequantizeLinear", _outputs(nodes, node("DynamicQuantizeLinear", [a]), 3))])
            product = node("Add", [product, node("DynamicQuantizeMatMul", [low, *names])])
        done["dynamic"] += 1
        return product, q.astype(np.float32) * scales

    def block_product(a: str, weight: np.ndarray) -> tuple[str, np.ndarray]:
        """``a @ weight`` by ``MatMulNBits``: the output's name and the dequantized weights."""
        K, N = weight.shape
        block = block_size_for(K, block_size)
        stored, scales = quantize_blocks(weight, block)
        return node("MatMulNBits", [a, constant(stored, np.uint8), constant(scales.reshape(-1), np.float32)], K=K,
                    N=N, bits=8, block_size=block, accuracy_level=accuracy_level), dequantize_blocks(
            stored, scales, K)

    def with_residual(a: str, K: int, axis: int) -> str:
        """``a`` with the residual of its int8 blocks stacked after it along ``axis``."""
        return node("Concat", [a, _residual_rows(a, K, block_size_for(K, block_size), node, constant)], axis=axis)

    def halves_added(product: str, axis: int) -> str:
        return node("Add", _outputs(nodes, node("Split", [product], axis=axis), 2))

    def matmul_int8(a: str, weight: np.ndarray) -> tuple[str, np.ndarray]:
        """``a @ weight`` for a ``(K, N)`` float matrix in int8 (the kernel by ``a``'s rows): the output's name
        and the dequantized weights."""
        if rows_of(a) >= dynamic_min_rows:
            return dynamic_product(a, weight)
        if not (residual and accuracy_level == 4):  # the float path multiplies the input as it is
            return block_product(a, weight)
        rank = len(shapes.get(a) or [None])
        flat = a if rank == 2 else node("Reshape", [a, constant([-1, weight.shape[0]])])
        product, deq = block_product(with_residual(flat, weight.shape[0], 0), weight)
        out = halves_added(product, 0)
        if rank != 2:
            out = node("Reshape", [out, node("Concat", [node("Slice", [node("Shape", [a]), constant([0]),
                                                                     constant([-1])]), constant([weight.shape[1]])],
                                                    axis=0)])
        return out, deq

    def grouped(a: str, w: np.ndarray) -> tuple[str, np.ndarray]:
        """``a (G, M, K) @ w (G, K, N)``: one product per group, concatenated back."""
        G, K, _ = w.shape
        M = shapes[a][1]
        if M >= dynamic_min_rows or not (residual and accuracy_level == 4):
            parts = _outputs(nodes, node("Split", [a, constant(np.ones(G))], axis=0), G)
            products = [matmul_int8(_shaped(shapes, p, [1, M, K]), w[g]) for g, p in enumerate(parts)]
            return node("Concat", [p for p, _ in products], axis=0), np.stack([d for _, d in products])
        stacked = with_residual(a, K, 1)  # (G, 2M, K): the residual once for every group
        parts = _outputs(nodes, node("Split", [stacked, constant(np.ones(G))], axis=0), G)
        products = [block_product(p, w[g]) for g, p in enumerate(parts)]
        return halves_added(node("Concat", [p for p, _ in products], axis=0), 1), np.stack([d for _, d in products])

    def weight_of(n, index: int):
        name = n.input[index] if len(n.input) > index else ""
        if name not in inits:
            return None
        w = numpy_helper.to_array(inits[name])
        return w if w.dtype == np.float32 and w.size >= min_elements else None

    def replace(n, out: str, deq: np.ndarray, matrices: int) -> None:
        nodes.append(helper.make_node("Identity", [out], [n.output[0]], name=f"int8_{n.output[0]}"))
        rounded[n.input[1]] = deq
        done["matrices"] += matrices
        done["weights_int8"] += deq.size

    constant_tensors = _constants(graph)
    for n in graph.node:
        # a product of constants stays float: onnxruntime computes it once, when it loads the model
        w = weight_of(n, 1) if n.op_type in ("MatMul", "Gemm") and n.input[0] not in constant_tensors else None
        attrs = {a.name: helper.get_attribute_value(a) for a in n.attribute}
        if w is not None and n.op_type == "MatMul" and w.ndim == 2:
            replace(n, *matmul_int8(n.input[0], w), 1)
        elif w is not None and n.op_type == "MatMul" and w.ndim == 3 and _batched(shapes.get(n.input[0]), w):
            replace(n, *grouped(n.input[0], w), w.shape[0])
        elif (w is not None and n.op_type == "Gemm" and w.ndim == 2 and attrs.get("transA", 0) == 0
              and attrs.get("alpha", 1.0) == 1.0 and attrs.get("beta", 1.0) == 1.0):
            out, deq = matmul_int8(n.input[0], w.T if attrs.get("transB", 0) else w)
            if len(n.input) > 2 and n.input[2]:
                out = node("Add", [out, n.input[2]])
            replace(n, out, deq.T if attrs.get("transB", 0) else deq, 1)
        else:
            nodes.append(n)

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


def _residual_rows(a: str, K: int, block_size: int, node, constant) -> str:
    """The nodes of ``a - round8(a)`` for ``a (..., K)``: what ``MatMulNBits`` (``accuracy_level=4``) leaves of
    ``a`` when it rounds each block of ``block_size`` along ``K`` to int8 with scale ``s`` = the block's largest
    magnitude / 127, ``a`` times ``1 / s`` rounded half to even (as its x86 kernels do). Multiplied by the same
    kernel, whose own rounding of it (at most ``s / 2`` in magnitude) is 254 times finer, and added, it makes the
    product that of the dequantized weights and the input as it was, each input within ``s / 508``."""
    blocks = -(-K // block_size)
    flat = node("Reshape", [a, constant([-1, K])])
    if blocks * block_size != K:
        flat = node("Pad", [flat, constant([0, 0, 0, blocks * block_size - K])])
    x = node("Reshape", [flat, constant([-1, blocks, block_size])])
    scale = node("Div", [node("ReduceMax", [node("Abs", [x])], axes=[2], keepdims=1), constant(127.0, np.float32)])
    inverse = node("Div", [constant(1.0, np.float32), node("Max", [scale, constant(1e-30, np.float32)])])
    low = node("Sub", [x, node("Mul", [node("Round", [node("Mul", [x, inverse])]), scale])])
    low = node("Reshape", [low, constant([-1, blocks * block_size])])
    if blocks * block_size != K:
        low = node("Slice", [low, constant([0]), constant([K]), constant([1])])
    return node("Reshape", [low, node("Shape", [a])])


def _constants(graph) -> set[str]:
    """Names of the tensors that depend on no graph input: initializers, and the outputs of (standard-domain)
    nodes all of whose inputs are such tensors."""
    known = {t.name for t in graph.initializer}
    for n in graph.node:  # nodes are in topological order
        if n.domain in ("", "ai.onnx") and all(not i or i in known for i in n.input):
            known.update(n.output)
    return known


def _outputs(nodes: list, name: str, count: int) -> list[str]:
    """Give the node just added (whose one output is ``name``) ``count`` outputs instead: their names."""
    last = nodes[-1]
    del last.output[:]
    outs = [f"{name}_{i}" for i in range(count)]
    last.output.extend(outs)
    return outs


def _shaped(shapes: dict, name: str, shape: list) -> str:
    shapes[name] = shape
    return name


def _batched(shape, weight: np.ndarray) -> bool:
    """Whether a MatMul input of ``shape`` times a ``(G, K, N)`` weight is one product per group: ``(G, M, K)``."""
    return (shape is not None and len(shape) == 3 and shape[0] == weight.shape[0] and shape[2] == weight.shape[1]
            and shape[1] is not None)

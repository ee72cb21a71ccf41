"""Stores an ONNX model's convolution and fully connected weights as int8 with one float32 scale
per output channel (+ a DequantizeLinear to float32 in the graph).

The shipped face models share a 1.5 MB budget; int8 storage halves what float16 storage
(onnx_f16.py) takes, which leaves room for more networks. Only the storage changes: tract (and
onnxruntime) fold the DequantizeLinear of a constant when the model is optimised at load, so
inference still runs in float32 on the dequantised weights. Symmetric quantisation (zero point 0,
scale = max |w| / 127 per output channel) rounds every weight by at most half a step, 0.4 % of its
channel's largest weight; eval_m3.py measures what that costs (RESEARCH_LOG.md).

Reads float32 weights, or float16 ones behind onnx_f16.py's Cast (the quantised values then come
from the float16 weights, so converting a float16 file gives the same bytes as converting its
float32 source after onnx_f16.py). Biases and tensors under MIN_ELEMENTS stay as they are.

    python3 core/models/train/onnx_q8.py MODEL.onnx [...]   # in place
"""
import sys

import numpy as np
import onnx
from onnx import helper, numpy_helper, TensorProto

from onnx_f16 import save_graph

MIN_ELEMENTS = 64
# DequantizeLinear's per-axis form needs opset 13.
MIN_OPSET = 13


def weight_axis(node, slot):
    """Output-channel axis of the weight that `node` reads at input `slot`, None if not a weight."""
    if slot != 1:
        return None
    if node.op_type == "Conv":
        return 0
    if node.op_type == "Gemm":
        attrs = {a.name: helper.get_attribute_value(a) for a in node.attribute}
        return 0 if attrs.get("transB", 0) == 1 else 1
    if node.op_type == "MatMul":
        return 1
    return None


def quantize(w, axis):
    """Symmetric int8 per-channel quantisation along `axis`: (int8 values, float32 scales)."""
    moved = np.moveaxis(w.astype(np.float64), axis, 0).reshape(w.shape[axis], -1)
    peak = np.abs(moved).max(axis=1)
    scale = np.where(peak > 0, peak / 127.0, 1.0).astype(np.float32)
    shape = [1] * w.ndim
    shape[axis] = -1
    q = np.clip(np.rint(w.astype(np.float64) / scale.reshape(shape).astype(np.float64)), -127, 127)
    return q.astype(np.int8), scale


def to_q8(path):
    m = onnx.load(path)
    if not any(o.domain in ("", "ai.onnx") and o.version >= MIN_OPSET for o in m.opset_import):
        raise SystemExit(f"{path}: opset < {MIN_OPSET}, no per-axis DequantizeLinear")
    g = m.graph
    inits = {i.name: i for i in g.initializer}
    # onnx_f16.py's Casts: float32 name -> float16 initializer name.
    casts = {n.output[0]: n for n in g.node
             if n.op_type == "Cast" and len(n.input) == 1 and n.input[0] in inits}
    axes = {}
    for n in g.node:
        for slot, name in enumerate(n.input):
            axis = weight_axis(n, slot)
            if axis is not None:
                axes.setdefault(name, set()).add(axis)
    done, new_nodes, drop_inits, drop_casts = [], [], set(), set()
    for name, axis_set in sorted(axes.items()):
        if len(axis_set) != 1:
            continue
        axis = axis_set.pop()
        if name in casts:
            src = inits[casts[name].input[0]]
            drop_casts.add(name)
        elif name in inits:
            src = inits[name]
        else:
            continue
        if src.data_type not in (TensorProto.FLOAT, TensorProto.FLOAT16) or np.prod(src.dims) < MIN_ELEMENTS:
            continue
        w = numpy_helper.to_array(src).astype(np.float32)
        if w.ndim < 2:
            continue
        q, scale = quantize(w, axis)
        base = name.replace("::", "_")
        qi = numpy_helper.from_array(q, base + "_q8")
        si = numpy_helper.from_array(scale, base + "_scale")
        zi = numpy_helper.from_array(np.zeros_like(scale, dtype=np.int8), base + "_zero")
        done += [qi, si, zi]
        drop_inits.add(src.name)
        new_nodes.append(helper.make_node("DequantizeLinear", [qi.name, si.name, zi.name], [name],
                                          axis=axis, name="dq_" + base))
    if not new_nodes:
        return
    # A float16 source shared by another (non-weight) consumer keeps its Cast and initializer.
    produced = {n.output[0] for n in new_nodes}
    used = {x for n in g.node if n.output[0] not in drop_casts for x in n.input} - produced
    drop_inits -= used
    keep = [i for i in g.initializer if i.name not in drop_inits] + done
    nodes = new_nodes + [n for n in g.node if not (n.op_type == "Cast" and n.output[0] in drop_casts)]
    save_graph(m, keep, nodes, path)


if __name__ == "__main__":
    for p in sys.argv[1:]:
        to_q8(p)

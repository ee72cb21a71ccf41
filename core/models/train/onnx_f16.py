"""Stores an ONNX model's float32 weights as float16 (+ a Cast to float32 in the graph).

The shipped models must stay small (all face models ≤ 1.5 MB); float16 storage halves them, and the
Cast of a constant is folded by tract (and onnxruntime) when the model is optimised at load, so
inference still runs in float32. The rounding costs < 0.01 % NME (checked by eval_m3.py).

    python3 core/models/train/onnx_f16.py MODEL.onnx [...]   # in place
"""
import sys

import numpy as np
import onnx
from onnx import helper, numpy_helper, TensorProto

MIN_ELEMENTS = 16  # tiny tensors (BatchNorm scalars, shapes) are not worth a Cast node


def to_f16(path):
    m = onnx.load(path)
    g = m.graph
    casts, keep = [], []
    for init in g.initializer:
        if init.data_type == TensorProto.FLOAT and np.prod(init.dims) >= MIN_ELEMENTS:
            arr = numpy_helper.to_array(init).astype(np.float16)
            half = numpy_helper.from_array(arr, init.name + "_f16")
            keep.append(half)
            casts.append(helper.make_node("Cast", [half.name], [init.name], to=TensorProto.FLOAT,
                                          name="cast_" + init.name))
        else:
            keep.append(init)
    if not casts:
        return
    save_graph(m, keep, casts + list(g.node), path)


def save_graph(m, initializers, nodes, path):
    """Replaces model `m`'s initializers and nodes, checks it and saves it to `path`."""
    g = m.graph
    del g.initializer[:]
    g.initializer.extend(initializers)
    del g.node[:]
    g.node.extend(nodes)
    onnx.checker.check_model(m)
    onnx.save(m, path)


if __name__ == "__main__":
    for p in sys.argv[1:]:
        to_f16(p)

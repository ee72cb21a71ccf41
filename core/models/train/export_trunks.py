#!/usr/bin/env python3
"""Exports M3 nets with given trunks and random weights, for timing them with tract
(`cargo run --release -p monotrack-core --example time_nets -- DIR`; RESEARCH_LOG.md's
"Trunk design" table). The time of a net does not depend on its weights.

    python3 core/models/train/export_trunks.py DIR level1=16s-32s-48s-48c-64s face=16s-32s-48s-48c-96s \
        brows=8s-16s-32s-32c-48s mouth=16s-32s-48s-48c-64s eye=8s-16s-16c-32s

Nets not named are not written. Trunk specs: m3nets.trunk.
"""
import os
import sys

import torch

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import m3data as D  # noqa: E402
from m3nets import Level1, Level2  # noqa: E402


def main():
    out, specs = sys.argv[1], dict(a.split("=") for a in sys.argv[2:])
    os.makedirs(out, exist_ok=True)
    torch.manual_seed(0)
    for name, spec in specs.items():
        if name == "level1":
            model, shapes, ins = Level1(64, spec=spec), [(1, 1, 64, 64)], ["image"]
        else:
            z = D.ZONES[name]
            model = Level2(z["width"], z["height"], len(z["indices68"]), len(z.get("gestures", [])),
                           bool(z.get("gaze")), spec=spec)
            shapes, ins = [(1, 1, z["height"], z["width"]), (1, 5)], ["patch", "yaw"]
        model.eval()
        torch.onnx.export(model, tuple(torch.rand(s) for s in shapes), os.path.join(out, f"{name}.onnx"),
                          input_names=ins, opset_version=17, dynamo=False)
        print(name, sum(p.numel() for p in model.parameters()), "parameters")


if __name__ == "__main__":
    main()

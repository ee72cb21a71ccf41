#!/usr/bin/env python3
"""Estimates m3.json's `x_offset_iod` on the training split and writes it into m3.json.

Why: the nets are trained on mirrored faces too (x -> W - x with the image flipped), which is exact
under the CONTRACT's pixel convention, so a systematic x offset of the annotations relative to the
image content flips sign between a face and its mirror and the nets cannot learn it: their points sit
left of the annotated ones by about 0.8 % of the outer-eye-corner distance (0.7 px on the training
faces, 0.9 px on the validation faces; y has no such offset, as no augmentation flips y). The same
offset is in the validation labels and presumably in any test set annotated the same way (300-W), so
the inference adds it back: x += x_offset_iod * |p36 - p45| on every output point (M3_IO.md). Measured
and chosen on the training split only (landmark boxes jittered as eval_m3.py does), never on the
validation split: MODEL_CARD.md has the validation figures with and without it.

    python3 core/models/train/calibrate_m3.py [MODEL_DIR]   # default core/models/m3 ($MONOTRACK_M3_OUT)

train_m3.py runs it after every training run (it rewrites m3.json).
"""
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import m3data as D  # noqa: E402
import eval_m3 as E  # noqa: E402
import m3_reference as R  # noqa: E402

# The evaluation's box jitter (centre +-5 %, side +-10 %) with a seed of its own: training faces.
JITTER_SEED = 11
DECIMALS = 4


def estimate(model_dir):
    """Mean over the training faces of the mean x error (annotated - ours) of their 68 points, in
    units of our outer-eye-corner distance, with the offset itself at 0."""
    m3 = R.M3(model_dir)
    m3.cfg["x_offset_iod"] = 0.0
    paths, faces = D.load_faces68("train")
    ratios = []
    for f, b in zip(faces, E.jittered_boxes(faces, JITTER_SEED)):
        p = m3.run(D.load_gray(paths[f["image"]]), np.array(b, float))["landmarks68"]
        ratios.append((f["pts"][:, 0] - p[:, 0]).mean() / D.outer_eye_distance(p))
    return float(np.mean(ratios)), len(ratios)


def write(model_dir):
    value, n = estimate(model_dir)
    value = round(value, DECIMALS)
    path = os.path.join(model_dir, "m3.json")
    cfg = json.load(open(path))
    cfg["x_offset_iod"] = value
    with open(path, "w") as fh:
        json.dump(cfg, fh, indent=1)
    return value, n


if __name__ == "__main__":
    d = sys.argv[1] if len(sys.argv) > 1 else os.environ.get("MONOTRACK_M3_OUT", os.path.join(D.REPO, "core", "models", "m3"))
    v, n = write(d)
    print(f"x_offset_iod = {v} ({n} training faces) -> {os.path.join(d, 'm3.json')}")

#!/usr/bin/env python3
"""Estimates m3.json's `x_offset_iod` and fits its `shape_prior` (shape_prior.bin) on the training
split, and writes both into the model directory.

Why: the nets are trained on mirrored faces too (x -> W - x with the image flipped), which is exact
under the CONTRACT's pixel convention, so a systematic x offset of the annotations relative to the
image content flips sign between a face and its mirror and the nets cannot learn it: their points sit
left of the annotated ones by about 0.8 % of the outer-eye-corner distance (0.7 px on the training
faces, 0.9 px on the validation faces; y has no such offset, as no augmentation flips y). The same
offset is in the validation labels and presumably in any test set annotated the same way (300-W), so
the inference adds it back: x += x_offset_iod * |p36 - p45| on every output point (M3_IO.md). Measured
and chosen on the training split only (landmark boxes jittered as eval_m3.py does), never on the
validation split: RESEARCH_LOG.md has the validation figures with and without it.

The shape prior (M3_IO.md): for each zone a ridge regression that predicts the zone's points from
every other point, fitted on the same training predictions (with the offset) against the annotated
points, in the outer-eye-corner frame. The nets' training-face points are better than their unseen
ones (NME 3.06 vs 4.13 %), so how far inference moves towards the regression (PRIOR_ZONES' weights)
cannot be chosen on the training faces (they say 0 for the jaw): the weights were chosen on the
validation split, on a grid, and checked by choosing on one half and scoring the other (RESEARCH_LOG.md).

    python3 core/models/train/calibrate_m3.py [MODEL_DIR]   # default core/models/m3 ($MONOTRACK_M3_OUT)

train_m3.py runs it after every training run (it rewrites m3.json and shape_prior.bin).
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
# Ridge penalty of the shape-prior regressions, in the frame's units (outer eye corners 2 apart);
# the validation NME is flat from 0.001 to 0.03.
RIDGE = 0.01
PRIOR_FILE = "shape_prior.bin"
# (zone, points, weight, normal weight or None): the jaw is an open contour whose nets' error lies
# mostly along it, so it moves along and across by different shares.
PRIOR_ZONES = [
    ("jaw", list(range(0, 17)), 0.5, 0.1),
    ("brows", list(range(17, 27)), 0.3, None),
    ("nose", list(range(27, 36)), 0.3, None),
    ("eyes", list(range(36, 48)), 0.3, None),
    ("mouth", list(range(48, 68)), 0.1, None),
]


def predict(model_dir):
    """The merged points (offset and prior off) and annotated points of the training faces."""
    m3 = R.M3(model_dir)
    m3.cfg["x_offset_iod"] = 0.0
    m3.shape_prior = None
    paths, faces = D.load_faces68("train")
    pred = [m3.run(D.load_gray(paths[f["image"]]), np.array(b, float))["landmarks68"]
            for f, b in zip(faces, E.jittered_boxes(faces, JITTER_SEED))]
    return np.array(pred), np.array([f["pts"] for f in faces])


def estimate_offset(pred, truth):
    """Mean over the faces of the mean x error (annotated - ours) of their 68 points, in units of
    our outer-eye-corner distance."""
    return float(np.mean([(g[:, 0] - p[:, 0]).mean() / D.outer_eye_distance(p) for p, g in zip(pred, truth)]))


def fit_prior(pred, truth, indices):
    """Ridge regression (the intercept penalised like the rest: RIDGE is tiny) from the other
    points to the zone's annotated points, both in the predicted points' frame."""
    X = np.array([D.prior_features(p, indices) for p in pred])
    Y = np.array([D.to_prior_frame(g[indices], D.prior_frame(p)).reshape(-1) for p, g in zip(pred, truth)])
    return np.linalg.solve(X.T @ X + RIDGE * np.eye(X.shape[1]), X.T @ Y)


def write(model_dir):
    pred, truth = predict(model_dir)
    value = round(estimate_offset(pred, truth), DECIMALS)
    pred = np.array([D.with_x_offset(p, value) for p in pred])
    zones, mats = [], []
    for name, idx, w, wn in PRIOR_ZONES:
        mats.append(fit_prior(pred, truth, idx).astype("<f4"))
        zones.append({"name": name, "indices68": idx, "weight": w, **({"normal_weight": wn} if wn is not None else {})})
    with open(os.path.join(model_dir, PRIOR_FILE), "wb") as fh:
        for m in mats:
            fh.write(m.tobytes())
    path = os.path.join(model_dir, "m3.json")
    cfg = json.load(open(path))
    cfg["x_offset_iod"] = value
    cfg["shape_prior"] = {"file": PRIOR_FILE, "zones": zones}
    with open(path, "w") as fh:
        json.dump(cfg, fh, indent=1)
    return value, len(pred)


if __name__ == "__main__":
    d = sys.argv[1] if len(sys.argv) > 1 else os.environ.get("MONOTRACK_M3_OUT", os.path.join(D.REPO, "core", "models", "m3"))
    v, n = write(d)
    print(f"x_offset_iod = {v}, shape prior ({n} training faces) -> {os.path.join(d, 'm3.json')}, {PRIOR_FILE}")

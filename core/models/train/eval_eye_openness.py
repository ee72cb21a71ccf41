#!/usr/bin/env python3
"""Per-eye openness of the shipped SDK against the annotated eye aspect ratio, on faces68.

    python3 core/models/train/eval_eye_openness.py --monotrack target/release/monotrack [--fit]

- Faces: every annotated face of the faces68 splits (m3data.load_faces68; validation = line
  i % 10 == 0, M3_IO.md), boxes = the landmark boxes with eval_m3.py's seeded jitter.
- Per eye (the subject's own: right = points 36-41, left = 42-47), the eye aspect ratio
  EAR = (|p2 - p6| + |p3 - p5|) / (2 |p1 - p4|) of the annotated points (the label) and of the
  SDK's (`monotrack landmarks`, single-pass mode, the video tracker's, and mirror-average mode,
  the CLI's stills default), and the SDK's openness (`eyes.left_open` / `eyes.right_open`,
  core::landmarks::eyes).
- Closed: annotated EAR < CLOSED_EAR (core::landmarks::eyes::CLOSED_EAR); open: annotated EAR
  > OPEN_EAR. Reported per split and mode: Spearman's rank correlation of openness and annotated
  EAR, the fraction (and counts) of closed eyes reading < 0.5 and of open eyes reading > 0.5.
- --fit: the logistic's centre and slope (EYE_OPEN_CENTRE, EYE_OPEN_SLOPE) by a class-balanced
  logistic regression of "annotated EAR >= CLOSED_EAR" on the SDK's single-pass EAR, on the
  training split only; printed, and stored in the metrics with the values the binary used.
Writes core/models/m3/eye_openness_metrics.json and prints a table.
"""
import argparse
import json
import os
import re
import subprocess
import sys
import tempfile

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import m3data as D  # noqa: E402
from eval_m3 import jittered_boxes  # noqa: E402

EYES_RS = os.path.join(D.REPO, "core", "src", "landmarks", "eyes.rs")
OPEN_EAR = 0.2
EYE_START = {"right": 36, "left": 42}  # the subject's eyes
MODES = {"single_pass": ["--single-pass"], "mirror_average": []}


def rust_constant(name):
    m = re.search(rf"pub const {name}: f32 = ([-0-9.eE]+);", open(EYES_RS).read())
    return float(m.group(1))


def ear(pts, e):
    p = np.asarray(pts, np.float64)
    width = np.linalg.norm(p[e] - p[e + 3])
    lids = np.linalg.norm(p[e + 1] - p[e + 5]) + np.linalg.norm(p[e + 2] - p[e + 4])
    return lids / (2.0 * width) if width > 0 else 0.0


def ranks(x):
    """Ranks 1..n, ties sharing their mean rank."""
    x = np.asarray(x)
    order = np.argsort(x, kind="mergesort")
    r = np.empty(len(x))
    r[order] = np.arange(1, len(x) + 1)
    for v in np.unique(x):
        tie = x == v
        if tie.sum() > 1:
            r[tie] = r[tie].mean()
    return r


def spearman(a, b):
    return float(np.corrcoef(ranks(a), ranks(b))[0, 1])


def run(monotrack, split, mode, tmp):
    """Per eye of `split`: (annotated EAR, SDK EAR, SDK openness) arrays, and the faces run."""
    paths, faces = D.load_faces68(split)
    man = os.path.join(tmp, f"{split}.jsonl")
    with open(man, "w") as fh:
        for f, b in zip(faces, jittered_boxes(faces)):
            fh.write(json.dumps({"image": paths[f["image"]], "faces": [{"box": [float(v) for v in b]}]}) + "\n")
    out = man + f".{mode}.out"
    subprocess.run([monotrack, "landmarks", man, "--out", out] + MODES[mode], check=True)
    label, pred, opened = [], [], []
    for f, line in zip(faces, open(out)):
        o = json.loads(line)["faces"][0]
        for side, e in EYE_START.items():
            label.append(ear(f["pts"], e))
            pred.append(ear(o["landmarks68"], e))
            opened.append(o["eyes"][f"{side}_open"])
    return np.array(label), np.array(pred), np.array(opened), len(faces)


def fit_logistic(x, y):
    """Centre and slope of p(y = 1 | x) = 1 / (1 + exp(-slope (x - centre))), each class weighted
    to half the total (Newton's method on the weighted log-likelihood)."""
    w = np.where(y, 0.5 / y.mean(), 0.5 / (1 - y.mean()))
    X = np.c_[np.ones_like(x), x]
    beta = np.zeros(2)
    for _ in range(100):
        p = 1 / (1 + np.exp(-X @ beta))
        g = X.T @ (w * (y - p))
        H = (X * (w * p * (1 - p))[:, None]).T @ X
        step = np.linalg.solve(H, g)
        beta += step
        if np.abs(step).max() < 1e-10:
            break
    return -beta[0] / beta[1], beta[1]


def summary(label, opened, closed_ear):
    closed, open_ = label < closed_ear, label > OPEN_EAR
    return {"eyes": int(len(label)), "spearman_openness_vs_annotated_ear": round(spearman(opened, label), 4),
            "closed_eyes": int(closed.sum()), "closed_reading_below_half": int((opened[closed] < 0.5).sum()),
            "closed_fraction_below_half": round(float((opened[closed] < 0.5).mean()), 4) if closed.any() else None,
            "open_eyes": int(open_.sum()), "open_reading_above_half": int((opened[open_] > 0.5).sum()),
            "open_fraction_above_half": round(float((opened[open_] > 0.5).mean()), 4) if open_.any() else None}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--monotrack", required=True, help="the built `monotrack` CLI")
    ap.add_argument("--fit", action="store_true", help="fit the logistic on the training split")
    ap.add_argument("--out", default=os.path.join(D.REPO, "core", "models", "m3", "eye_openness_metrics.json"))
    a = ap.parse_args()
    closed_ear = rust_constant("CLOSED_EAR")
    centre, slope = rust_constant("EYE_OPEN_CENTRE"), rust_constant("EYE_OPEN_SLOPE")
    tmp = tempfile.mkdtemp()
    metrics = {"label": "annotated 68-point eye aspect ratio (faces68)", "closed_ear_below": closed_ear,
               "open_ear_above": OPEN_EAR, "built_with": {"EYE_OPEN_CENTRE": centre, "EYE_OPEN_SLOPE": slope}}
    for split in ("train", "val"):
        metrics[split] = {}
        for mode in MODES:
            label, pred, opened, n_faces = run(a.monotrack, split, mode, tmp)
            # The CLI's openness is the built constants' logistic of its own points' EAR.
            logistic = 1 / (1 + np.exp(-slope * (pred - centre)))
            s = summary(label, opened, closed_ear)
            s.update({"faces": n_faces, "spearman_sdk_ear_vs_annotated_ear": round(spearman(pred, label), 4),
                      "max_abs_cli_minus_logistic": round(float(np.abs(opened - logistic).max()), 5)})
            metrics[split][mode] = s
            if a.fit and split == "train" and mode == "single_pass":
                c, k = fit_logistic(pred, label >= closed_ear)
                metrics["fitted"] = {"EYE_OPEN_CENTRE": round(float(c), 4), "EYE_OPEN_SLOPE": round(float(k), 1),
                                     "on": "train, single_pass, class-balanced"}
    with open(a.out, "w") as fh:
        json.dump(metrics, fh, indent=1)
    print(f"built with centre {centre}, slope {slope}; closed: annotated EAR < {closed_ear}, open: > {OPEN_EAR}")
    for split in ("train", "val"):
        for mode, s in metrics[split].items():
            print(f"  {split:5s} {mode:15s} spearman {s['spearman_openness_vs_annotated_ear']:.3f}  "
                  f"closed<0.5 {s['closed_reading_below_half']}/{s['closed_eyes']}  "
                  f"open>0.5 {s['open_reading_above_half']}/{s['open_eyes']}  (eyes {s['eyes']})")
    if "fitted" in metrics:
        print("fitted on train:", metrics["fitted"])


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""The learning-free gradient detector (`monotrack landmarks --landmarks gradient`) next to M3 on the
faces68 validation split, in the same run, through the shipped CLI.

    python3 core/models/train/eval_gradient.py --monotrack target/release/monotrack

- Faces: the faces68 validation split (M3_IO.md: line i % 10 == 0).
- Boxes: the ground-truth landmark box of each face (the detector's box convention), and the SDK's
  own detector (each ground-truth face matched to the detection whose box centre lies nearest,
  within a third of the box side; unmatched faces are counted as missed).
- NME: over the 27 points the gradient detector has a 68-point counterpart of, divided by the outer
  eye-corner distance (CONTRACT.md), overall and per part; M3 on the same points and on all 68.
- Speed: the CLI's own `landmarks` time per face (median), this machine.
Writes core/models/gradient_metrics.json and prints a table.
"""
import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import m3data as D  # noqa: E402

# iBUG-68 indices the gradient detector gives (core::landmarks::GRADIENT_TO_68), by part.
PARTS = {"contour": [1, 15, 4, 12, 6, 10, 8], "brows": [17, 19, 21, 22, 24, 26],
         "eyes": [36, 39, 42, 45], "nose": [30, 31, 33, 35], "mouth": [48, 51, 54, 57, 62, 66]}
COUNTERPARTS = sorted(i for v in PARTS.values() for i in v)


def nme(pred, gt, idx):
    iod = D.outer_eye_distance(gt)
    e = np.linalg.norm(pred[idx] - gt[idx], axis=1) / iod
    return float(e.mean())


def run(cli, manifest, mode):
    out = manifest + f".{mode}.jsonl"
    subprocess.run([cli, "landmarks", manifest, "--out", out, "--landmarks", mode], check=True)
    return [json.loads(line) for line in open(out)]


def as_points(face):
    return np.array([p if p is not None else [np.nan, np.nan] for p in face["landmarks68"]], float)


def summarize(pairs):
    """pairs: (pred 68×2 with NaN where absent, gt) → NME per part and overall on the counterparts."""
    out = {"faces": len(pairs)}
    out["counterparts"] = float(np.mean([nme(p, g, COUNTERPARTS) for p, g in pairs])) if pairs else None
    for k, idx in PARTS.items():
        out[k] = float(np.mean([nme(p, g, idx) for p, g in pairs])) if pairs else None
    return out


def matched(lines, faces_by_line):
    pairs, missed, us = [], 0, []
    for line, faces in zip(lines, faces_by_line):
        dets = line.get("faces", [])
        n = max(1, len(dets))
        for gt in faces:
            box = D.box_of(gt)
            c = np.array([box[0] + box[2] / 2, box[1] + box[3] / 2])
            best, dist = None, 1e9
            for d in dets:
                b = d["box"]
                dc = np.linalg.norm(np.array([b[0] + b[2] / 2, b[1] + b[3] / 2]) - c)
                if dc < dist:
                    best, dist = d, dc
            if best is None or dist > max(box[2], box[3]) / 3:
                missed += 1
                continue
            pairs.append((as_points(best), gt))
        us.append(line["timings_us"]["landmarks"] / n)
    return pairs, missed, us


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--monotrack", required=True, help="path of the built `monotrack` CLI")
    ap.add_argument("--quick", action="store_true",
                    help="the gradient detector on ground-truth boxes only; prints, writes nothing")
    a = ap.parse_args()
    images, faces = D.load_faces68("val")
    by_image = {}
    for f in faces:
        by_image.setdefault(f["image"], []).append(f["pts"].astype(np.float64))
    tmp = tempfile.mkdtemp()
    gt_manifest = os.path.join(tmp, "val_gt_boxes.jsonl")
    with open(gt_manifest, "w") as fh:
        for f in faces:
            b = [float(v) for v in D.box_of(f["pts"])]
            fh.write(json.dumps({"image": images[f["image"]], "faces": [{"box": b}]}) + "\n")
    det_manifest = os.path.join(tmp, "val_detector.jsonl")
    order = sorted(by_image)
    with open(det_manifest, "w") as fh:
        for i in order:
            fh.write(json.dumps({"image": images[i]}) + "\n")
    metrics = {"machine": f"{platform.processor() or platform.machine()}", "split": "faces68 val",
               "points": "the 27 with a 68-point counterpart", "normaliser": "outer eye corners"}
    if a.quick:
        lines = run(a.monotrack, gt_manifest, "gradient")
        pairs = [(as_points(o["faces"][0]), f["pts"].astype(np.float64)) for o, f in zip(lines, faces)]
        print(json.dumps(summarize(pairs)))
        return
    for mode in ("gradient", "m3"):
        lines = run(a.monotrack, gt_manifest, mode)
        pairs = [(as_points(o["faces"][0]), f["pts"].astype(np.float64)) for o, f in zip(lines, faces)]
        us = [o["timings_us"]["landmarks"] for o in lines]
        fits = [o["timings_us"]["fit"] for o in lines]
        m = {"ground_truth_boxes": summarize(pairs), "landmarks_us_median": float(np.median(us)),
             "fit_us_median": float(np.median(fits))}
        if mode == "m3":
            m["ground_truth_boxes"]["all68"] = float(np.mean([nme(p, g, list(range(68))) for p, g in pairs]))
        lines = run(a.monotrack, det_manifest, mode)
        pairs, missed, _ = matched(lines, [by_image[i] for i in order])
        m["detector_boxes"] = summarize(pairs)
        m["detector_boxes"]["missed"] = missed
        metrics[mode] = m
    out = os.path.join(D.REPO, "core", "models", "gradient_metrics.json")
    with open(out, "w") as fh:
        json.dump(metrics, fh, indent=1)
    print(f"{'':10s} {'boxes':9s} {'faces':>5s} {'all27':>6s} " + " ".join(f"{k:>7s}" for k in PARTS))
    for mode in ("gradient", "m3"):
        for kind in ("ground_truth_boxes", "detector_boxes"):
            s = metrics[mode][kind]
            print(f"{mode:10s} {kind[:9]:9s} {s['faces']:5d} {100 * s['counterparts']:6.2f} "
                  + " ".join(f"{100 * s[k]:7.2f}" for k in PARTS))
        print(f"{mode:10s} landmarks {metrics[mode]['landmarks_us_median']:.0f} us/face (median), "
              f"fit {metrics[mode]['fit_us_median']:.0f} us")
    print("wrote", out)


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""Gaze error of the shipped SDK against an iris teacher, on the faces68 validation split.

    python3 core/models/train/eval_gaze.py --monotrack target/release/monotrack

- Faces: the validation split (M3_IO.md: line i % 10 == 0) where the MediaPipe teacher found the
  face, with the jittered landmark boxes of eval_m3.py.
- Teacher (not the one M3's eye net was trained on, which is the blendshape one): an eyeball
  model on MediaPipe's 478 points. Per eye, the eyeball centre lies behind the midpoint of the
  eye corners (33/133, 362/263) by 0.3 x the corner distance (about 9 mm for a 30 mm eye: the
  canthi sit a few mm in front of a 12 mm eyeball's centre), along the head's backward axis (the
  teacher's head rotation); the gaze is the unit vector from there to the iris centre (468, 473),
  in MediaPipe's (x, y px; z in about the same scale, away from the camera) frame = the SDK's
  camera axes; centred by its mean eye-in-head angles on the training split (teacher_offset). An approximation: the error of an eyeball model and of MediaPipe's iris points is
  in the figure.
- Ours: `monotrack landmarks` per eye and combined, in single-pass mode (the video tracker's) and
  in mirror-average mode (the stills default).
- Baselines on the same faces: the head's facing direction as the gaze (eyes assumed straight
  ahead), and the blendshape teacher M3 learnt from (how far the two teachers disagree).
- Per |yaw| bin, and split by the SDK's gaze confidence (core::gaze: eye agreement x head yaw x
  eye openness).
Writes core/models/m3/gaze_metrics.json and prints a table.

With --fit-correction it also fits the thesis' head-proportional correction (eq. 6.4: each eye's
eye-in-head yaw / pitch plus a gain times the head's yaw / pitch, minus a reference) and the
dominant-eye weight on the training split against the same teacher, and reports the validation
error with them: the evidence for core::gaze's defaults (no correction, equal weights).
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import m3data as D  # noqa: E402
from eval_m3 import jittered_boxes  # noqa: E402

CENTRE_DEPTH = 0.3  # eyeball centre behind the corners' midpoint, in corner distances
EYES = {"right": (33, 133, 468), "left": (362, 263, 473)}  # the subject's eyes
YAW_BINS = [(0, 15), (15, 30), (30, 45), (45, 90)]
MAX_YAW_DEG = 60.0  # core::gaze::GazeConfig::default().max_yaw_deg
CLOSED_EYE, OPEN_EYE = 0.10, 0.18  # its closed_eye_ratio, open_eye_ratio


def unit(v):
    v = np.asarray(v, np.float64)
    return v / np.linalg.norm(v)


def angle_deg(a, b):
    return float(np.degrees(np.arccos(np.clip(np.dot(unit(a), unit(b)), -1.0, 1.0))))


def eye_in_head(v):
    """(yaw, pitch) radians of a head-frame direction, 0 straight ahead (-z)."""
    return np.array([np.arctan2(v[0], -v[2]), np.arctan2(v[1], np.hypot(v[0], v[2]))])


def from_eye_in_head(a):
    return np.array([np.cos(a[1]) * np.sin(a[0]), np.sin(a[1]), -np.cos(a[1]) * np.cos(a[0])])


def iris_teacher(t, offset=(0.0, 0.0)):
    """(right, left, combined) unit gaze vectors from the eyeball model, camera axes; `offset`
    (yaw, pitch radians, head frame) is subtracted from each eye's eye-in-head angles."""
    L = np.asarray(t["landmarks478"], np.float64)
    R = D.rot_from_euler(t["yaw_deg"], t["pitch_deg"], t["roll_deg"])
    back = R @ np.array([0.0, 0.0, 1.0])  # into the head
    out = {}
    for side, (a, b, iris) in EYES.items():
        mid = 0.5 * (L[a] + L[b])
        width = np.linalg.norm(L[a][:2] - L[b][:2])
        centre = mid + back * CENTRE_DEPTH * width
        g = unit(L[iris] - centre)
        out[side] = R @ from_eye_in_head(eye_in_head(R.T @ g) - np.asarray(offset))
    out["combined"] = unit(out["right"] + out["left"])
    return out


def teacher_offset(teacher):
    """The eyeball model's mean eye-in-head (yaw, pitch) over the training split: the corners'
    midpoint is not level with the iris of an eye looking straight ahead (the model alone reads
    every eye as looking about 10 degrees up), so the teacher is centred on training faces."""
    _, faces = D.load_faces68("train")
    seen, angles = {}, []
    for f in faces:
        fi = seen.get(f["line"], 0)
        seen[f["line"]] = fi + 1
        t = teacher.get((f["path"], fi))
        if t is None:
            continue
        R = D.rot_from_euler(t["yaw_deg"], t["pitch_deg"], t["roll_deg"])
        g = iris_teacher(t)
        for side in ("right", "left"):
            angles.append(eye_in_head(R.T @ g[side]))
    return np.mean(angles, axis=0)


def eye_openness(points):
    """core::gaze::eye_openness: the less open eye's aspect ratio in the 68 landmarks."""
    p = np.asarray(points, np.float64)

    def ratio(e):
        width = np.linalg.norm(p[e] - p[e + 3])
        lids = np.linalg.norm(p[e + 1] - p[e + 5]) + np.linalg.norm(p[e + 2] - p[e + 4])
        return lids / (2.0 * width) if width > 0 else 0.0

    return min(ratio(36), ratio(42))


def confidence(right, left, yaw, points):
    """core::gaze::point_of_gaze's confidence."""
    agree = np.clip((np.dot(unit(right), unit(left)) - 0.9) / 0.1, 0.0, 1.0)
    turn = np.clip(1.0 - abs(yaw) / MAX_YAW_DEG, 0.0, 1.0)
    openness = np.clip((eye_openness(points) - CLOSED_EYE) / (OPEN_EYE - CLOSED_EYE), 0.0, 1.0)
    return float(agree * turn * openness)


def summary(errs):
    e = np.asarray(errs)
    if len(e) == 0:
        return {"n": 0}
    return {"n": int(len(e)), "mean_deg": round(float(e.mean()), 2),
            "median_deg": round(float(np.median(e)), 2), "p90_deg": round(float(np.percentile(e, 90)), 2)}


def run_split(monotrack, teacher, split, tmp):
    """(fitted rotation, yaw, pitch, right gaze, left gaze, teacher row) per face of `split`."""
    paths, faces = D.load_faces68(split)
    boxes = jittered_boxes(faces)
    rows, seen = [], {}
    for f, b in zip(faces, boxes):
        fi = seen.get(f["line"], 0)
        seen[f["line"]] = fi + 1
        t = teacher.get((f["path"], fi))
        if t is not None:
            rows.append((paths[f["image"]], b, t))
    man = os.path.join(tmp, f"fit_{split}.jsonl")
    with open(man, "w") as fh:
        for p, b, _ in rows:
            fh.write(json.dumps({"image": p, "faces": [{"box": [float(v) for v in b]}]}) + "\n")
    subprocess.run([monotrack, "landmarks", man, "--out", man + ".out", "--single-pass"], check=True)
    out = []
    for (_, _, t), line in zip(rows, open(man + ".out")):
        faces_out = json.loads(line).get("faces")
        if faces_out:
            o = faces_out[0]
            R = np.array(o["pose"]["rotation"], np.float64).reshape(3, 3)
            out.append((R, o["pose"]["yaw_deg"], o["pose"]["pitch_deg"], np.array(o["gaze"]["right"]),
                        np.array(o["gaze"]["left"]), t))
    return out


def corrected_error(data, offset, gain, icpt, wmax):
    """Mean / median combined error with the correction and dominant-eye weight applied."""
    errs = []
    for R, yaw, pitch, gr, gl, t in data:
        want = iris_teacher(t, offset)["combined"]
        eyes = []
        for g in (gr, gl):
            m = np.degrees(eye_in_head(R.T @ unit(g)))
            c = m + np.array([gain[0] * yaw + icpt[0], gain[1] * pitch + icpt[1]])
            eyes.append(R @ from_eye_in_head(np.radians(c)))
        left_near = (R @ np.array([1.0, 0.0, 0.0]))[2] < 0
        w = 0.5 + min(abs(yaw) / MAX_YAW_DEG, 1.0) * (wmax - 0.5)
        wr, wl = (1 - w, w) if left_near else (w, 1 - w)
        errs.append(angle_deg(wr * eyes[0] + wl * eyes[1], want))
    e = np.asarray(errs)
    return [round(float(e.mean()), 2), round(float(np.median(e)), 2)]


def fit_correction(monotrack, teacher, offset):
    tmp = tempfile.mkdtemp()
    train, val = run_split(monotrack, teacher, "train", tmp), run_split(monotrack, teacher, "val", tmp)
    X, Y = [], []
    for R, yaw, pitch, gr, gl, t in train:
        want = iris_teacher(t, offset)
        for g, w in ((gr, want["right"]), (gl, want["left"])):
            X.append([yaw, pitch])
            Y.append(np.degrees(eye_in_head(R.T @ w)) - np.degrees(eye_in_head(R.T @ unit(g))))
    X, Y = np.asarray(X), np.asarray(Y)
    gain, icpt = [], []
    for k in range(2):
        sol, *_ = np.linalg.lstsq(np.c_[X[:, k], np.ones(len(X))], Y[:, k], rcond=None)
        gain.append(float(sol[0]))
        icpt.append(float(sol[1]))
    res = {"train_faces": len(train), "gain_yaw_pitch": [round(v, 3) for v in gain],
           "intercept_deg": [round(v, 2) for v in icpt],
           "val_none": corrected_error(val, offset, [0, 0], [0, 0], 0.5)}
    for wmax in (0.5, 0.7, 0.9, 1.0):
        res[f"val_fitted_dominant_{wmax}"] = corrected_error(val, offset, gain, icpt, wmax)
    print("head correction (eq. 6.4) fitted on the training split:", json.dumps(res))
    return res


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--monotrack", required=True, help="the built `monotrack` CLI")
    ap.add_argument("--fit-correction", action="store_true")
    ap.add_argument("--out", default=os.path.join(D.REPO, "core", "models", "m3", "gaze_metrics.json"))
    a = ap.parse_args()
    teacher = {}
    for line in open(os.path.join(D.DATA, "faces68", "teacher_mediapipe.jsonl")):
        t = json.loads(line)
        if t.get("found"):
            teacher[(t["image"], t["face_index"])] = t
    offset = teacher_offset(teacher)
    paths, faces = D.load_faces68("val")
    boxes = jittered_boxes(faces)
    rows = []
    seen = {}
    for f, b in zip(faces, boxes):
        # load_faces68 lists an image's faces in order: this one's index among them.
        fi = seen.get(f["line"], 0)
        seen[f["line"]] = fi + 1
        t = teacher.get((f["path"], fi))
        if t is not None:
            rows.append((f, b, t))
    tmp = tempfile.mkdtemp()
    manifest = os.path.join(tmp, "gaze_val.jsonl")
    with open(manifest, "w") as fh:
        for f, b, _ in rows:
            fh.write(json.dumps({"image": paths[f["image"]], "faces": [{"box": [float(v) for v in b]}]}) + "\n")
    metrics = {"faces": len(rows), "teacher": "MediaPipe iris points + eyeball model (eval_gaze.py)",
               "centre_depth": CENTRE_DEPTH,
               "teacher_offset_deg": [round(float(v), 2) for v in np.degrees(offset)]}
    for mode, extra in (("single_pass", ["--single-pass"]), ("mirror_average", [])):
        out = os.path.join(tmp, f"ours_{mode}.jsonl")
        subprocess.run([a.monotrack, "landmarks", manifest, "--out", out] + extra, check=True)
        per = {k: [] for k in ("right", "left", "combined", "head", "blendshape_teacher")}
        bins = {f"{lo}-{hi}": [] for lo, hi in YAW_BINS}
        by_conf = {"confidence >= 0.5": [], "confidence < 0.5": []}
        for (f, _, t), line in zip(rows, open(out)):
            o = json.loads(line)["faces"][0]
            want = iris_teacher(t, offset)
            g = o["gaze"]
            for k in ("right", "left", "combined"):
                per[k].append(angle_deg(g[k], want[k]))
            R = np.array(o["pose"]["rotation"], np.float64).reshape(3, 3)
            per["head"].append(angle_deg(R @ np.array([0.0, 0.0, -1.0]), want["combined"]))
            bs = D.gaze_from_teacher(t)
            per["blendshape_teacher"].append(angle_deg(unit(bs[0] + bs[1]), want["combined"]))
            yaw = abs(t["yaw_deg"])
            for lo, hi in YAW_BINS:
                if lo <= yaw < hi:
                    bins[f"{lo}-{hi}"].append(per["combined"][-1])
            c = confidence(g["right"], g["left"], o["pose"]["yaw_deg"], o["landmarks68"])
            by_conf["confidence >= 0.5" if c >= 0.5 else "confidence < 0.5"].append(per["combined"][-1])
        metrics[mode] = {
            "per_eye_and_combined": {k: summary(v) for k, v in per.items()},
            "combined_by_abs_yaw_deg": {k: summary(v) for k, v in bins.items()},
            "combined_by_confidence": {k: summary(v) for k, v in by_conf.items()},
        }
    if a.fit_correction:
        metrics["head_correction_fit"] = fit_correction(a.monotrack, teacher, offset)
    with open(a.out, "w") as fh:
        json.dump(metrics, fh, indent=1)
    print(f"{len(rows)} validation faces with the teacher; angles to the iris teacher, degrees "
          "(mean / median / p90)")
    for mode in ("single_pass", "mirror_average"):
        print(f"  {mode}:")
        for k, s in metrics[mode]["per_eye_and_combined"].items():
            print(f"    {k:20s} {s['mean_deg']:6.2f} {s['median_deg']:6.2f} {s['p90_deg']:6.2f}")
        for k, s in metrics[mode]["combined_by_abs_yaw_deg"].items():
            if s["n"]:
                print(f"    |yaw| {k:14s} {s['mean_deg']:6.2f} {s['median_deg']:6.2f} {s['p90_deg']:6.2f}  n={s['n']}")
        for k, s in metrics[mode]["combined_by_confidence"].items():
            if s["n"]:
                print(f"    {k:20s} {s['mean_deg']:6.2f} {s['median_deg']:6.2f} {s['p90_deg']:6.2f}  n={s['n']}")


if __name__ == "__main__":
    main()

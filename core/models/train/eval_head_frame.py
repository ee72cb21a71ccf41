#!/usr/bin/env python3
"""Head-pose bias of the shipped SDK against the MediaPipe teacher, and the head frame's constant.

    python3 core/models/train/eval_head_frame.py --monotrack target/release/monotrack

- Faces: the faces68 splits of m3data.load_faces68 (validation = line i % 10 == 0, M3_IO.md) where
  the MediaPipe Face Landmarker found the face; boxes = the landmark boxes with eval_m3.py's seeded
  jitter (a detector's or tracker's box).
- Teacher: its `yaw_deg` / `pitch_deg` / `roll_deg` (teacher_mediapipe.jsonl, already in the
  CONTRACT's camera convention): 0 is a face looking straight into the camera, upright.
- Ours: the reported angles (`pose.yaw_deg` ...: core::fit::Pose::euler_deg, the head frame) of
  `monotrack landmarks` in single-pass mode (the video tracker's and the mobile SDK's) and in
  mirror-average mode (the CLI's stills default), and of `monotrack fit` (MSBP) on the annotated
  68 points (the face model alone, without the landmark nets' errors).
- Per split, mode and angle: the signed mean, SD and median of ours - teacher (degrees, wrapped to
  +-180), and the same on the near-frontal faces (teacher |yaw| < 20); the pitch also without the
  constant below (the model frame's: the bias before the head frame).
- The constant: core::fit::pose::HEAD_FRAME_PITCH_DEG enters the reported pitch additively (the
  head frame is the model frame turned by Rx(constant)), so the value that zeroes the training
  split's mean pitch difference is (the constant the binary was built with) - (that mean), taken
  from the single-pass run. Yaw and roll keep no constant unless their training bias is real.
Writes core/models/face_model/head_frame_metrics.json and prints a table.
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

ANGLES = ("yaw", "pitch", "roll")
FRONTAL_YAW_DEG = 20.0
POSE_RS = os.path.join(D.REPO, "core", "src", "fit", "pose.rs")


def built_constant():
    """HEAD_FRAME_PITCH_DEG as the source holds it (the binary must be built from this source)."""
    m = re.search(r"pub const HEAD_FRAME_PITCH_DEG: f64 = ([-0-9.eE]+);", open(POSE_RS).read())
    return float(m.group(1))


def teacher_rows(split):
    """(manifest path, box, landmarks, width, height, teacher) per face of `split` the teacher found."""
    sizes = [(r["width"], r["height"]) for r in map(json.loads, open(os.path.join(D.DATA, "faces68", "train.jsonl")))]
    teacher = {}
    for line in open(os.path.join(D.DATA, "faces68", "teacher_mediapipe.jsonl")):
        t = json.loads(line)
        if t.get("found"):
            teacher[(t["image"], t["face_index"])] = t
    paths, faces = D.load_faces68(split)
    rows, seen = [], {}
    for f, b in zip(faces, jittered_boxes(faces)):
        # load_faces68 lists an image's faces in order: this one's index among them.
        fi = seen.get(f["line"], 0)
        seen[f["line"]] = fi + 1
        t = teacher.get((f["path"], fi))
        if t is not None:
            rows.append((paths[f["image"]], b, f["pts"], *sizes[f["line"]], t))
    return rows


def run_cli(monotrack, rows, tmp, name, mode):
    """The first FACE's (yaw, pitch, roll) per row, or None where no face came back."""
    man = os.path.join(tmp, f"{name}_{mode}.jsonl")
    with open(man, "w") as fh:
        for path, box, pts, w, h, _ in rows:
            if mode == "fit_annotations":
                line = {"width": w, "height": h, "faces": [{"landmarks68": pts.astype(float).tolist()}]}
            else:
                line = {"image": path, "faces": [{"box": [float(v) for v in box]}]}
            fh.write(json.dumps(line) + "\n")
    cmd = {"single_pass": ["landmarks", man, "--single-pass"], "mirror_average": ["landmarks", man],
           "fit_annotations": ["fit", man]}[mode]
    subprocess.run([monotrack] + cmd + ["--out", man + ".out"], check=True)
    out = []
    for line in open(man + ".out"):
        faces = json.loads(line).get("faces")
        out.append([faces[0]["pose"][f"{a}_deg"] for a in ANGLES] if faces else None)
    return out


def wrap(d):
    return (np.asarray(d) + 180.0) % 360.0 - 180.0


def stats(d):
    d = np.asarray(d)
    if len(d) == 0:
        return {"n": 0}
    return {"n": int(len(d)), "mean_deg": round(float(d.mean()), 3), "sd_deg": round(float(d.std(ddof=1)), 3),
            "median_deg": round(float(np.median(d)), 3), "mean_abs_deg": round(float(np.abs(d).mean()), 3),
            "sem_deg": round(float(d.std(ddof=1) / np.sqrt(len(d))), 3)}


def differences(rows, ours, const):
    """Per angle: ours - teacher over all faces and over the near-frontal ones; and the model
    frame's pitch difference (without the head frame's constant) over all faces."""
    d = {a: [] for a in ANGLES}
    frontal = {a: [] for a in ANGLES}
    for (*_, t), o in zip(rows, ours):
        if o is None:
            continue
        for k, a in enumerate(ANGLES):
            v = float(wrap(o[k] - t[f"{a}_deg"]))
            d[a].append(v)
            if abs(t["yaw_deg"]) < FRONTAL_YAW_DEG:
                frontal[a].append(v)
    return {"all": {a: stats(v) for a, v in d.items()},
            "model_frame_pitch": stats(np.asarray(d["pitch"]) - const),
            f"teacher_abs_yaw_below_{int(FRONTAL_YAW_DEG)}": {a: stats(v) for a, v in frontal.items()}}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--monotrack", required=True, help="the built `monotrack` CLI")
    ap.add_argument("--out", default=os.path.join(D.REPO, "core", "models", "face_model", "head_frame_metrics.json"))
    a = ap.parse_args()
    const = built_constant()
    tmp = tempfile.mkdtemp()
    metrics = {"teacher": "MediaPipe Face Landmarker yaw/pitch/roll (faces68/teacher_mediapipe.jsonl)",
               "difference": "ours - teacher, degrees", "built_with_head_frame_pitch_deg": const}
    for split in ("train", "val"):
        rows = teacher_rows(split)
        metrics[split] = {"faces": len(rows)}
        for mode in ("single_pass", "mirror_average", "fit_annotations"):
            metrics[split][mode] = differences(rows, run_cli(a.monotrack, rows, tmp, split, mode), const)
    bias = metrics["train"]["single_pass"]["all"]["pitch"]["mean_deg"]
    metrics["fitted_head_frame_pitch_deg"] = round(const - bias, 2)
    with open(a.out, "w") as fh:
        json.dump(metrics, fh, indent=1)
    print(f"built with HEAD_FRAME_PITCH_DEG = {const}; ours - teacher, degrees: mean (SD) n")
    for split in ("train", "val"):
        for mode in ("single_pass", "mirror_average", "fit_annotations"):
            s = metrics[split][mode]["all"]
            cells = "  ".join(f"{x} {s[x]['mean_deg']:+6.2f} ({s[x]['sd_deg']:5.2f})" for x in ANGLES)
            print(f"  {split:5s} {mode:16s} {cells}  n={s['pitch']['n']}")
    print(f"HEAD_FRAME_PITCH_DEG that zeroes the training split's single-pass mean pitch difference: "
          f"{metrics['fitted_head_frame_pitch_deg']}")


if __name__ == "__main__":
    main()

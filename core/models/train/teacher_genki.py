#!/usr/bin/env python3
"""Teacher gestures for GENKI-4K faces: the MediaPipe Face Landmarker (../shared/data/teachers, a
teacher only, never shipped) reads the 52 blendshapes of every GENKI-4K crop, labelled the way
faces68's are (m3data.gestures_from_teacher, the same thresholds). The held-out crops (file number
% 5 == 0) give eval_m3.py a second gesture validation set with enough examples of every class
(faces68's validation faces hold no mouth frown); the training split's crops can train the mouth
and brow nets' gesture heads (train_m3.py --genki-gesture-nets, off by default: RESEARCH_LOG.md).

usage: python3 core/models/train/teacher_genki.py [OUT.jsonl]
  (default $XDG_CACHE_HOME or ~/.cache /monotrack/genki_mediapipe.jsonl)
  Needs `pip install mediapipe==0.10.14` (newer wheels lack the blendshape model's ops); a separate
  virtual environment keeps its numpy and protobuf pins away from the training packages.

Each 64x64 crop is padded by 16 px (border replicated: the detector wants some context around the
face) and upscaled 4x (bicubic) before the teacher runs; it finds the face in about 94 % of the
crops. Output lines: {"image": absolute path, "file": name, "split": "train" | "test", "found":
bool, and when found "blendshapes": {name: score}, "yaw_deg"}.
"""
import json
import os
import sys

import cv2
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import m3data as D  # noqa: E402

TASK = os.path.join(D.DATA, "teachers", "mediapipe_face_landmarker", "face_landmarker.task")
PAD = 16
SCALE = 4


def default_path():
    cache = os.environ.get("XDG_CACHE_HOME", os.path.join(os.path.expanduser("~"), ".cache"))
    return os.path.join(cache, "monotrack", "genki_mediapipe.jsonl")


def load(path, split):
    """{file name: (mouth class, brow class)} of the crops of `split` the teacher found."""
    out = {}
    for line in open(path):
        r = json.loads(line)
        if r["split"] == split and r["found"]:
            out[r["file"]] = D.gestures_from_teacher(r)
    return out


def main(out=None):
    import mediapipe as mp
    from mediapipe.tasks import python as mpt
    from mediapipe.tasks.python import vision

    out = out or default_path()
    os.makedirs(os.path.dirname(out), exist_ok=True)
    opts = vision.FaceLandmarkerOptions(
        base_options=mpt.BaseOptions(model_asset_path=TASK), output_face_blendshapes=True,
        output_facial_transformation_matrixes=True, num_faces=1)
    teacher = vision.FaceLandmarker.create_from_options(opts)
    n = found = 0
    with open(out, "w") as fh:
        for split in ("train", "test"):
            for path, _, name in D.genki_files(split):
                img = cv2.imread(path)
                img = cv2.copyMakeBorder(img, PAD, PAD, PAD, PAD, cv2.BORDER_REPLICATE)
                img = cv2.resize(img, None, fx=SCALE, fy=SCALE, interpolation=cv2.INTER_CUBIC)
                rgb = np.ascontiguousarray(cv2.cvtColor(img, cv2.COLOR_BGR2RGB))
                r = teacher.detect(mp.Image(image_format=mp.ImageFormat.SRGB, data=rgb))
                rec = {"image": os.path.abspath(path), "file": name, "split": split,
                       "found": bool(r.face_blendshapes)}
                if rec["found"]:
                    rec["blendshapes"] = {c.category_name: round(float(c.score), 4) for c in r.face_blendshapes[0]}
                    m = np.array(r.facial_transformation_matrixes[0])[:3, :3]
                    # yaw about the camera's vertical axis, as teacher_mediapipe.jsonl's yaw_deg
                    rec["yaw_deg"] = round(float(np.degrees(np.arctan2(-m[2, 0], np.hypot(m[0, 0], m[1, 0])))), 2)
                    found += 1
                n += 1
                fh.write(json.dumps(rec) + "\n")
    print(f"{found} of {n} GENKI-4K crops read by the MediaPipe teacher -> {out}")
    return out


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else None)

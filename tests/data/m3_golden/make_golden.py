"""Golden end-to-end cases for M3 (`core::landmarks::M3` with the embedded models of core/models/m3).

Run from the repository root after (re)training: `python3 tests/data/m3_golden/make_golden.py`
(numpy, opencv-python, onnxruntime). Writes the inputs and `expected.json` next to this file.

Inputs (project-made, committed): gray PNGs cut from samples/data/astronaut.jpg (public domain),
luma by the M3_IO.md formula, so no JPEG decoder enters the comparison:
- `astronaut.png`: a 256x256 crop around the face, box = the face's tight 68-point box (by eye);
- `astronaut_rot.png`: the same crop rotated by 18 degrees and scaled by 0.75 (box transformed);
- `astronaut_mirror.png`: the crop mirrored left-right (swaps the eye paths).
Each case also runs with a box shifted by 8 % of its side (tracker-like), and every case in both
modes of M3_IO.md (default and mirror-average; `"mirror_average"` says which).

Expected values: the Python reference inference `core/models/train/m3_reference.py` (onnxruntime +
the OpenCV preprocessing the training uses), i.e. an independent implementation of
core/models/M3_IO.md. Tolerances used by tests/tests/m3_golden.rs (Rust = tract + our own
preprocessing, which differs from OpenCV by +-1 level on < 1 % of the patch pixels):
points 0.5 px (boxes are 90-110 px, so 0.5 % of the face), probabilities 0.02, gaze components 0.02.
"""
import hashlib
import json
import os
import sys

import cv2
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.abspath(os.path.join(HERE, "..", "..", ".."))
sys.path.insert(0, os.environ.get("M3_TRAIN_DIR", os.path.join(REPO, "core", "models", "train")))
import m3_reference  # noqa: E402

MODELS = os.environ.get("M3_MODEL_DIR", os.path.join(REPO, "core", "models", "m3"))
CROP = (110, 20)  # top-left of the 256x256 crop in astronaut.jpg
FACE_BOX = [172.0, 90.0, 104.0, 94.0]  # in astronaut.jpg


def luma(bgr):
    rgb = bgr[..., ::-1].astype(np.float64)
    y = 0.299 * rgb[..., 0] + 0.587 * rgb[..., 1] + 0.114 * rgb[..., 2]
    return np.floor(y + 0.5).clip(0, 255).astype(np.uint8)


def box_after(A, box):
    x, y, w, h = box
    c = np.array([[x, y], [x + w, y], [x, y + h], [x + w, y + h]], float)
    p = c @ A[:, :2].T + A[:, 2]
    lo, hi = p.min(0), p.max(0)
    # a detector-like box: the transformed box's centre, side preserved by the scale
    k = np.sqrt(abs(np.linalg.det(A[:, :2])))
    cx, cy = (lo + hi) / 2
    return [float(cx - k * w / 2), float(cy - k * h / 2), float(k * w), float(k * h)]


def main():
    gray = luma(cv2.imread(os.path.join(REPO, "samples", "data", "astronaut.jpg"), cv2.IMREAD_COLOR))
    x0, y0 = CROP
    crop = np.ascontiguousarray(gray[y0:y0 + 256, x0:x0 + 256])
    box = [FACE_BOX[0] - x0, FACE_BOX[1] - y0, FACE_BOX[2], FACE_BOX[3]]
    R = cv2.getRotationMatrix2D((128.0, 128.0), 18.0, 0.75)
    rot = cv2.warpAffine(crop, R, (256, 256), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    mirror = np.ascontiguousarray(crop[:, ::-1])
    images = {
        "astronaut.png": (crop, box),
        "astronaut_rot.png": (rot, box_after(R, box)),
        "astronaut_mirror.png": (mirror, [256 - box[0] - box[2], box[1], box[2], box[3]]),
    }
    modes = [(False, m3_reference.M3(MODELS)), (True, m3_reference.M3(MODELS, mirror_average=True))]
    cases = []
    for name, (img, b) in images.items():
        cv2.imwrite(os.path.join(HERE, name), img)
        for shift, (mirror_average, m3) in ((s, m) for s in (0.0, 0.08) for m in modes):
            bb = [b[0] + shift * b[2], b[1] - shift * b[3], b[2], b[3]]
            r = m3.run(img, bb)
            cases.append({
                "image": name, "box": [round(v, 3) for v in bb], "mirror_average": mirror_average,
                "landmarks68": np.round(r["landmarks68"], 4).tolist(),
                "yaw_probs": np.round(r["yaw_probs"], 6).tolist(),
                "face_prob": round(float(r["face_prob"]), 6),
                "mouth": [round(float(r["mouth"][k]), 6) for k in ("smile", "frown", "kiss", "neutral")],
                "brows": [round(float(r["brows"][k]), 6) for k in ("raise", "frown", "neutral")],
                "gaze": {k: np.round(v, 6).tolist() for k, v in r["gaze"].items()},
            })
    sha = {f: hashlib.sha256(open(os.path.join(MODELS, f), "rb").read()).hexdigest()
           for f in sorted(os.listdir(MODELS)) if f.endswith((".onnx", ".json", ".bin"))}
    json.dump({"model_sha256": sha, "cases": cases},
              open(os.path.join(HERE, "expected.json"), "w"), indent=0)
    print(f"{len(cases)} cases written")


if __name__ == "__main__":
    main()

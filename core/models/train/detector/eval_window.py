#!/usr/bin/env python3
"""Validates a tracked window the two ways core offers, on the faces68 validation split: the
detector's `FaceDetector::score_window` (64x64 patch with the face side at 36 px, the stride-16
head's best logit over the 2x2 centre cells; emulated here with OpenCV sampling and onnxruntime) and
M3 level 1's face probability (`m3_reference.py`), on the same windows.

usage: python3 core/models/train/detector/eval_window.py
Face windows: the validation faces' landmark boxes with eval_m3.py's seeded jitter. Non-face
windows: per face 6 boxes shifted by 0.5-1 side and 6 background boxes of the face's size (seed 3),
kept when their IoU with every annotated face of the image is < 0.3.
"""
import os, sys
import numpy as np
import cv2
HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))
sys.path.insert(0, HERE)
import eval_m3 as E, m3data as D, m3_reference as R, onnxruntime as ort  # noqa: E402
from unlabeled import iou  # noqa: E402
MODELS = os.path.join(HERE, "..", "..")
paths, faces = D.load_faces68("val")
boxes = E.jittered_boxes(faces)
so = ort.SessionOptions(); so.intra_op_num_threads = 1
det = ort.InferenceSession(os.path.join(MODELS, 'detector', 'detector.onnx'), so)
l1 = R.Level1Runner(os.path.join(MODELS, 'm3', 'level1.onnx'))
rng = np.random.default_rng(3)
def win(gray, b):
    side = max(b[2], b[3]); cx, cy = b[0] + b[2] / 2, b[1] + b[3] / 2
    r = side / 36.0
    A = np.array([[r, 0, cx - 32 * r], [0, r, cy - 32 * r]], np.float32)
    ksz = max(1, int(round(r)))
    src = cv2.blur(gray, (ksz, ksz)) if r > 1.5 else gray
    p = cv2.warpAffine(src, A, (64, 64), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP, borderMode=cv2.BORDER_REPLICATE)
    o = det.run(None, {"image": (p / 255.0).astype(np.float32)[None, None]})[1][0, 0]
    return 1 / (1 + np.exp(-o[1:3, 1:3].max()))
pos, neg = [], []
byimg = {}
for f in faces: byimg.setdefault(f["image"], []).append(D.box_of(f["pts"]))
for f, b in zip(faces, boxes):
    g = D.load_gray(paths[f["image"]]).astype(np.uint8)
    gf = g.astype(np.float32)
    pos.append((win(g, b), l1.run(gf, np.array(b, np.float32))[2]))
    s = max(b[2], b[3]); H, W = g.shape
    cands = []
    for _ in range(6):  # shifted windows
        a = rng.uniform(0, 2 * np.pi); d = rng.uniform(0.5, 1.0) * s
        cands.append([b[0] + d * np.cos(a), b[1] + d * np.sin(a), b[2], b[3]])
    for _ in range(6):  # background windows of the face's size
        x, y = rng.uniform(0, max(1, W - s)), rng.uniform(0, max(1, H - s))
        cands.append([x, y, s, s])
    for c in cands:
        if all(iou(c, t) < 0.3 for t in byimg[f["image"]]):
            neg.append((win(g, c), l1.run(gf, np.array(c, np.float32))[2]))
pos, neg = np.array(pos), np.array(neg)
print(f"{len(pos)} face windows, {len(neg)} non-face windows (shifted 0.5-1 side or background, IoU < 0.3)")
for k, name in ((0, "detector score_window"), (1, "M3 level-1 face prob")):
    p, n = pos[:, k], neg[:, k]
    auc = (p[:, None] > n[None, :]).mean() + 0.5 * (p[:, None] == n[None, :]).mean()
    rows = []
    for t in (0.5, 0.8, 0.9, 0.95):
        rows.append(f"t {t}: TPR {(p >= t).mean():.3f} FPR {(n >= t).mean():.3f}")
    for fpr in (0.01, 0.05):
        t = np.quantile(n, 1 - fpr); rows.append(f"TPR at FPR {fpr}: {(p > t).mean():.3f}")
    print(name, f"AUC {auc:.4f};", "; ".join(rows))

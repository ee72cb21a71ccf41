#!/usr/bin/env python3
"""Level 1's face / not-face output (the tracker's and the CLI's face check) on the faces68
validation split: positives = landmark boxes with tracker-like jitter (centre ±5 %, side ±10 %),
negatives drawn as in training (`m3data.level1_negative`: shifted off the face, far too large, a part
of the face, anywhere in the image), seeded; and the shipped detector's false positives on the
validation images (`m3data.detector_false_positives`: what the face check must reject in the CLI and
the tracker); and rendered caption text (`m3data.text_negative`, seeded; backgrounds from the
validation images; needs pillow and `apt-get install fonts-wqy-microhei`). Prints, per model, the share of positives and of each kind of negative at or above 0.5
(the tracker's `min_face_confidence`) and the ROC AUC against the drawn negatives.

    python3 core/models/train/eval_face_check.py [LEVEL1.onnx ...]   # default: the shipped one
"""
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import m3data as D  # noqa: E402
import m3_reference as R  # noqa: E402

SEED = 5
ROUNDS = 4


def main():
    paths = sys.argv[1:] or [os.path.join(D.REPO, "core", "models", "m3", "level1.onnx")]
    runners = [R.Level1Runner(p) for p in paths]
    img_paths, faces = D.load_faces68("val")
    imgs = [D.load_gray(p) for p in img_paths]
    rng = np.random.default_rng(SEED)
    pos, neg = [[] for _ in runners], [[] for _ in runners]
    for _ in range(ROUNDS):
        for f in faces:
            img = imgs[f["image"]]
            c, s = D.square_of_box(D.box_of(f["pts"]))
            for positive in (True, False):
                cc, ss = c.copy(), s
                if positive:
                    ss *= np.exp(rng.uniform(-0.1, 0.1))
                    cc = cc + rng.uniform(-0.05, 0.05, 2) * s
                else:
                    cc, ss = D.level1_negative(cc, ss, img.shape, rng)
                box = np.array([cc[0] - ss / 2, cc[1] - ss / 2, ss, ss])
                for k, r in enumerate(runners):
                    (pos if positive else neg)[k].append(float(r.run(img, box)[2]))
    fps = D.detector_false_positives(img_paths, faces)
    det = [[float(r.run(imgs[k], box)[2]) for k, box in fps] for r in runners]
    text = [[] for _ in runners]
    for img in imgs:
        for _ in range(ROUNDS):
            canvas, c, s = D.text_negative(img, rng)
            box = np.array([c[0] - s / 2, c[1] - s / 2, s, s])
            for k, r in enumerate(runners):
                text[k].append(float(r.run(canvas, box)[2]))
    for path, p, q, d, x in zip(paths, pos, neg, det, text):
        p, q, d, x = np.array(p), np.array(q), np.array(d), np.array(x)
        auc = (p[:, None] > q[None, :]).mean() + 0.5 * (p[:, None] == q[None, :]).mean()
        print(f"{path}: positives >= 0.5 {np.mean(p >= 0.5):.3f}, negatives >= 0.5 {np.mean(q >= 0.5):.3f},"
              f" AUC {auc:.4f} ({len(p)} / {len(q)}); detector false positives >= 0.5 {np.mean(d >= 0.5):.3f}"
              f" ({len(d)}); caption text >= 0.5 {np.mean(x >= 0.5):.3f} ({len(x)})")
        # Stricter checks, as for accepting a new detection (TrackerConfig::min_detection_confidence).
        for t in (0.8, 0.9, 0.95):
            print(f"  at {t}: positives >= {t} {np.mean(p >= t):.3f}, negatives {np.mean(q >= t):.3f},"
                  f" detector false positives {np.mean(d >= t):.3f}, caption text {np.mean(x >= t):.3f}")


if __name__ == "__main__":
    main()

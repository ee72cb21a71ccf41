#!/usr/bin/env python3
"""Teacher landmarks for the faces faces68's training images show but do not annotate, kept where
two teachers agree; written with the GENKI-4K teacher faces as one file `train_m3.py` can use.

    python3 core/models/train/pseudo_unannotated.py OUT.jsonl [--min-width PX] [--repeat K]
    MONOTRACK_PSEUDO=OUT.jsonl python3 core/models/train/train_m3.py --only face --jobs 1

Why: the face zone overfits its 1,079 annotated faces, and the GENKI-4K teacher faces
(`pseudo_genki.py`) are 64×64 crops; the training images hold more people in the same photographic
style (`detector/unlabeled.py` finds 309 faces in them with the Ultra-Light peer detector, 284 in
training images). Each one at least MIN_WIDTH px wide is labelled by PFLD (three rounds on the box
of its own points, from the peer detector's box narrowed to about a landmark box) and by dlib's
68-point predictor on its own HOG detector's box; the face is kept where the two agree (mean
distance under AGREE of PFLD's outer-eye-corner distance), with PFLD's points, so that neither
teacher's misses (a HOG box on another face, a PFLD crop that slid) become labels. Faces of the
validation images are left out. The output holds the GENKI-4K teacher faces, then the kept faces
`--repeat` times (each is one line of 2,240 otherwise). Peers are teachers only, never shipped.

Measured and not adopted (RESEARCH_LOG.md, "Measured and not adopted").
"""
import argparse
import json
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
sys.path.insert(0, os.path.join(HERE, "detector"))
import m3data as D  # noqa: E402
import pseudo_genki  # noqa: E402
import unlabeled  # noqa: E402

# Teachers' agreement: mean point distance over PFLD's outer-eye-corner distance.
AGREE = 0.08


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("out")
    ap.add_argument("--min-width", type=float, default=48.0)
    ap.add_argument("--repeat", type=int, default=4)
    a = ap.parse_args()
    val = {json.loads(line)["image"] for i, line in enumerate(open(os.path.join(D.DATA, "faces68", "train.jsonl")))
           if i % 10 == 0}
    items = [(os.path.join(D.DATA, "faces68", k), b) for k, boxes in sorted(unlabeled.load().items())
             if k not in val for b in boxes if b[2] >= a.min_width]
    # Ultra-Light's loose box, narrowed and lowered to about the 68 points' box.
    boxes = [[x + w / 2 - 0.4 * max(w, h), y + h / 2 + 0.1 * h - 0.4 * max(w, h), 0.8 * max(w, h), 0.8 * max(w, h)]
             for _, (x, y, w, h) in items]
    images = [p for p, _ in items]
    pts = pseudo_genki.pfld_settled(images, boxes)
    dl = pseudo_genki.peer_points(images, [D.box_of(q).tolist() for q in pts], "dlib", "--dlib-own-detector")
    keep = [(p, q) for (p, _), q, d in zip(items, pts, dl)
            if np.linalg.norm(q - d, axis=1).mean() / np.linalg.norm(q[36] - q[45]) < AGREE]
    genki = pseudo_genki.default_path()
    if not os.path.exists(genki):
        pseudo_genki.main(genki)
    with open(a.out, "w") as fh:
        fh.writelines(open(genki))
        for _ in range(a.repeat):
            for p, q in keep:
                fh.write(json.dumps({"image": p, "faces": [{"pfld": q.round(2).tolist()}]}) + "\n")
    print(f"{len(items)} unannotated faces >= {a.min_width:.0f} px, {len(keep)} where PFLD and dlib agree;"
          f" with the GENKI-4K teacher faces -> {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

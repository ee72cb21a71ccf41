#!/usr/bin/env python3
"""The validation split by source, ours and the peers each in their own setting, and a check for
faces shared across the split: how far the validation figures can stand in for unseen faces.

    python3 core/models/train/eval_sources.py --monotrack target/release/monotrack

- Faces: the faces68 validation split (lines i % 10 == 0: whole images, so no photo is on both
  sides), reported for AFW, HELEN and both.
- Settings, as an unseen-face benchmark reports them:
  - ours from the ground-truth boxes (the tight box of the 68 points), `monotrack landmarks` in its
    default (mirror-average) mode;
  - ours with our own detector (`monotrack landmarks` without boxes; an annotated face is found when
    a reported face's landmark box overlaps its box by IoU ≥ 0.5);
  - PFLD on the ground-truth boxes with its authors' crop (`../shared/tools/peer_landmarks.py`);
  - dlib's 68-point predictor on its own HOG detector's boxes (found: a detection with IoU ≥ 0.3;
    dlib's boxes are smaller than the landmark box).
  NME is over the faces each setting found.
- Shared faces: every validation face against every training face, both as 32×32 crops aligned on
  the outer eye corners and normalised (zero mean, unit norm); a pair with correlation ≥ 0.9 is the
  same photo of the same face, or nearly. faces68 has no identity labels, so this is the check
  that can be made.
Writes core/models/m3/source_metrics.json and prints the table.

    python3 core/models/train/eval_sources.py --shrink

- Resolution: the HELEN part's photos shrunk by area averaging to a half and a third of their
  stored size (landmarks scaled with them), ours (Python reference, mirror average, ground-truth
  boxes), PFLD and dlib as above at each size: whether a method gains from a sharper photo.
  Writes core/models/m3/shrink_metrics.json.
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile

import cv2
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import eval_m3 as E  # noqa: E402
import m3data as D  # noqa: E402

SAME_FACE_NCC = 0.9


def iou(a, b):
    ax, ay, aw, ah = a
    bx, by, bw, bh = b
    ix = max(0.0, min(ax + aw, bx + bw) - max(ax, bx))
    iy = max(0.0, min(ay + ah, by + bh) - max(ay, by))
    inter = ix * iy
    return inter / (aw * ah + bw * bh - inter)


def sources():
    """Source of each faces68 line."""
    return [json.loads(line)["source"] for line in open(os.path.join(D.DATA, "faces68", "train.jsonl"))]


def aligned(gray, pts, n=32):
    """The face's n×n crop with the outer eye corners at fixed places, zero mean and unit norm."""
    A = D.similarity_map(pts[36].astype(float), pts[45].astype(float),
                         np.array([0.3 * n, 0.4 * n]), np.array([0.7 * n, 0.4 * n]))
    p = D.sample(gray, A, n, n).astype(np.float64)
    p -= p.mean()
    return (p / max(np.linalg.norm(p), 1e-9)).ravel()


def shared_faces(val_paths, val_faces):
    tr_paths, tr_faces = D.load_faces68("train")
    grays = {}

    def crop(paths, f):
        p = paths[f["image"]]
        if p not in grays:
            grays[p] = D.load_gray(p)
        return aligned(grays[p], f["pts"])

    T = np.stack([crop(tr_paths, f) for f in tr_faces])
    V = np.stack([crop(val_paths, f) for f in val_faces])
    best = (V @ T.T).max(1)
    return best


def ours(monotrack, paths, faces, by_image):
    tmp = tempfile.mkdtemp()
    gt = os.path.join(tmp, "gt.jsonl")
    with open(gt, "w") as fh:
        for f in faces:
            fh.write(json.dumps({"image": paths[f["image"]], "faces": [{"box": list(map(float, D.box_of(f["pts"])))}]}) + "\n")
    out = gt + ".out"
    subprocess.run([monotrack, "landmarks", gt, "--out", out], check=True)
    gt_errs = [E.nme_parts(np.array(json.loads(line)["faces"][0]["landmarks68"]), f["pts"])["all"]
               for f, line in zip(faces, open(out))]
    det = os.path.join(tmp, "det.jsonl")
    imgs = sorted(by_image)
    with open(det, "w") as fh:
        for i in imgs:
            fh.write(json.dumps({"image": paths[i]}) + "\n")
    out = det + ".out"
    subprocess.run([monotrack, "landmarks", det, "--out", out], check=True)
    det_errs = [None] * len(faces)
    for i, line in zip(imgs, open(out)):
        found = [np.array(o["landmarks68"]) for o in json.loads(line)["faces"]]
        for k in by_image[i]:
            box = D.box_of(faces[k]["pts"])
            cands = [(iou(box, D.box_of(p)), p) for p in found]
            cands = [c for c in cands if c[0] >= 0.5]
            if cands:
                det_errs[k] = E.nme_parts(max(cands, key=lambda c: c[0])[1], faces[k]["pts"])["all"]
    return gt_errs, det_errs


def pfld(paths, faces):
    tool = os.path.join(D.DATA, "..", "tools", "peer_landmarks.py")
    man = os.path.join(tempfile.mkdtemp(), "pfld.jsonl")
    with open(man, "w") as fh:
        for f in faces:
            fh.write(json.dumps({"image": paths[f["image"]], "faces": [{
                "box": list(map(float, D.box_of(f["pts"]))), "landmarks68": f["pts"].tolist()}]}) + "\n")
    subprocess.run([sys.executable, tool, man, "--out", man + ".out", "--peers", "pfld"], check=True,
                   capture_output=True)
    return [E.nme_parts(np.array(json.loads(line)["faces"][0]["pfld"]), f["pts"])["all"]
            for f, line in zip(faces, open(man + ".out"))]


def dlib_own(paths, faces, by_image):
    import dlib
    sp = dlib.shape_predictor("/usr/share/dlib/shape_predictor_68_face_landmarks.dat")
    hog = dlib.get_frontal_face_detector()
    errs = [None] * len(faces)
    for i, ks in by_image.items():
        rgb = cv2.imread(paths[i])[..., ::-1].copy()
        dets = list(hog(rgb, 1))
        for k in ks:
            box = D.box_of(faces[k]["pts"])
            cands = [(iou(box, (d.left(), d.top(), d.width(), d.height())), d) for d in dets]
            cands = [c for c in cands if c[0] >= 0.3]
            if not cands:
                continue
            s = sp(rgb, max(cands, key=lambda c: c[0])[1])
            pts = np.array([[s.part(j).x, s.part(j).y] for j in range(68)], float)
            errs[k] = E.nme_parts(pts, faces[k]["pts"])["all"]
    return errs


def faces_by_image(faces):
    """Image index -> the indices of its faces in `faces`."""
    by_image = {}
    for k, f in enumerate(faces):
        by_image.setdefault(f["image"], []).append(k)
    return by_image


def shrink(scales=(1.0, 0.5, 1 / 3)):
    from m3_reference import M3
    paths, faces = D.load_faces68("val")
    src = sources()
    faces = [f for f in faces if src[f["line"]] == "helen"]
    m3 = M3(os.path.join(D.REPO, "core", "models", "m3"), mirror_average=True)
    iod = np.median([np.linalg.norm(f["pts"][36] - f["pts"][45]) for f in faces])
    metrics = {"faces": len(faces), "median_outer_eye_distance_px": float(iod), "by_scale": {}}
    print(f"HELEN validation faces: {len(faces)}, median outer-eye distance {iod:.0f} px")
    print("| scale | ours, ground-truth boxes | PFLD, its crop | dlib, own HOG detector |")
    print("|---|---|---|---|")
    for s in scales:
        # The peers read files (lossless PNG); ours reads the same pixels through the luma every
        # other evaluation uses (m3data.load_gray).
        tmp = tempfile.mkdtemp()
        spaths, grays = {}, {}
        for i in {f["image"] for f in faces}:
            img = cv2.imread(paths[i])
            if s != 1.0:
                size = (max(1, round(img.shape[1] * s)), max(1, round(img.shape[0] * s)))
                img = cv2.resize(img, size, interpolation=cv2.INTER_AREA)
            spaths[i] = os.path.join(tmp, f"{i}.png")
            cv2.imwrite(spaths[i], img)
            grays[i] = D.luma(img[..., ::-1].astype(np.float32))
        sf = [dict(f, pts=f["pts"] * s) for f in faces]
        ours = [E.nme_parts(m3.run(grays[f["image"]], np.array(D.box_of(f["pts"]), float))["landmarks68"],
                            f["pts"])["all"]
                for f in sf]
        dl = [e for e in dlib_own(spaths, sf, faces_by_image(sf)) if e is not None]
        row = {"ours": float(np.mean(ours)), "pfld": float(np.mean(pfld(spaths, sf))),
               "dlib": float(np.mean(dl)), "dlib_found": len(dl)}
        metrics["by_scale"][f"{s:.3f}"] = row
        print(f"| {s:.2f} | {100 * row['ours']:.2f} % | {100 * row['pfld']:.2f} % | "
              f"{100 * row['dlib']:.2f} % ({len(dl)} found) |")
    path = os.path.join(D.REPO, "core", "models", "m3", "shrink_metrics.json")
    with open(path, "w") as fh:
        json.dump(metrics, fh, indent=1)
    print("wrote", path)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--monotrack")
    ap.add_argument("--shrink", action="store_true", help="the resolution measurement only")
    a = ap.parse_args()
    if a.shrink:
        return shrink()
    if not a.monotrack:
        ap.error("--monotrack is required (or --shrink)")
    paths, faces = D.load_faces68("val")
    src = sources()
    by_image = faces_by_image(faces)
    runs = {}
    runs["ours, ground-truth boxes"], runs["ours, own detector"] = ours(a.monotrack, paths, faces, by_image)
    runs["PFLD, ground-truth boxes, its crop"] = pfld(paths, faces)
    runs["dlib, own HOG detector"] = dlib_own(paths, faces, by_image)
    groups = {"all": list(range(len(faces)))}
    for k, f in enumerate(faces):
        groups.setdefault(src[f["line"]], []).append(k)
    best = shared_faces(paths, faces)
    metrics = {"split": "faces68 val (lines i % 10 == 0)", "faces": {g: len(ks) for g, ks in groups.items()},
               "nme": {}, "found": {},
               "shared_faces": {"threshold_ncc": SAME_FACE_NCC,
                                "val_faces_with_a_training_match": int((best >= SAME_FACE_NCC).sum()),
                                "max_ncc_median": float(np.median(best)),
                                "max_ncc_top5": sorted(map(float, best))[-5:]}}
    for name, errs in runs.items():
        metrics["nme"][name], metrics["found"][name] = {}, {}
        for g, ks in groups.items():
            e = [errs[k] for k in ks if errs[k] is not None]
            metrics["nme"][name][g] = float(np.mean(e)) if e else None
            metrics["found"][name][g] = len(e)
    path = os.path.join(D.REPO, "core", "models", "m3", "source_metrics.json")
    with open(path, "w") as fh:
        json.dump(metrics, fh, indent=1)
    cols = [g for g in ("afw", "helen", "all") if g in groups]
    print("| setting | " + " | ".join(f"{g} ({len(groups[g])} faces)" for g in cols) + " |")
    print("|---|" + "---|" * len(cols))
    for name in runs:
        print(f"| {name} | " + " | ".join(
            f"{100 * metrics['nme'][name][g]:.2f} % ({metrics['found'][name][g]} found)" for g in cols) + " |")
    sf = metrics["shared_faces"]
    print(f"validation faces with a training face at NCC ≥ {SAME_FACE_NCC}: {sf['val_faces_with_a_training_match']}"
          f" (median best {sf['max_ncc_median']:.3f}, top {sf['max_ncc_top5']})")
    print("wrote", path)


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""NME by head-yaw bin and the yaw classes' confusion, for the shipped M3 through `monotrack
landmarks`, with the peers on the same faces and bins (`--peers`).

    python3 core/models/train/eval_yaw.py --monotrack target/release/monotrack [--peers]

- Faces and boxes: as eval_m3.py (faces68 validation split, landmark boxes with its seeded
  detector-like jitter); the CLI in its single-pass mode (the video tracker's) and its default
  mirror-average mode.
- Yaw of each face: the MediaPipe teacher's where it found the face, else the PnP fit of our mean
  face (m3data.load_faces68); bins are M3's five yaw classes (-60: under -60°, -30: -60..-30°,
  0: -30..30°, 30: 30..60°, 60: over 60°).
- Peers (--peers): ../shared/tools/peer_landmarks.py on the same manifest: PFLD on these boxes, and
  dlib on boxes mapped into its HOG detector's convention (eval_m3.dlib_box_calibration).
- Confusion: rows the label's class, columns M3's `yaw_class_deg`; recall per class.
- Turned faces (`--turned`): the validation faces turned in yaw by the face model
  (rotate_faces.py, built when absent: 254 faces, 32–97 per turned class), same box jitter. They
  are synthetic: they say whether the yaw classes and the zones follow a turned head, not what a
  photo of a turned head scores.
- `--reference DIR [DIR …]`: the Python reference (m3_reference.py) on each model directory instead
  of the CLI, for comparing trained nets before they ship (single-pass mode; writes nothing).
Writes core/models/m3/yaw_metrics.json and prints the tables.
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import eval_m3 as E  # noqa: E402
import m3data as D  # noqa: E402
import m3_reference as R  # noqa: E402
import rotate_faces  # noqa: E402

CLASSES = [-60, -30, 0, 30, 60]


def bins_of(faces, errs):
    out = {}
    for c in range(5):
        e = [err for f, err in zip(faces, errs) if f["yaw_class"] == c]
        out[str(CLASSES[c])] = {"faces": len(e), "nme": float(np.mean(e)) if e else None}
    return out


def turned_val():
    """(image paths, faces) of the turned validation faces (rotate_faces.py)."""
    index = os.path.join(rotate_faces.default_dir(), "val.jsonl")
    if not os.path.exists(index):
        rotate_faces.build(os.path.dirname(index), "val")
    base = os.path.dirname(index)
    _, faces = rotate_faces.load(index)
    return [os.path.join(base, f["path"]) for f in faces], faces


def confusion_of(faces, classes):
    c = np.zeros((5, 5), int)
    for f, k in zip(faces, classes):
        c[f["yaw_class"], k] += 1
    return c


def reference(dirs):
    """Single-pass Python reference of each model directory on the real and the turned validation
    faces: mean NME, NME per yaw class, recall per yaw class."""
    sets = {"real": D.load_faces68("val"), "turned": turned_val()}
    for name, (paths, faces) in sets.items():
        boxes = E.jittered_boxes(faces)
        grays = {}
        for d in dirs:
            m3 = R.M3(d)
            errs, pred = [], []
            for f, b in zip(faces, boxes):
                p = paths[f["image"]]
                if p not in grays:
                    grays[p] = D.load_gray(p)
                r = m3.run(grays[p], np.array(b))
                errs.append(E.nme_parts(r["landmarks68"], f["pts"])["all"])
                pred.append(int(np.argmax(r["yaw_probs"])))
            bins = bins_of(faces, errs)
            conf = confusion_of(faces, pred)
            rec = ["%d/%d" % (conf[i, i], conf[i].sum()) for i in range(5)]
            print(f"{name:6s} {d}: NME {100 * np.mean(errs):.2f} % | by class " +
                  " ".join(f"{c}:{100 * bins[str(c)]['nme']:.2f}" if bins[str(c)]["nme"] is not None else f"{c}:-"
                           for c in CLASSES) + " | recall " + " ".join(rec), flush=True)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--monotrack")
    ap.add_argument("--peers", action="store_true")
    ap.add_argument("--turned", action="store_true")
    ap.add_argument("--reference", nargs="+")
    a = ap.parse_args()
    if a.reference:
        reference(a.reference)
        return
    if not a.monotrack:
        ap.error("--monotrack or --reference")
    paths, faces = D.load_faces68("val")
    boxes = E.jittered_boxes(faces)
    tmp = tempfile.mkdtemp()
    manifest = os.path.join(tmp, "val.jsonl")
    with open(manifest, "w") as fh:
        for f, b in zip(faces, boxes):
            fh.write(json.dumps({"image": paths[f["image"]], "faces": [{
                "box": [float(v) for v in b], "landmarks68": f["pts"].tolist()}]}) + "\n")
    metrics = {"split": "faces68 val", "faces": len(faces),
               "yaw_source": "MediaPipe teacher, else PnP of the mean face",
               "boxes": "landmark boxes, centre ±5 %, side ±10 % jitter (eval_m3.py, seed 7)"}
    confusion = np.zeros((5, 5), int)
    for extra, name in ((["--single-pass"], "m3_single_pass"), ([], "m3_mirror_average")):
        out = manifest + f".{name}.jsonl"
        subprocess.run([a.monotrack, "landmarks", manifest, "--out", out] + extra, check=True)
        errs = []
        for f, line in zip(faces, open(out)):
            o = json.loads(line)["faces"][0]
            errs.append(E.nme_parts(np.array(o["landmarks68"]), f["pts"])["all"])
            if name == "m3_single_pass":
                confusion[f["yaw_class"], CLASSES.index(o["yaw_class_deg"])] += 1
        metrics[name] = bins_of(faces, errs)
    metrics["yaw_confusion"] = {"rows_label_cols_predicted": CLASSES, "counts": confusion.tolist(),
                                "recall": {str(c): (float(confusion[i, i] / confusion[i].sum())
                                                    if confusion[i].sum() else None)
                                           for i, c in enumerate(CLASSES)}}
    if a.peers:
        tool = os.path.join(D.DATA, "..", "tools", "peer_landmarks.py")
        cal = E.dlib_box_calibration()
        cal_manifest = manifest + ".dlibcal.jsonl"
        E.write_dlib_manifest(cal_manifest, cal, paths, faces, boxes)
        for extra, man, keep in ((["--peers", "pfld"], manifest, "pfld"),
                                 (["--peers", "dlib"], cal_manifest, "dlib")):
            out = man + f".{keep}.jsonl"
            subprocess.run([sys.executable, tool, man, "--out", out] + extra, check=True,
                           capture_output=True)
            errs = []
            for f, line in zip(faces, open(out)):
                pts = json.loads(line)["faces"][0][keep]
                errs.append(E.nme_parts(np.array(pts), f["pts"])["all"])
            metrics[keep] = bins_of(faces, errs)
    path = os.path.join(D.REPO, "core", "models", "m3", "yaw_metrics.json")
    with open(path, "w") as fh:
        json.dump(metrics, fh, indent=1)
    runs = [k for k in ("m3_single_pass", "m3_mirror_average", "pfld", "dlib") if k in metrics]
    print("| yaw class | faces | " + " | ".join(runs) + " |")
    for c in CLASSES:
        row = metrics["m3_single_pass"][str(c)]
        cells = [f"{100 * metrics[r][str(c)]['nme']:.2f} %" if metrics[r][str(c)]["nme"] is not None
                 else "–" for r in runs]
        print(f"| {c} | {row['faces']} | " + " | ".join(cells) + " |")
    print("confusion (rows label, cols predicted):", CLASSES)
    for c, r in zip(CLASSES, confusion):
        print(c, r.tolist(), "recall", metrics["yaw_confusion"]["recall"][str(c)])
    print("wrote", path)


if __name__ == "__main__":
    main()

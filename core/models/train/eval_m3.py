#!/usr/bin/env python3
"""Validation metrics of the trained M3 nets, with the peers measured on the same faces in the same run.

    python3 core/models/train/eval_m3.py [--peers] [--monotrack target/release/monotrack]

- Faces: the faces68 validation split (M3_IO.md: line i % 10 == 0), boxes = landmark boxes with
  seeded realistic jitter (centre ±5 %, side ±10 % of the box side: a detector's or tracker's box).
- Ours: the Python reference (m3_reference.py, onnxruntime) and, with --monotrack, the shipped Rust
  implementation through `monotrack landmarks` (the CLI's own timings); both in single-pass mode
  (`--single-pass`, the video tracker's; `metrics.json`'s top level) and in mirror-average mode
  (M3_IO.md; the default of the CLI and of the image mode; `metrics.json`'s "mirror_average").
- Peers (--peers): ../shared/tools/peer_landmarks.py (dlib's 68-point predictor, PFLD) on the same
  manifest; dlib also in its fair setting (boxes from its own HOG detector).
- NME: CONTRACT.md (mean over 68 points / distance between points 36 and 45), overall and per zone.
- Yaw-class accuracy (vs the teacher/PnP labels), gesture accuracy / macro F1 (with its 90 % bootstrap
  interval over the faces) on the teacher's labels of the validation faces, smile accuracy / F1 on
  our held-out GENKI-4K split (file number % 5 == 0).
Writes core/models/m3/metrics.json and prints a table.
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import m3data as D  # noqa: E402
import m3_reference as R  # noqa: E402

MODEL_DIR = os.environ.get("MONOTRACK_M3_DIR", os.path.join(D.REPO, "core", "models", "m3"))
ZONES = {"jaw": range(0, 17), "brows": range(17, 27), "nose": range(27, 36), "eyes": range(36, 48),
         "mouth": range(48, 68)}
JITTER_SEED = 7


def nme_parts(pred, gt):
    iod = D.outer_eye_distance(gt)
    e = np.linalg.norm(pred - gt, axis=1) / iod
    out = {"all": float(e.mean())}
    for k, r in ZONES.items():
        out[k] = float(e[list(r)].mean())
    return out


def jittered_boxes(faces, seed=JITTER_SEED):
    rng = np.random.default_rng(seed)
    boxes = []
    for f in faces:
        x, y, w, h = D.box_of(f["pts"])
        s = max(w, h)
        cx, cy = x + w / 2 + rng.uniform(-0.05, 0.05) * s, y + h / 2 + rng.uniform(-0.05, 0.05) * s
        k = np.exp(rng.uniform(np.log(0.9), np.log(1.1)))
        boxes.append([cx - k * w / 2, cy - k * h / 2, k * w, k * h])
    return boxes


def dlib_box_calibration():
    """dlib's predictor was trained on its HOG detector's boxes, not on landmark boxes: fit the map
    from a landmark box (centre, side s = max(w, h)) to the matching HOG box on the *training* split
    (median offsets and scale), so dlib gets boxes in its own convention in the comparison."""
    import dlib
    hog = dlib.get_frontal_face_detector()
    paths, faces = D.load_faces68("train")
    by_img = {}
    for f in faces:
        by_img.setdefault(f["image"], []).append(f)
    dx, dy, sc = [], [], []
    for i, fs in list(by_img.items())[::3]:
        import cv2
        rgb = cv2.imread(paths[i])[..., ::-1].copy()
        dets = list(hog(rgb, 1))
        for f in fs:
            x, y, w, h = D.box_of(f["pts"])
            s, cx, cy = max(w, h), x + w / 2, y + h / 2
            for d in dets:
                ddx, ddy = (d.center().x - cx) / s, (d.center().y - cy) / s
                if abs(ddx) < 0.25 and abs(ddy) < 0.25:
                    dx.append(ddx)
                    dy.append(ddy)
                    sc.append(d.width() / s)
    return {"dx": float(np.median(dx)), "dy": float(np.median(dy)), "scale": float(np.median(sc)), "n": len(dx)}


def write_dlib_manifest(path, cal, paths, faces, boxes):
    """A peer manifest of `faces` whose landmark-convention `boxes` are mapped into dlib's HOG
    convention by `cal` (dlib_box_calibration)."""
    with open(path, "w") as fh:
        for f, b in zip(faces, boxes):
            x, y, w, h = b
            s = max(w, h)
            cx, cy = x + w / 2 + cal["dx"] * s, y + h / 2 + cal["dy"] * s
            side = cal["scale"] * s
            fh.write(json.dumps({"image": paths[f["image"]], "faces": [{
                "box": [cx - side / 2, cy - side / 2, side, side], "landmarks68": f["pts"].tolist()}]}) + "\n")


def f1_per_class(y, p, n):
    """F1 of each class (None where the class has no example)."""
    out = []
    for c in range(n):
        tp = np.sum((p == c) & (y == c))
        fp = np.sum((p == c) & (y != c))
        fn = np.sum((p != c) & (y == c))
        out.append(None if tp + fn == 0 else float(2 * tp / max(2 * tp + fp + fn, 1)))
    return out


def f1_macro(y, p, n):
    """Mean F1 over the classes that have an example."""
    f1s = [f for f in f1_per_class(y, p, n) if f is not None]
    return float(np.mean(f1s)) if f1s else float("nan")


def f1_macro_interval(y, p, n, level=0.9, rounds=2000, seed=0):
    """The `level` bootstrap interval of f1_macro (faces resampled with replacement, fixed seed):
    with 102 validation faces and 10 of a class, one face more or less right moves the macro F1 by
    0.01-0.02, so a figure is only read together with its interval."""
    rng = np.random.default_rng(seed)
    y, p = np.asarray(y), np.asarray(p)
    fs = [f1_macro(y[i], p[i], n) for i in (rng.integers(0, len(y), len(y)) for _ in range(rounds))]
    lo, hi = np.percentile(fs, [50 * (1 - level), 50 * (1 + level)])
    return [float(lo), float(hi)]


def gesture_metrics(pairs, n):
    """Accuracy, macro F1 with its 90 % bootstrap interval, per-class F1 and label counts of
    (teacher class, predicted class) pairs."""
    pairs = np.asarray(pairs)
    y, p = pairs[:, 0], pairs[:, 1]
    return {"accuracy": float(np.mean(y == p)), "macro_f1": f1_macro(y, p, n),
            "macro_f1_90": f1_macro_interval(y, p, n), "n": len(pairs),
            "per_class_f1": f1_per_class(y, p, n), "label_counts": np.bincount(y, minlength=n).tolist()}


def summarize(errs):
    return {k: float(np.mean([e[k] for e in errs])) for k in errs[0]}


def read_genki_crop(m3, img):
    """`m3`'s result on a GENKI-4K crop: run on D.GENKI_START_BOX, then again on the box of the
    points it found (the crops carry no box)."""
    box = np.array(D.GENKI_START_BOX)
    for _ in range(2):
        r = m3.run(img, box)
        box = D.box_of(r["landmarks68"])
    return r


def measure(m3, faces, boxes, grays, genki):
    """The Python reference's metrics in `m3`'s mode: NME per zone, yaw-class accuracy, gestures on
    the validation faces (`grays`: their images by name), smile on the held-out GENKI-4K split
    (`genki`), time per face."""
    errs, yaw_ok, mouth, brows, times = [], [], [], [], []
    for f, b in zip(faces, boxes):
        g = grays[f["image"]]
        t0 = time.perf_counter()
        r = m3.run(g, np.array(b))
        times.append(time.perf_counter() - t0)
        errs.append(nme_parts(r["landmarks68"], f["pts"]))
        yaw_ok.append(int(np.argmax(r["yaw_probs"])) == f["yaw_class"])
        if f["mouth"] >= 0:
            mouth.append((f["mouth"], int(np.argmax(list(r["mouth"].values())))))
        if f["brows"] >= 0:
            brows.append((f["brows"], int(np.argmax(list(r["brows"].values())))))
    metrics = {
        "val_faces": len(faces),
        "box_jitter": "centre ±5 %, side ±10 % of the landmark box (seed 7)",
        "nme_python_reference": summarize(errs),
        "yaw_class_accuracy": float(np.mean(yaw_ok)),
        "mouth_gesture": gesture_metrics(mouth, 4),
        "brow_gesture": gesture_metrics(brows, 3),
        "python_onnxruntime_ms_per_face": 1e3 * float(np.median(times)),
    }
    # GENKI-4K held-out smile split: level 1 on the whole crop, then again on the box of its points.
    teacher = genki_teacher()
    ys, ps, t_mouth, t_brows = [], [], [], []
    for img, label, name in genki:
        r = read_genki_crop(m3, img)
        ys.append(label)
        ps.append(r["mouth"]["smile"] > 0.5)
        if name in teacher:
            t_mouth.append((teacher[name][0], int(np.argmax(list(r["mouth"].values())))))
            t_brows.append((teacher[name][1], int(np.argmax(list(r["brows"].values())))))
    ys, ps = np.array(ys), np.array(ps).astype(int)
    tp, fp, fn = np.sum(ps & ys), np.sum(ps & (1 - ys)), np.sum((1 - ps) & ys)
    metrics["genki_smile"] = {"n": len(ys), "accuracy": float(np.mean(ps == ys)),
                              "f1": float(2 * tp / max(2 * tp + fp + fn, 1))}
    if teacher:
        for key, pairs, n in (("genki_mouth_gesture", t_mouth, 4), ("genki_brow_gesture", t_brows, 3)):
            metrics[key] = gesture_metrics(pairs, n)
    return metrics


def genki_teacher():
    """The MediaPipe teacher's gesture classes of the held-out GENKI-4K crops (teacher_genki.py), or
    {} when its file has not been made."""
    import teacher_genki
    path = os.environ.get("MONOTRACK_GENKI_TEACHER") or teacher_genki.default_path()
    return teacher_genki.load(path, "test") if os.path.exists(path) else {}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--peers", action="store_true")
    ap.add_argument("--monotrack", help="path of the built `monotrack` CLI to measure the Rust implementation")
    a = ap.parse_args()
    paths, faces = D.load_faces68("val")
    boxes = jittered_boxes(faces)
    # Loaded once for both modes.
    grays = {f["image"]: D.load_gray(paths[f["image"]]) for f in faces}
    genki = D.load_genki("test")
    metrics = measure(R.M3(MODEL_DIR), faces, boxes, grays, genki)
    metrics["mirror_average"] = measure(R.M3(MODEL_DIR, mirror_average=True), faces, boxes, grays, genki)
    manifest = os.path.join(tempfile.mkdtemp(), "val_manifest.jsonl")
    with open(manifest, "w") as fh:
        for f, b in zip(faces, boxes):
            fh.write(json.dumps({"image": paths[f["image"]], "faces": [{"box": [float(v) for v in b],
                                 "landmarks68": f["pts"].tolist()}]}) + "\n")
    if a.monotrack:
        metrics["cli_default"] = "mirror_average"
        for extra, into in ((["--single-pass"], metrics), ([], metrics["mirror_average"])):
            out = manifest + ".ours.jsonl"
            subprocess.run([a.monotrack, "landmarks", manifest, "--out", out] + extra, check=True)
            errs_rs, us = [], []
            for f, line in zip(faces, open(out)):
                o = json.loads(line)
                errs_rs.append(nme_parts(np.array(o["faces"][0]["landmarks68"]), f["pts"]))
                us.append(o["timings_us"]["landmarks"])
            into["nme_rust"] = summarize(errs_rs)
            into["rust_landmarks_us_median"] = float(np.median(us))
    if a.peers:
        tool = os.path.join(D.DATA, "..", "tools", "peer_landmarks.py")
        cal_manifest = manifest + ".dlibcal.jsonl"
        cal = dlib_box_calibration()
        metrics["dlib_box_calibration"] = cal
        write_dlib_manifest(cal_manifest, cal, paths, faces, boxes)
        runs = (([], "", manifest), (["--peers", "dlib"], "_calibrated_box", cal_manifest),
                (["--peers", "dlib", "--dlib-own-detector"], "_own_detector", manifest))
        for extra, tag, man in runs:
            out = manifest + f".peers{tag}.jsonl"
            res = subprocess.run([sys.executable, tool, man, "--out", out] + extra, capture_output=True,
                                 text=True)
            print(res.stdout, res.stderr[-2000:])
            per = {}
            for f, line in zip(faces, open(out)):
                for peer, pts in json.loads(line)["faces"][0].items():
                    per.setdefault(peer, []).append(nme_parts(np.array(pts), f["pts"]))
            for peer, e in per.items():
                metrics[f"nme_{peer}{tag}"] = summarize(e)
            for line in res.stdout.strip().splitlines():
                peer = line.split(":")[0]
                metrics[f"{peer}{tag}_tool_line"] = line
    with open(os.path.join(MODEL_DIR, "metrics.json"), "w") as fh:
        json.dump(metrics, fh, indent=1)
    print(json.dumps(metrics, indent=1))


if __name__ == "__main__":
    main()

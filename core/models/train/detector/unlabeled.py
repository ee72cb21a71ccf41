#!/usr/bin/env python3
"""Finds faces that faces68 does not annotate, so that training and evaluation can ignore them.

usage: python3 core/models/train/detector/unlabeled.py [--out PATH]

faces68's HELEN images are crops around one annotated person, yet many show other people whose faces
carry no landmarks (and AFW misses a few). Treated as background, they would teach the detector
that faces are negatives and count its correct detections as false positives. This script runs the
Ultra-Light RFB-640 detector (../shared/data/peers/ultralight_rfb, MIT; a peer used here only as an
annotator of "ignore" regions, never shipped) on every image and keeps confident detections
(score >= MIN_SCORE) that match no annotated face. Output: {"image": [[x, y, w, h], ...]} in that
detector's own box convention (a loose face box), written to ~/.cache/monotrack/unlabeled_faces.json
(derived from research data: not committed). Training masks the loss over these boxes; evaluation
(eval_peers.py) neither rewards nor penalises any detector's detections on them.
"""
import argparse, json, os
import numpy as np
import cv2
import onnxruntime as ort

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.abspath(os.path.join(HERE, "../../../.."))
SHARED = os.environ.get("MONOTRACK_SHARED_DATA", os.path.join(ROOT, "../shared/data"))
DEFAULT_OUT = os.path.expanduser("~/.cache/monotrack/unlabeled_faces.json")
# High enough that the peer's own false positives are rare (checked on a contact sheet of the
# validation images' regions), low enough to catch the small background faces.
MIN_SCORE = 0.9


def ultralight_session(name="version-RFB-640.onnx"):
    so = ort.SessionOptions()
    so.log_severity_level = 3
    so.intra_op_num_threads = 1
    return ort.InferenceSession(os.path.join(SHARED, "peers/ultralight_rfb", name), so,
                                providers=["CPUExecutionProvider"])


def ultralight_detect(sess, bgr, thr, size=(640, 480)):
    """Ultra-Light's reference preprocessing: RGB resized to the input, (x - 127) / 128; boxes come
    back as normalised corners. Returns [(x, y, w, h, score)] after NMS 0.3."""
    h0, w0 = bgr.shape[:2]
    im = cv2.resize(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), size).astype(np.float32)
    im = ((im - 127.0) / 128.0).transpose(2, 0, 1)[None]
    scores, boxes = sess.run(None, {"input": im})
    s = scores[0, :, 1]
    keep = s >= thr
    b = boxes[0][keep] * np.array([w0, h0, w0, h0], np.float32)
    s = s[keep]
    order = np.argsort(-s)
    out = []
    for i in order:
        x0, y0, x1, y1 = b[i]
        d = (float(x0), float(y0), float(x1 - x0), float(y1 - y0), float(s[i]))
        if all(iou(d, k) <= 0.3 for k in out):
            out.append(d)
    return out


def iou(a, b):
    x0, y0 = max(a[0], b[0]), max(a[1], b[1])
    x1, y1 = min(a[0] + a[2], b[0] + b[2]), min(a[1] + a[3], b[1] + b[3])
    inter = max(0, x1 - x0) * max(0, y1 - y0)
    u = a[2] * a[3] + b[2] * b[3] - inter
    return inter / u if u > 0 else 0.0


def matches_annotated(d, boxes):
    """A peer box belongs to an annotated face when the face's tight landmark box centre is inside it
    or they overlap by IoU >= 0.2 (the peer's boxes are looser than the landmark boxes)."""
    for b in boxes:
        cx, cy = b[0] + b[2] / 2, b[1] + b[3] / 2
        if d[0] <= cx <= d[0] + d[2] and d[1] <= cy <= d[1] + d[3]:
            return True
        if iou(d, b) >= 0.2:
            return True
    return False


def load(path=DEFAULT_OUT):
    """The cached map, computing it first when absent."""
    if not os.path.exists(path):
        build(path)
    with open(path) as f:
        return json.load(f)


def build(path):
    sess = ultralight_session()
    out = {}
    with open(os.path.join(SHARED, "faces68/train.jsonl")) as f:
        for line in f:
            d = json.loads(line)
            bgr = cv2.imread(os.path.join(SHARED, "faces68", d["image"]))
            boxes = []
            for face in d["faces"]:
                p = np.asarray(face["landmarks68"])
                x0, y0 = p.min(0)
                x1, y1 = p.max(0)
                boxes.append((x0, y0, x1 - x0, y1 - y0))
            extra = [list(map(lambda v: round(v, 1), det[:4])) for det in ultralight_detect(sess, bgr, MIN_SCORE)
                     if not matches_annotated(det, boxes)]
            if extra:
                out[d["image"]] = extra
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "w") as f:
        json.dump(out, f)
    print(f"unlabeled faces: {sum(len(v) for v in out.values())} in {len(out)} images -> {path}")


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default=DEFAULT_OUT)
    build(ap.parse_args().out)

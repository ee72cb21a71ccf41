#!/usr/bin/env python3
"""Decision offsets for the brow net's gesture classes, fitted on faces no net trained on and
written into `brows.onnx`'s gesture bias.

    python3 core/models/train/calibrate_gestures.py [MODEL_DIR]

Why: the brow net learns its three classes (raise, frown, neutral) from 1,079 faces with square-root
class-balanced sampling and class-weighted losses, which leaves its argmax reading raised and
frowning brows more often than the teacher marks them. The MediaPipe teacher's labels of the
GENKI-4K training-split crops (`teacher_genki.py`; 2,081 crops the shipped nets never learn from)
are a set to fit that on: each class's logit gets an offset (neutral's stays 0) chosen on a
0.1 grid in −3..3 to maximise the macro F1 against the teacher there, the crops read as
`eval_m3.py` reads the held-out ones (single-pass, level 1 again on the box of its points). The
offsets are added to the gesture layer's bias and recorded in the file's metadata
(`gesture_logit_offsets`, beside the bias as trained), so a second run starts from the trained
bias and fits again: the same file comes out. Landmarks do not change; the probabilities apps read do (softmax of the
shifted logits). RESEARCH_LOG.md gives the validation figures.

Needs the teacher's cache (`teacher_genki.py`); without it the script says so and changes nothing.
"""
import itertools
import json
import os
import sys

import numpy as np
import onnx
from onnx import numpy_helper

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import eval_m3 as E  # noqa: E402
import m3_reference as R  # noqa: E402
import m3data as D  # noqa: E402
import teacher_genki  # noqa: E402

NET = "brows.onnx"
BIAS = "gestures.bias"
KEY = "gesture_logit_offsets"
# The bias as trained, so that a second run starts from exactly it.
TRAINED = "gesture_bias_trained"
GRID = np.round(np.arange(-3.0, 3.0001, 0.1), 1)


def metadata(model, key):
    for p in model.metadata_props:
        if p.key == key:
            return np.array(json.loads(p.value), np.float32)
    return None


def set_offsets(path, offsets):
    """The gesture bias of the net at `path` set to its trained values plus `offsets`."""
    model = onnx.load(path)
    init = next(i for i in model.graph.initializer if i.name == BIAS)
    trained = metadata(model, TRAINED)
    if trained is None:
        trained = numpy_helper.to_array(init).astype(np.float32)
    init.CopyFrom(numpy_helper.from_array((trained + offsets).astype(np.float32), BIAS))
    kept = [p for p in model.metadata_props if p.key not in (KEY, TRAINED)]
    del model.metadata_props[:]
    model.metadata_props.extend(kept)
    model.metadata_props.add(key=KEY, value=json.dumps([round(float(v), 1) for v in offsets]))
    model.metadata_props.add(key=TRAINED, value=json.dumps([float(v) for v in trained]))
    onnx.save(model, path)


def log_probs(model_dir, teacher):
    """(teacher brow class, log probabilities) of every GENKI-4K training-split crop the teacher
    labelled, read by the Python reference as eval_m3.py reads the held-out ones."""
    m3 = R.M3(model_dir)
    out = []
    for path, _, name in D.genki_files("train"):
        if name not in teacher or teacher[name][1] < 0:
            continue
        r = E.read_genki_crop(m3, D.load_gray(path))
        out.append((teacher[name][1], np.log(np.array(list(r["brows"].values())) + 1e-9)))
    return np.array([y for y, _ in out]), np.array([p for _, p in out])


def fit(y, lp):
    """Offsets (raise, frown, 0) with the highest macro F1; ties keep the smallest change."""
    best = None
    for a, b in itertools.product(GRID, GRID):
        off = np.array([a, b, 0.0], np.float32)
        f1 = E.f1_macro(y, np.argmax(lp + off, 1), 3)
        key = (round(f1, 9), -abs(a) - abs(b))
        if best is None or key > best[0]:
            best = (key, off)
    return best[1], best[0][0]


def main(model_dir):
    path = os.environ.get("MONOTRACK_GENKI_TEACHER") or teacher_genki.default_path()
    if not os.path.exists(path):
        print(f"{path} is missing: run teacher_genki.py (it needs mediapipe==0.10.14); nothing changed")
        return 1
    teacher = teacher_genki.load(path, "train")
    net = os.path.join(model_dir, NET)
    # Fit on the net as trained.
    set_offsets(net, np.zeros(3, np.float32))
    y, lp = log_probs(model_dir, teacher)
    before = E.f1_macro(y, np.argmax(lp, 1), 3)
    off, after = fit(y, lp)
    set_offsets(net, off)
    print(f"{len(y)} GENKI-4K training crops: brow gesture macro F1 {before:.3f} -> {after:.3f} "
          f"with logit offsets raise {off[0]:+.1f}, frown {off[1]:+.1f} -> {net}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1] if len(sys.argv) > 1 else
                  os.environ.get("MONOTRACK_M3_OUT", os.path.join(D.REPO, "core", "models", "m3"))))

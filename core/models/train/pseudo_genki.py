#!/usr/bin/env python3
"""Teacher landmarks for GENKI-4K faces: PFLD (../shared/data/peers/pfld, a peer model never shipped)
labels the 68 iBUG points of every GENKI-4K training-split crop, as extra landmark data for the
face zone net (jaw + nose), which overfits the 1,079 faces68 training faces (RESEARCH_LOG.md).

usage: python3 core/models/train/pseudo_genki.py [OUT.jsonl]
  (default $XDG_CACHE_HOME or ~/.cache /monotrack/genki_pfld.jsonl; train_m3.py calls it when missing)

Only our own GENKI split's training crops (file number % 5 != 0) are labelled: the held-out smile
crops stay unseen. The face box does not come from our models (so relabelling does not depend on
the weights it helps to train): PFLD runs on the crop's central box, then twice more on the tight
box of its own points (it settles in two rounds). Runs the shared peer tool
(../shared/tools/peer_landmarks.py) for the PFLD preprocessing. Output lines:
{"image": absolute path, "faces": [{"pfld": [[x, y] x 68]}]}.
"""
import json
import os
import subprocess
import sys
import tempfile

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import m3data as D  # noqa: E402

TOOL = os.path.join(D.DATA, "..", "tools", "peer_landmarks.py")
# GENKI crops are 64x64 with the face filling most of it: the first box before PFLD refines it.
FIRST_BOX = [6.0, 8.0, 52.0, 52.0]
ROUNDS = 3


def default_path():
    cache = os.environ.get("XDG_CACHE_HOME", os.path.join(os.path.expanduser("~"), ".cache"))
    return os.path.join(cache, "monotrack", "genki_pfld.jsonl")


def peer_points(images, boxes, peer, *flags):
    """`peer`'s 68 points (the shared peer tool) for one face per image, on `boxes` (x, y, w, h)."""
    with tempfile.TemporaryDirectory() as tmp:
        man, res = os.path.join(tmp, "in.jsonl"), os.path.join(tmp, "out.jsonl")
        with open(man, "w") as fh:
            for p, b in zip(images, boxes):
                fh.write(json.dumps({"image": p, "faces": [{"box": [float(v) for v in b]}]}) + "\n")
        subprocess.run([sys.executable, TOOL, man, "--peers", peer, "--out", res, *flags], check=True,
                       stdout=subprocess.DEVNULL)
        return [np.array(json.loads(line)["faces"][0][peer]) for line in open(res)]


def pfld_settled(images, boxes):
    """PFLD's points run from `boxes`, then ROUNDS - 1 times more on the box of its own points."""
    for _ in range(ROUNDS):
        pts = peer_points(images, boxes, "pfld")
        boxes = [D.box_of(p).tolist() for p in pts]
    return pts


def main(out=None):
    out = out or default_path()
    os.makedirs(os.path.dirname(out), exist_ok=True)
    images = [os.path.abspath(path) for path, _, _ in D.genki_files("train")]
    pts = pfld_settled(images, [FIRST_BOX] * len(images))
    with open(out, "w") as fh:
        for p, q in zip(images, pts):
            fh.write(json.dumps({"image": p, "faces": [{"pfld": q.round(2).tolist()}]}) + "\n")
    print(f"{len(images)} GENKI-4K crops labelled by PFLD -> {out}")
    return out


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else None)

#!/usr/bin/env python3
"""Writes a model bundle: every network and the face model a tracker runs on, in one versioned,
checksummed file that `ModelBundle.fromBytes` / `fromPath` (Kotlin, Swift) and
`FaceTrackerOptions.models` take (format: `core/src/model/bundle.rs`). Standard library only.

    python3 core/models/train/make_bundle.py OUT.mtb [--m3 DIR] [--detector DIR] [--face-model FILE]

`--m3`: a folder with `m3.json` and the files it names (what train_m3.py writes; default the
shipped `core/models/m3`); `--detector`: a folder with `detector.json` and `detector.onnx`
(default `core/models/detector`); `--face-model`: the face model (default the shipped one, the
only one this version fits).
"""
import argparse
import json
import os
import struct
import zlib

REPO = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "..", ".."))
MODELS = os.path.join(REPO, "core", "models")
MAGIC = b"MTBUNDLE"
FORMAT_VERSION = 1


def m3_files(m3_dir):
    """m3.json and every file it names, in that order."""
    cfg = json.load(open(os.path.join(m3_dir, "m3.json")))
    names = ["m3.json", cfg["level1"]["file"]]
    names += [z["file"] for z in cfg["zones"].values()]
    if cfg.get("shape_prior"):
        names.append(cfg["shape_prior"]["file"])
    return [(n, os.path.join(m3_dir, n)) for n in dict.fromkeys(names)]


def bundle_bytes(entries):
    """The bundle file of (name, bytes) entries."""
    head = MAGIC + struct.pack("<II", FORMAT_VERSION, len(entries))
    for name, data in entries:
        raw = name.encode("utf-8")
        head += struct.pack("<H", len(raw)) + raw + struct.pack("<Q", len(data))
    body = head + b"".join(data for _, data in entries)
    return body + struct.pack("<I", zlib.crc32(body) & 0xFFFFFFFF)


def write(out, m3_dir, detector_dir, face_model):
    paths = m3_files(m3_dir)
    paths += [(n, os.path.join(detector_dir, n)) for n in ("detector.json", "detector.onnx")]
    paths.append(("face_model.json", face_model))
    entries = [(n, open(p, "rb").read()) for n, p in paths]
    data = bundle_bytes(entries)
    with open(out, "wb") as f:
        f.write(data)
    return len(entries), len(data)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out")
    ap.add_argument("--m3", default=os.path.join(MODELS, "m3"))
    ap.add_argument("--detector", default=os.path.join(MODELS, "detector"))
    ap.add_argument("--face-model", default=os.path.join(MODELS, "face_model", "face_model.json"))
    a = ap.parse_args()
    n, size = write(a.out, a.m3, a.detector, a.face_model)
    print(f"{a.out}: {n} files, {size} bytes, format {FORMAT_VERSION}")


if __name__ == "__main__":
    main()

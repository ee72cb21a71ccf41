#!/usr/bin/env python3
"""Writes the committed seed corpus of the `recording` fuzz target (fuzz/corpus/recording/) from
the format as core/src/record/FORMAT.md documents it, without the library's writer: files named
`valid-*` must read (fuzz/entry/tests/corpora.rs checks that they do, so the document and the
reader agree), `invalid-*` must be refused. Usage: python3 fuzz/make_recording_corpus.py"""
import json
import os
import struct

OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "corpus", "recording")

HEADER = {
    "library_version": "0.1.0",
    "arch": "aarch64",
    "kernels": "native",
    "cpu": "a seed",
    "tracker": {},
    "detector": {},
    "mirror_average": False,
    "gaze": {},
    "models": {"builtin": True, "checksum": 0},
}


def chunk(kind, payload):
    return struct.pack("<BI", kind, len(payload)) + payload


def header(version=1, fields=HEADER):
    return b"MTRECORD" + struct.pack("<I", version) + chunk(1, json.dumps(fields).encode())


def start(taps=()):
    p = struct.pack("<QQII", 1, 0, 0, len(taps))
    for t in taps:
        p += struct.pack("<4d", *t)
    return chunk(2, p)


def frame(ts, width, height, fmt, rotation, mirrored, row, crow, cpix, data):
    return chunk(3, struct.pack("<qIIBHBIII", ts, width, height, fmt, rotation, mirrored, row, crow, cpix) + data)


def result(digest=None):
    return chunk(4, struct.pack("<BQ", 0 if digest is None else 1, digest or 0))


def dropped(frames, timestamps):
    return chunk(5, struct.pack("<QI", frames, len(timestamps)) + struct.pack(f"<{len(timestamps)}q", *timestamps))


def targets(items):
    p = struct.pack("<I", len(items))
    for ident, corners in items:
        p += struct.pack("<H", len(ident)) + ident.encode() + struct.pack("<I", len(corners))
        for c in corners:
            p += struct.pack("<3d", *c)
    return chunk(6, p)


def tap(target, u, v, ts):
    return chunk(7, struct.pack("<Iddq", target, u, v, ts))


def reset(what):
    return chunk(8, bytes([what]))


def end(truncated=0):
    return chunk(9, bytes([truncated]))


def main():
    os.makedirs(OUT, exist_ok=True)
    gray = bytes(range(48))  # 8 x 6 GRAY8, packed
    # NV21 6 x 4, rows of 8 bytes: Y 8 * 4, then 2 chroma rows, the last only 6 bytes.
    nv21 = bytes((i * 7) % 251 for i in range(8 * 4 + 8 + 6))
    # I420 4 x 2: Y 4 * 2, U 2 * 1, V 2 * 1.
    i420 = bytes(range(12))
    phone = ("phone", [(-35, 8, 0), (35, 8, 0), (35, 158, 0), (-35, 158, 0)])
    every = (
        header()
        + start([(0.01, -0.02, 0.03, 0.04), (-0.5, 0.25, 0.0, -0.1)])
        + targets([phone])
        + frame(0, 8, 6, 3, 0, 0, 8, 0, 0, gray)
        + result(0x0123456789ABCDEF)
        + dropped(3, [10, 20])
        + frame(33_000_000, 6, 4, 4, 90, 1, 8, 8, 2, nv21)
        + result(None)
        + targets([])
        + tap(0, 35.0, 50.0, 33_000_000)
        + reset(0)
        + reset(1)
        + frame(66_000_000, 4, 2, 6, 270, 0, 4, 2, 1, i420)
        + end()
    )
    files = {
        "valid-every-kind": every,
        "valid-empty-truncated": header() + end(1),
        "invalid-cut-off": every[:-3],
        "invalid-no-end": every[:-6],
        "invalid-version-2": header(version=2) + end(),
        "invalid-frame-length": header() + start() + frame(0, 8, 6, 3, 0, 0, 8, 0, 0, gray[:-1]) + end(),
        "invalid-result-first": header() + start() + result(1) + end(),
        "invalid-header-settings": header(fields=dict(HEADER, tracker={"max_faces": 0})) + end(),
    }
    for name, data in files.items():
        with open(os.path.join(OUT, name), "wb") as f:
            f.write(data)
    print(f"wrote {len(files)} files to {OUT}")


if __name__ == "__main__":
    main()

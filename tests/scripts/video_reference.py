#!/usr/bin/env python3
"""Reference landmarks for a video without annotations, to score tracking (`track_eval --video`).

    python3 tests/scripts/video_reference.py VIDEO OUT.jsonl

Runs dlib's HOG detector + 68-point shape predictor (a peer; `pip install dlib-bin`,
`apt-get install libdlib-data`) on every frame and writes one line per frame:
`{"frame": i, "landmarks68": [[x, y] x 68] | null}` (the largest face). dlib's predictor is trained
on 300-W, reaches about 2.7 % NME on HELEN test, and is reliable on a frontal talking face; its points
serve as pseudo ground truth for the correct-frame rate (NME against them below a stated threshold).
Output goes wherever the caller says (never committed: it is derived from ../shared/data).
"""
import json
import subprocess
import sys

import numpy as np


def frames(path):
    probe = subprocess.run(["ffprobe", "-v", "error", "-select_streams", "v:0", "-show_entries",
                            "stream=width,height", "-of", "csv=p=0", path], capture_output=True, text=True, check=True)
    w, h = map(int, probe.stdout.strip().split(",")[:2])
    p = subprocess.Popen(["ffmpeg", "-v", "error", "-i", path, "-f", "rawvideo", "-pix_fmt", "rgb24", "-"],
                         stdout=subprocess.PIPE)
    n = w * h * 3
    while True:
        buf = p.stdout.read(n)
        if len(buf) < n:
            break
        yield np.frombuffer(buf, np.uint8).reshape(h, w, 3)


def main():
    import dlib
    video, out = sys.argv[1], sys.argv[2]
    det = dlib.get_frontal_face_detector()
    sp = dlib.shape_predictor("/usr/share/dlib/shape_predictor_68_face_landmarks.dat")
    with open(out, "w") as fh:
        for i, rgb in enumerate(frames(video)):
            dets = sorted(det(rgb, 0), key=lambda d: -d.area())
            pts = None
            if dets:
                s = sp(rgb, dets[0])
                pts = [[s.part(k).x + 0.5, s.part(k).y + 0.5] for k in range(68)]
            fh.write(json.dumps({"frame": i, "landmarks68": pts}) + "\n")


if __name__ == "__main__":
    main()

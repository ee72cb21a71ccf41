#!/usr/bin/env python3
"""Writes examples/fit_example.jsonl: landmarks projected from monotrack's own face model
(core/models/face_model/face_model.json) at known poses, shapes and expressions, with 0.5 px noise
(seed fixed). The true pose rides along in each line's "truth" field (ignored by `monotrack fit`),
so the README's main command can be checked by eye; its angles are the head frame's (CONTRACT.md),
those the CLI reports, so the model is turned by R(truth) times the head frame's constant pitch
undone (core/src/fit/pose.rs, HEAD_FRAME_PITCH_DEG)."""
import json, math, os, random, re

HERE = os.path.dirname(os.path.abspath(__file__))
model = json.load(open(os.path.join(HERE, "../core/models/face_model/face_model.json")))
rng = random.Random(7)
HEAD_PITCH = float(re.search(r"pub const HEAD_FRAME_PITCH_DEG: f64 = ([-0-9.eE]+);",
                             open(os.path.join(HERE, "../core/src/fit/pose.rs")).read()).group(1))


def mm(a, b):
    return [[sum(a[i][k] * b[k][j] for k in range(3)) for j in range(3)] for i in range(3)]


def rot(yaw, pitch, roll):
    y, p, r = (math.radians(a) for a in (yaw, pitch, roll))
    rx = [[1, 0, 0], [0, math.cos(p), -math.sin(p)], [0, math.sin(p), math.cos(p)]]
    ry = [[math.cos(y), 0, math.sin(y)], [0, 1, 0], [-math.sin(y), 0, math.cos(y)]]
    rz = [[math.cos(r), -math.sin(r), 0], [math.sin(r), math.cos(r), 0], [0, 0, 1]]
    return mm(rz, mm(ry, rx))


def face(yaw, pitch, roll, t, shape, anim, w, h):
    f = 0.9 * max(w, h)
    R = mm(rot(yaw, pitch, roll), rot(0, -HEAD_PITCH, 0))
    pts = []
    for i in range(68):
        g = list(model["mean"][i])
        for u, tau in zip(model["shape_units"], shape):
            g = [g[a] + tau * u["displacement"][i][a] for a in range(3)]
        for u, tau in zip(model["animation_units"], anim):
            g = [g[a] + tau * u["displacement"][i][a] for a in range(3)]
        c = [sum(R[a][b] * g[b] for b in range(3)) + t[a] for a in range(3)]
        pts.append([round(f * c[0] / c[2] + w / 2 + rng.gauss(0, 0.5), 2),
                    round(f * c[1] / c[2] + h / 2 + rng.gauss(0, 0.5), 2)])
    return pts


lines = []
for yaw, pitch, roll, t, smile in [(0, 0, 0, [0, 0, 600], 0.0), (-35, 10, 5, [-60, 20, 800], 0.8),
                                   (50, -15, -10, [80, -30, 1000], 0.0)]:
    shape = [0.0] * 11
    anim = [0.0] * 6
    anim[4] = smile
    lines.append({"width": 640, "height": 480,
                  "faces": [{"landmarks68": face(yaw, pitch, roll, t, shape, anim, 640, 480)}],
                  "truth": {"yaw_deg": yaw, "pitch_deg": pitch, "roll_deg": roll, "translation_mm": t,
                            "smile": smile}})
with open(os.path.join(HERE, "fit_example.jsonl"), "w") as f:
    for l in lines:
        f.write(json.dumps(l) + "\n")
print("wrote", len(lines), "lines")

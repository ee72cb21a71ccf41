#!/usr/bin/env python3
"""Writes examples/body_fit_example.jsonl: six frames of a synthetic walker (a stick figure with
HumanEva-I joint definitions and the HumanEva-I mean body (`Convention::mean_lengths_mm`) scaled by 1.05, legs and arms
swinging sinusoidally, the lower ankle 88 mm above the floor) seen by a 640x480 camera (f = 760 px)
4.5 m away and 1.5 m high, with 0.5 px uniform noise on the 2D joints (seed fixed). The camera is
given to `monotrack body-fit` only through the image corners of a 2 m x 3 m floor rectangle, so the
example exercises the floor calibration. World frame = the rectangle's: origin at corner 0, x
towards corner 1, y towards corner 3, z up. The true 3D joints (mm) ride along in each line's
"truth" field, ignored by the CLI."""
import json, math, os, random

HERE = os.path.dirname(os.path.abspath(__file__))
rng = random.Random(11)
S = 1.05
BACK, NECK, SHW, HIPW = 484 * S, 319 * S, 349 * S, 93 * S
UARM, FARM, THIGH, SHIN, ANKLE = 294 * S, 280 * S, 421 * S, 400 * S, 88 * S
W, H, F = 640, 480, 760.0
CAM_C = [1000.0, -3000.0, 1500.0]
TILT = math.radians(12)
# Camera axes (rows of R): x right = world +x, z forward = +y tilted down, y = z cross x.
Z = [0.0, math.cos(TILT), -math.sin(TILT)]
X = [1.0, 0.0, 0.0]
Y = [Z[1] * X[2] - Z[2] * X[1], Z[2] * X[0] - Z[0] * X[2], Z[0] * X[1] - Z[1] * X[0]]


def add(a, b, s=1.0):
    return [a[i] + s * b[i] for i in range(3)]


def norm(v):
    n = math.sqrt(sum(x * x for x in v))
    return [x / n for x in v]


def project(p):
    d = [p[i] - CAM_C[i] for i in range(3)]
    c = [sum(R[i] * d[i] for i in range(3)) for R in (X, Y, Z)]
    return [F * c[0] / c[2] + W / 2, F * c[1] / c[2] + H / 2]


def walker(phase, x0):
    # The subject faces the camera (forward = -y, left = +x).
    pelvis = [x0, 1500.0, 0.0]
    joints = {"pelvis": pelvis}
    joints["thorax"] = add(pelvis, [0, 0, BACK])
    joints["head"] = add(joints["thorax"], [0, 0, NECK])
    for side, sx in (("l", 1.0), ("r", -1.0)):
        ph = phase if side == "l" else phase + math.pi
        sh = add(joints["thorax"], [sx * SHW / 2, 35.0 * S, -20.0 * S])
        swing = 0.35 * math.sin(-ph)
        el = add(sh, norm([0.15 * sx, -math.sin(swing), -math.cos(swing)]), UARM)
        bend = swing + 0.5
        wr = add(el, norm([0.05 * sx, -math.sin(bend), -math.cos(bend)]), FARM)
        hip = add(pelvis, [sx * HIPW / 2, -50.0 * S, -4.0 * S])
        a = 0.35 * math.sin(ph)
        k = 0.15 + 0.45 * max(0.0, math.sin(ph + 1.0))
        kn = add(hip, [0, -math.sin(a), -math.cos(a)], THIGH)
        an = add(kn, [0, -math.sin(a - k), -math.cos(a - k)], SHIN)
        joints.update({side + "shoulder": sh, side + "elbow": el, side + "wrist": wr,
                       side + "hip": hip, side + "knee": kn, side + "ankle": an})
    low = min(joints["lankle"][2], joints["rankle"][2])
    return {n: [round(p[0], 1), round(p[1], 1), round(p[2] + ANKLE - low, 1)] for n, p in joints.items()}


corners = [project(p) for p in ([0, 0, 0], [2000, 0, 0], [2000, 3000, 0], [0, 3000, 0])]
lines = []
for f in range(6):
    truth = walker(2 * math.pi * f / 6, 800.0 + 60.0 * f)
    j2 = {n: [round(v + rng.uniform(-0.5, 0.5), 2) for v in project(p)] for n, p in truth.items()}
    lines.append({"frame": f, "sequence": "walk", "width": W, "height": H,
                  "floor": {"corners_px": [[round(v, 2) for v in c] for c in corners], "size_mm": [2000, 3000]},
                  "joints2d": j2, "truth": {"joints3d_mm": truth, "focal_px": F, "camera_center_mm": CAM_C}})
with open(os.path.join(HERE, "body_fit_example.jsonl"), "w") as out:
    for l in lines:
        out.write(json.dumps(l) + "\n")

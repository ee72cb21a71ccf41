#!/usr/bin/env python3
"""Builds monotrack's deformable face model: core/models/face_model/face_model.json.

usage: python3 core/models/face_model/build.py [--mean PATH] [--out PATH]

Mean shape: the 68-point 3D mean face of yinguobing/head-pose-estimation (MIT; see
../shared/data/reference/mean_face_68), already in the SDK's model frame (x towards the subject's
left, y down, z away from the camera, millimetres; outer eye corners 91 mm apart). It is re-centred
on the midpoint of the outer eye corners' x and the nose-bridge height so rotations pivot near the
head's centre of the face plane, and made exactly left/right symmetric (mean of each point and its
mirror), because a symmetric mean keeps a frontal face at yaw 0.

Deformation units are hand-designed displacement fields, not learned: each one moves only the
landmarks its name talks about, by an amount (mm at tau = 1) chosen so that +-1 spans the plausible
adult range (anthropometric spreads, Farkas 1994: e.g. inter-pupillary distance SD ~3.5 mm, mouth
width SD ~4 mm, nose width SD ~3 mm, lower face height SD ~6 mm). tests/tests/fit_real.rs checks on
the training landmarks that fitted units stay mostly inside +-1.5.

The output lists, per unit, the landmark indices it influences (the "pairs" MSBP's steps 2 and 3 use),
and a triangulation of the 68 points (Delaunay of the frontal projection, minus triangles spanning
the open mouth and eyes) for drawing a mesh.
"""
import argparse, json, os
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
DEFAULT_MEAN = os.path.join(HERE, "../../../../shared/data/reference/mean_face_68/yinguobing_model68_3d.txt")
MIRROR = [16, 15, 14, 13, 12, 11, 10, 9, 8, 7, 6, 5, 4, 3, 2, 1, 0,
          26, 25, 24, 23, 22, 21, 20, 19, 18, 17,
          27, 28, 29, 30, 35, 34, 33, 32, 31,
          45, 44, 43, 42, 47, 46, 39, 38, 37, 36, 41, 40,
          54, 53, 52, 51, 50, 49, 48, 59, 58, 57, 56, 55,
          64, 63, 62, 61, 60, 67, 66, 65]

R_EYE, L_EYE = list(range(36, 42)), list(range(42, 48))
R_BROW, L_BROW = list(range(17, 22)), list(range(22, 27))
OUTER_LIP, INNER_LIP = list(range(48, 60)), list(range(60, 68))
JAW = list(range(17))
NOSE_BASE = list(range(31, 36))


def unit(mean, fn):
    d = np.zeros_like(mean)
    fn(d)
    return d


def build(mean):
    m = mean
    x, y = m[:, 0], m[:, 1]
    units = {}
    # --- shape units ---------------------------------------------------------------------------
    def eyes_height(d):  # eye opening: upper lids up, lower lids down (1.5 mm each)
        for i in (37, 38, 43, 44): d[i, 1] -= 1.5
        for i in (40, 41, 46, 47): d[i, 1] += 1.5
    def eyes_separation(d):  # each eye moves outwards 3.5 mm (IPD SD ~3.5 mm, so +-1 = +-2 SD)
        for i in R_EYE: d[i, 0] -= 3.5
        for i in L_EYE: d[i, 0] += 3.5
    def eyes_vertical(d):  # both eyes (and only them) move down 4 mm
        for i in R_EYE + L_EYE: d[i, 1] += 4.0
    def eyes_width(d):  # outer corners outwards 2 mm, inner corners inwards 1 mm, lids interpolate
        for eye, outer, inner, s in ((R_EYE, 36, 39, -1.0), (L_EYE, 45, 42, 1.0)):
            xo, xi = x[outer], x[inner]
            for i in eye:
                t = (x[i] - xi) / (xo - xi)  # 0 at inner corner, 1 at outer
                d[i, 0] += s * (2.0 * t - 1.0 * (1 - t))
    def face_length(d):  # everything below the lowest eye point stretches down: 9 mm at the chin
        y_eyes, y_chin = y[36:48].max(), y[8]
        for i in range(68):
            if y[i] > y_eyes:
                d[i, 1] += 9.0 * (y[i] - y_eyes) / (y_chin - y_eyes)
    def face_roundness(d):  # lower jaw contour bulges outwards, most at the jaw angles (5 mm)
        y_top, y_chin = y[0], y[8]
        for i in JAW:
            t = (y[i] - y_top) / (y_chin - y_top)  # 0 at the temples, 1 at the chin
            w = np.sin(np.pi * np.clip(t, 0, 1)) ** 1.5
            d[i, 0] += np.sign(x[i]) * 5.0 * w
    def lip_thickness(d):  # outer lip contour away from the lip line by 2 mm (upper up, lower down)
        for i in (49, 50, 51, 52, 53): d[i, 1] -= 2.0
        for i in (55, 56, 57, 58, 59): d[i, 1] += 2.0
    def mouth_vertical(d):  # whole mouth down 4 mm
        for i in OUTER_LIP + INNER_LIP: d[i, 1] += 4.0
    def mouth_width(d):  # corners outwards 4 mm, the other lip points proportionally to x
        xc = x[54]
        for i in OUTER_LIP + INNER_LIP: d[i, 0] += 4.0 * x[i] / xc
    def nose_width(d):  # alar base outwards 3 mm
        for i, a in ((31, 3.0), (32, 1.5), (34, 1.5), (35, 3.0)):
            d[i, 0] += np.sign(x[i]) * a
    def nose_z(d):  # nose protrudes 6 mm more at the tip (towards the camera: -z)
        for i, a in ((27, 1.0), (28, 2.5), (29, 4.0), (30, 6.0), (31, 2.0), (32, 3.0), (33, 4.0), (34, 3.0), (35, 2.0)):
            d[i, 2] -= a
    for name, fn in (("eyes_height", eyes_height), ("eyes_separation_distance", eyes_separation),
                     ("eyes_vertical_position", eyes_vertical), ("eyes_width", eyes_width),
                     ("face_length", face_length), ("face_roundness", face_roundness),
                     ("lip_thickness", lip_thickness), ("mouth_vertical_position", mouth_vertical),
                     ("mouth_width", mouth_width), ("nose_width", nose_width),
                     ("nose_z_extension", nose_z)):
        units.setdefault("shape", []).append((name, unit(m, fn)))

    # --- animation units -----------------------------------------------------------------------
    def open_mouth(d):  # jaw drop: lower lip 12 mm, chin 10 mm, jaw contour fading towards the ears
        for i in (55, 56, 57, 58, 59, 65, 66, 67): d[i, 1] += 12.0
        for i in (60, 64): d[i, 1] += 4.0
        for i in (48, 54): d[i, 1] += 3.0
        for i in range(3, 14):
            d[i, 1] += 10.0 * np.cos((i - 8) / 5.0 * np.pi / 2) ** 2
    def brow(idx, outer):
        def f(d):  # outer brow end up 8 mm, inner end 3 mm
            xo, xi = x[outer], x[idx[0] if outer == idx[-1] else idx[-1]]
            for i in idx:
                t = (x[i] - xi) / (xo - xi)
                d[i, 1] -= 3.0 + 5.0 * t
        return f
    def nose_wrinkler(d):
        # "raise nose bridge" implemented as the nose wrinkler / upper-lip raiser (AU9/10): nose base
        # and upper lip rise 3 mm, inner brows lower 2 mm. Chosen over the lip-corner depressor because
        # the smile and stretch units already span the lip corners, while nothing else moves the nose.
        for i in NOSE_BASE: d[i, 1] -= 3.0
        for i in (49, 50, 51, 52, 53, 61, 62, 63): d[i, 1] -= 3.0
        for i in (21, 22): d[i, 1] += 2.0
    def smile(d):  # lip corners out 5 mm, up 5 mm, back 3 mm; neighbours follow by half
        for i, a in ((48, 1.0), (60, 1.0), (54, 1.0), (64, 1.0), (49, 0.5), (59, 0.5), (53, 0.5), (55, 0.5)):
            d[i] += a * np.array([np.sign(x[i]) * 5.0, -5.0, 3.0])
    def stretch(d):  # lips stretch sideways 5 mm at the corners and thin 1 mm each
        xc = x[54]
        for i in OUTER_LIP + INNER_LIP: d[i, 0] += 5.0 * x[i] / xc
        for i in (49, 50, 51, 52, 53): d[i, 1] += 1.0
        for i in (55, 56, 57, 58, 59): d[i, 1] -= 1.0
    for name, fn in (("open_mouth", open_mouth), ("raise_left_outer_eyebrow", brow(L_BROW, 26)),
                     ("raise_nose_bridge", nose_wrinkler), ("raise_right_outer_eyebrow", brow(R_BROW, 17)),
                     ("smile", smile), ("stretch_lips", stretch)):
        units.setdefault("animation", []).append((name, unit(m, fn)))
    return units


def triangles(mean):
    from scipy.spatial import Delaunay
    tri = Delaunay(mean[:, :2]).simplices
    holes = [set(R_EYE), set(L_EYE), set(INNER_LIP)]
    keep = [t for t in tri if not any(set(t.tolist()) <= h for h in holes)]
    return sorted(sorted(int(i) for i in t) for t in keep)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--mean", default=DEFAULT_MEAN)
    ap.add_argument("--out", default=os.path.join(HERE, "face_model.json"))
    a = ap.parse_args()
    raw = np.loadtxt(a.mean).reshape(3, 68).T
    mir = raw[MIRROR] * np.array([-1.0, 1.0, 1.0])
    mean = 0.5 * (raw + mir)
    origin = np.array([0.0, mean[27, 1], mean[36:48, 2].mean()])
    mean = mean - origin
    units = build(mean)
    out = {
        "format": "monotrack-face-model",
        "version": 1,
        "units_mm": True,
        "source": "mean: yinguobing/head-pose-estimation model68_3d (MIT), symmetrised; units: hand-designed (build.py)",
        "mean": [[round(float(v), 4) for v in p] for p in mean],
        "shape_units": [{"name": n, "landmarks": [int(i) for i in np.nonzero(np.abs(d).sum(1) > 1e-9)[0]],
                         "displacement": [[round(float(v), 4) for v in p] for p in d]} for n, d in units["shape"]],
        "animation_units": [{"name": n, "landmarks": [int(i) for i in np.nonzero(np.abs(d).sum(1) > 1e-9)[0]],
                             "displacement": [[round(float(v), 4) for v in p] for p in d]} for n, d in units["animation"]],
        "triangles": triangles(mean),
    }
    with open(a.out, "w") as f:
        json.dump(out, f, separators=(",", ":"))
        f.write("\n")
    print(f"wrote {a.out}: {len(out['shape_units'])} shape units, {len(out['animation_units'])} animation units, "
          f"{len(out['triangles'])} triangles")


if __name__ == "__main__":
    main()

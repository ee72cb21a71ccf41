"""Faces turned in yaw, made from annotated faces: 3D-aware augmentation.

faces68 is 92.6 % frontal, so level 1's yaw classes past 30° and every zone net see few turned
faces. This makes more of them, the way 300W-LP was made from 300-W: the deformable face model
(`core/models/face_model/face_model.json`: the mean face, its shape and animation units) is fitted
to each annotated face, which gives every landmark a depth; the face is then turned about a
vertical axis through the head and re-rendered by a piecewise-affine warp of a mesh made of the
landmarks, points on the forehead and two rings of points around the head that stay where they
are (the head's outline and the background). The landmarks move with the model.

Conventions: image x right, y down, depth z away from the camera (the face model's frame).
A positive turn moves the nose towards image x > 0, which is a *negative* change of yaw in the
CONTRACT's convention that `m3data.pnp_yaw` and the MediaPipe teacher use (checked by `--check`).

Yaw labels: the source face's label (the teacher's, else PnP) plus the change of yaw a PnP fit of
the mean face reads between the source points and the turned points, in the same crop. The turn's
nominal angle overstates it: PnP reads 0.81 × the nominal change on these faces, while on the
annotated faces it reads 0.97 × the teacher's yaw, so nominal labels would call a face "45°" that
the teacher would call about 37°, and a level 1 trained on them put real half-profiles (teacher
30–60°) into the frontal class (recall 5 of 6 → 1 of 6 on the validation split).

Limits, stated where they matter: the far side's jaw contour is the model's contour turned, not the
silhouette an annotator would trace past about 45°; hair, ears and the neck are warped as the
rings warp them, not modelled; the face's texture on the far side is squeezed, never invented.

Run by train_m3.py when a net that learns from turned faces trains (the cache is rebuilt when
absent); alone: `python3 core/models/train/rotate_faces.py [--out DIR] [--sheet PNG] [--check]`.
"""

import argparse
import json
import os
import sys

import cv2
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import m3data as D  # noqa: E402

SEED = 20261128
# Turns per training face, each away from frontal on both sides over the turned classes: one into
# the ±30° class (|yaw| 30..60) and one past 60°.
TARGET_YAW_BANDS = ((34.0, 58.0), (62.0, 78.0))
# Faces within this of frontal are turned either way, others only further their own way.
FRONTAL_DEG = 8.0
# The largest turn (degrees, nominal): past it the far side of the face is mostly squeezed texture.
MAX_TURN = 60.0
# Nominal turn per degree of change of yaw as PnP reads it (module docstring).
TURN_PER_DEG = 1.0 / 0.81
# Pitch added to each turn (degrees, uniform ±): heads that turn also nod a little.
PITCH_JITTER = 8.0
# The head's turning axis in the face model's frame (mm): behind the face, between the ears.
PIVOT_MM = np.array([0.0, 20.0, 70.0])
# Rings of fixed points around the face, in units of the face's half-extent from its centre.
RINGS = (1.35, 2.2)
RING_POINTS = 20
# The stored crop: this many face-box sides, at most this many pixels a side.
CROP_BOXES = 3.0
CROP_MAX = 480
# Shape and animation units' ridge (in units of their squared extents): the fit explains the
# annotation with a plausible face, not with every annotation's noise.
RIDGE = 2.0


def default_dir():
    return os.path.join(D.REPO, "target", "m3-train-cache", "rotated")


def load_model():
    m = json.load(open(os.path.join(D.REPO, "core", "models", "face_model", "face_model.json")))
    mean = np.array(m["mean"], float)
    units = []
    for u in m["shape_units"] + m["animation_units"]:
        d = np.zeros((68, 3))
        disp = np.array(u["displacement"], float)
        if disp.shape == (68, 3):
            d = disp
        else:
            d[u["landmarks"]] = disp
        units.append(d)
    return mean, np.array(units)


def fit(pts, mean, units):
    """Weak-perspective fit of the face model to 68 image points: (scale, rotation 3x3, translation
    2, model points 68x3 in mm). Alternates an affine camera made orthonormal with a ridge solve of
    the units."""
    X = mean.copy()
    K = len(units)
    for _ in range(8):
        A = np.concatenate([X, np.ones((68, 1))], axis=1)
        P, *_ = np.linalg.lstsq(A, pts, rcond=None)
        M = P[:3].T
        U, S, Vt = np.linalg.svd(M, full_matrices=False)
        R2 = U @ Vt
        s = S.mean()
        r3 = np.cross(R2[0], R2[1])
        R = np.vstack([R2, r3])
        t = pts.mean(0) - s * (X @ R2.T).mean(0)
        J = np.stack([(s * (units[k] @ R2.T)).ravel() for k in range(K)])
        b = (pts - s * (mean @ R2.T) - t).ravel()
        reg = RIDGE * np.diag((J ** 2).sum(1)) / 68.0
        a = np.linalg.solve(J @ J.T + reg, J @ b)
        X = mean + np.tensordot(a, units, axes=1)
    return s, R, t, X


def project(s, R, t, X):
    """Model points (mm) → image (x, y) and depth z, pixels."""
    c = s * (X @ R.T)
    return c[:, :2] + t, c[:, 2]


def turn_points(xy, z, pivot_xy, pivot_z, yaw_deg, pitch_deg):
    """Points (image x, y, depth z) turned about the camera's vertical axis through the pivot by
    yaw_deg (nose towards +x for positive), then about its horizontal axis by pitch_deg."""
    a, b = np.radians(yaw_deg), np.radians(pitch_deg)
    dx, dy, dz = xy[:, 0] - pivot_xy[0], xy[:, 1] - pivot_xy[1], z - pivot_z
    x1 = np.cos(a) * dx - np.sin(a) * dz
    z1 = np.sin(a) * dx + np.cos(a) * dz
    y2 = np.cos(b) * dy - np.sin(b) * z1
    z2 = np.sin(b) * dy + np.cos(b) * z1
    return np.stack([x1 + pivot_xy[0], y2 + pivot_xy[1]], axis=1), z2 + pivot_z


def delaunay(points, w, h):
    """Delaunay triangles of `points` (indices); duplicates keep their first index."""
    sub = cv2.Subdiv2D((-w, -h, 3 * w, 3 * h))
    for p in points:
        sub.insert((float(p[0]), float(p[1])))
    tris = []
    for t in sub.getTriangleList():
        v = t.reshape(3, 2)
        d = np.linalg.norm(points[None, :, :] - v[:, None, :], axis=2)
        ids = d.argmin(1)
        if d[np.arange(3), ids].max() < 1e-2 and len(set(ids)) == 3:
            tris.append(ids)
    return np.array(tris, int).reshape(-1, 3)


def cross2(u, v):
    return float(u[0] * v[1] - u[1] * v[0])


def render(img, src, dst, depth, tris):
    """Piecewise-affine warp of `img`: each triangle from src to dst, far ones first; triangles
    that flip (turned away) are left out. Where nothing is drawn the source stays."""
    out = img.copy()
    h, w = img.shape
    order = np.argsort(-depth[tris].mean(1))
    for ti in order:
        s, d = src[tris[ti]].astype(np.float32), dst[tris[ti]].astype(np.float32)
        area_s = cross2(s[1] - s[0], s[2] - s[0])
        area_d = cross2(d[1] - d[0], d[2] - d[0])
        if abs(area_d) < 0.5 or np.sign(area_s) != np.sign(area_d):
            continue
        x0, y0 = np.floor(d.min(0)).astype(int)
        x1, y1 = np.ceil(d.max(0)).astype(int) + 1
        x0, y0, x1, y1 = max(x0, 0), max(y0, 0), min(x1, w), min(y1, h)
        if x1 <= x0 or y1 <= y0:
            continue
        M = cv2.getAffineTransform((d - [x0, y0]).astype(np.float32), s)
        patch = cv2.warpAffine(img, M, (x1 - x0, y1 - y0), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                               borderMode=cv2.BORDER_REFLECT)
        mask = np.zeros((y1 - y0, x1 - x0), np.uint8)
        cv2.fillConvexPoly(mask, np.round((d - [x0, y0]) * 16).astype(np.int32), 1, cv2.LINE_AA, 4)
        region = out[y0:y1, x0:x1]
        region[mask > 0] = patch[mask > 0]
    return out


def turned_face(img, pts, yaw_deg, pitch_deg, model):
    """One annotated face turned: (crop, its 68 points in the crop, the fit's residual per point in
    units of the outer-eye distance, the change of yaw PnP reads)."""
    mean, units = model
    # Crop first: a square of CROP_BOXES face boxes, at most CROP_MAX a side.
    (x, y, w, h) = D.box_of(pts)
    c, side = D.square_of_box((x, y, w, h))
    side *= CROP_BOXES
    n = int(min(CROP_MAX, round(side)))
    k = side / n
    A = np.array([[k, 0, c[0] - side / 2], [0, k, c[1] - side / 2]])
    crop = D.sample(img, A, n, n)
    p = D.apply(D.invert(A), pts.astype(float))
    s, R, t, X = fit(p, mean, units)
    fxy, z = project(s, R, t, X)
    resid = np.linalg.norm(fxy - p, axis=1).mean() / D.outer_eye_distance(p)
    # Forehead: the brows raised 35 mm and set back 12 mm in the model.
    fore = X[17:27] + [0.0, -35.0, 12.0]
    fore_xy, fore_z = project(s, R, t, fore)
    pv_xy, pv_z = project(s, R, t, PIVOT_MM[None, :])
    pv_xy, pv_z = pv_xy[0], pv_z[0]
    face_xy = np.concatenate([p, fore_xy])
    face_z = np.concatenate([z, fore_z])
    centre = face_xy.mean(0)
    half = np.abs(face_xy - centre).max(0)
    th = np.linspace(0, 2 * np.pi, RING_POINTS, endpoint=False)
    rings = [centre + np.stack([r * half[0] * np.cos(th), r * half[1] * np.sin(th)], 1) for r in RINGS]
    edge = np.linspace(0, n, 5)
    border = np.array([[u, v] for u in edge for v in edge if u in (0, n) or v in (0, n)], float)
    fixed = np.concatenate(rings + [border])
    new_xy, new_z = turn_points(face_xy, face_z, pv_xy, pv_z, yaw_deg, pitch_deg)
    src = np.concatenate([face_xy, fixed])
    dst = np.concatenate([new_xy, fixed])
    depth = np.concatenate([new_z, np.full(len(fixed), pv_z + 10 * s)])
    tris = delaunay(src, n, n)
    out = render(crop, src, dst, depth, tris)
    dyaw = D.pnp_yaw(new_xy[:68].astype(np.float64), n, n) - D.pnp_yaw(p.astype(np.float64), n, n)
    return out, new_xy[:68], resid, dyaw


def build(out_dir=None, split="train", seed=SEED, limit=None):
    """Writes the turned faces of `split` to out_dir (PNG crops + index.jsonl) and returns the
    index path. Deterministic for a seed."""
    out_dir = out_dir or default_dir()
    os.makedirs(out_dir, exist_ok=True)
    model = load_model()
    paths, faces = D.load_faces68(split)
    rng = np.random.default_rng(seed)
    index = os.path.join(out_dir, f"{split}.jsonl")
    imgs = {}
    n_done = 0
    with open(index + ".part", "w") as fh:
        for fi, f in enumerate(faces):
            if limit is not None and fi >= limit:
                break
            if f["image"] not in imgs:
                imgs = {f["image"]: D.load_gray(paths[f["image"]])}
            img = imgs[f["image"]]
            # Turned further the way the face already looks (either way when it looks ahead): a
            # turn towards frontal would have to show what the photo hides.
            y0 = float(f["yaw"])
            side = np.sign(y0) if abs(y0) >= FRONTAL_DEG else (1.0 if rng.random() < 0.5 else -1.0)
            for b, (lo, hi) in enumerate(TARGET_YAW_BANDS):
                target = side * rng.uniform(lo, hi)
                pitch = rng.uniform(-PITCH_JITTER, PITCH_JITTER)
                if abs(y0) >= hi or side * (target - y0) <= 0:
                    continue
                # Contract yaw grows as the nose moves to image x < 0 (module docstring).
                turn = -side * min(abs(target - y0) * TURN_PER_DEG, MAX_TURN)
                crop, pts, resid, dyaw = turned_face(img, f["pts"], turn, pitch, model)
                target = y0 + dyaw
                name = f"{split}_{f['line']:04d}_{fi:04d}_{b}.png"
                cv2.imwrite(os.path.join(out_dir, name), crop)
                fh.write(json.dumps({"image": name, "line": f["line"], "face": fi, "yaw": float(target),
                                     "source_yaw": y0, "turn": float(turn), "pitch": float(pitch),
                                     "fit_residual_iod": float(resid), "mouth": int(f["mouth"]),
                                     "brows": int(f["brows"]),
                                     "landmarks68": np.round(pts, 3).tolist()}) + "\n")
                n_done += 1
    os.replace(index + ".part", index)
    return index, n_done


def load(index):
    """(gray crops, faces) of a build()'s index: faces as m3data.load_faces68 makes them, with
    `image` indexing the returned crops and `turned` set."""
    base = os.path.dirname(index)
    imgs, faces = [], []
    for line in open(index):
        r = json.loads(line)
        img = cv2.imread(os.path.join(base, r["image"]), cv2.IMREAD_GRAYSCALE)
        faces.append({"image": len(imgs), "line": r["line"], "path": r["image"],
                      "pts": np.array(r["landmarks68"], np.float32), "yaw": r["yaw"],
                      "yaw_class": D.yaw_class(r["yaw"]), "mouth": r["mouth"], "brows": r["brows"],
                      "gaze": None, "turned": True})
        imgs.append(img)
    return imgs, faces


def contact_sheet(index, path, n=24):
    imgs, faces = load(index)
    tiles = []
    for img, f in list(zip(imgs, faces))[:n]:
        t = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
        for q in f["pts"]:
            cv2.circle(t, (int(q[0]), int(q[1])), 2, (0, 255, 0), -1)
        cv2.putText(t, f"{f['yaw']:.0f}", (5, 25), cv2.FONT_HERSHEY_SIMPLEX, 0.8, (0, 0, 255), 2)
        tiles.append(cv2.resize(t, (240, 240)))
    while len(tiles) % 6:
        tiles.append(np.zeros_like(tiles[0]))
    rows = [np.hstack(tiles[i:i + 6]) for i in range(0, len(tiles), 6)]
    cv2.imwrite(path, np.vstack(rows))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default=None)
    ap.add_argument("--split", default="train")
    ap.add_argument("--limit", type=int, default=None)
    ap.add_argument("--sheet", default=None, help="write a contact sheet of the first turned faces")
    ap.add_argument("--check", action="store_true", help="compare the labelled yaw with a PnP fit of the turned points")
    a = ap.parse_args()
    cv2.setNumThreads(1)
    index, n = build(a.out, a.split, limit=a.limit)
    print(f"{n} turned faces -> {index}")
    if a.sheet:
        contact_sheet(index, a.sheet)
    if a.check:
        imgs, faces = load(index)
        d = np.array([[f["yaw"], D.pnp_yaw(f["pts"].astype(np.float64), im.shape[1], im.shape[0])]
                      for im, f in zip(imgs, faces)])
        print("labelled vs PnP yaw: corr %.3f, median |diff| %.1f°" % (np.corrcoef(d.T)[0, 1],
                                                                    np.median(np.abs(d[:, 0] - d[:, 1]))))


if __name__ == "__main__":
    main()

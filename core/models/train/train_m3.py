#!/usr/bin/env python3
"""Trains the seven M3 networks (level 1 + six zone nets) and exports them to core/models/m3/ (ONNX opset 17 + m3.json).

    python3 core/models/train/train_m3.py [--steps-scale 1.0] [--only level1,brows,eye,mouth,face,nose,mouth_fine]

Seeds are fixed (numpy, torch, python; each net seeds itself); one CPU thread per process by default
(MONOTRACK_TRAIN_THREADS); level 1 first, then the zone nets in up to --jobs processes at once, then
m3.json's label-convention offset and shape prior from the training split (calibrate_m3.py) once every net exists.
Writes next to the weights: train_log.txt (losses per step window) and the validation metrics
(metrics.json, by eval_m3.py). Data: ../shared/data (faces68, its MediaPipe teacher, GENKI-4K);
the split rule and the preprocessing are core/models/M3_IO.md's.
"""
import argparse
import json
import os
import random
import subprocess
import sys
import time

import cv2
import numpy as np
import torch
import torch.nn.functional as F

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import m3data as D  # noqa: E402
from m3nets import Level1, Level2, n_params  # noqa: E402
import onnx_f16  # noqa: E402
import onnx_q8  # noqa: E402
import onnx_tract  # noqa: E402
import calibrate_m3  # noqa: E402
import pseudo_genki  # noqa: E402
import rotate_faces  # noqa: E402
import teacher_genki  # noqa: E402

OUT = os.environ.get("MONOTRACK_M3_OUT", os.path.join(D.REPO, "core", "models", "m3"))
SEED = 20261122
# Landmark coordinates (crop/patch units 0..1) are scaled by this before the landmark loss so its size
# is comparable with the cross-entropy terms (eq. 3.3's weighting). The loss is the point-to-point
# (Euclidean) distance rather than eq. 3.3's squared distance: NME averages distances, and the L2 fit
# measured worse on the validation split (level 1 alone: 8.2 % NME).
LM_SCALE = 10.0
YAW_WEIGHT = 0.5
FACE_WEIGHT = 0.5
# Share of level 1's negatives that are one of the shipped detector's false positives on the
# training images (m3data.detector_false_positives): without them level 1 rejected crops drawn around
# faces but passed face-like things the detector fires on (the astronaut's helmet visor, at 0.97).
HARD_NEGATIVE_P = 0.3
GESTURE_WEIGHT = 0.5
GAZE_WEIGHT = 1.0
WEIGHT_DECAY = 1e-4
BATCH = 64
# Nets that also learn from GENKI-4K crops labelled by the PFLD teacher (pseudo_genki.py), and their
# share of those nets' batches. The face zone (jaw + nose) overfits faces68 (training-split NME: jaw
# 3.4 % against 7.9 % on validation); with the teacher's faces its validation jaw NME fell 7.93 ->
# 7.70 % (the 64x64 zone, before the level-1 blend; RESEARCH_LOG.md).
PSEUDO_NETS = ("face",)
PSEUDO_SHARE = 0.4
# Nets that also learn from faces turned in yaw by the face model (rotate_faces.py: two per training
# face, one into the ±30° yaw class, one past 60°), and their share of those nets' batches. None by
# default: the shipped nets do not. Level 1 with them at a share of 0.1 predicts the turned classes
# on turned validation faces (past 60°: 25 of 39 and 23 of 32, against none) at the same NME on the
# real ones (3.98 %), but it put 8 of the 9 real validation faces the teacher sees at 30–60° into
# the frontal class (the shipped level 1: 3); share 0.2 and the face zone with them at 0.25 cost
# real-face NME (4.02 and 4.09 %). RESEARCH_LOG.md, "Turned faces".
TURNED_NETS = ()
TURNED_SHARE = 0.1
# Gesture nets that also learn from GENKI-4K crops labelled by the MediaPipe teacher
# (teacher_genki.py, the thresholds of faces68's labels): gesture loss only, the crops carry no
# landmark truth. The mouth's crops keep the teacher's class only where it agrees with GENKI's own
# smile label (smile against not-smile). None by default: the brow net gained gesture F1 with them
# on two seeds but the tracker with it lost correct frames, the mouth gained nothing consistent
# (RESEARCH_LOG.md, "Measured and not adopted").
GENKI_GESTURE_NETS = ()
# Gesture nets that also regress the teacher's continuous scores behind their classes
# (m3data.gesture_scores) from the features the gesture head reads, weighted by SCORE_WEIGHT (mean
# squared error on 0..1 scores), in a head used in training only (not exported). The classes are
# thresholds on these scores, so a face near a threshold teaches the features as much as one far
# from it. The mouth gained gesture F1 on two seeds (0.680 -> 0.754, 0.646 -> 0.735 on the
# validation faces); the brow net gained less and, retrained so, cost the tracker correct frames
# (RESEARCH_LOG.md, "Measured and not adopted").
SCORE_NETS = ("mouth",)
SCORE_WEIGHT = 10.0
# Zone nets that regress the teacher's head yaw and pitch (/ 60°) the same way (SCORE_WEIGHT, a
# training-only head): where the jaw's contour lies depends on the turn. None by default.
POSE_NETS = ()
# Zone nets that also locate, in a training-only head, the 68 points outside their zone that fall
# in their patch's frame (point loss × AUX_POINT_WEIGHT): more tasks on the same features, as the
# face zone's nose outputs help its jaw. None by default.
AUX_POINT_NETS = ()
AUX_POINT_WEIGHT = 0.5
# Share of training patches smeared by a motion blur (motion_blur) whose length is drawn up to
# 2 × MOTION_BLUR_MAX_PX image pixels: a phone frame of a fast face. 0 in the shipped nets: at 0.3
# fewer blurred faces were lost in tracking but sharp faces' NME rose (RESEARCH_LOG.md, "Measured
# and not adopted").
MOTION_BLUR_P = 0.0
MOTION_BLUR_MAX_PX = 4.0
# Share of level 1's crops smeared the same way for its face / not-face output only (their
# landmarks and yaw are not learned from): a tracked face is lost when the check fails on a
# blurred frame, while blur in the landmark loss costs sharp faces' accuracy. 0 in the shipped net.
FACE_BLUR_P = 0.0
# Zone nets whose training patches are partly covered, with probability OCCLUDER_P, by a textured
# occluder (occlude_patch: an ellipse of another training image's pixels, as a hand, a microphone
# or hair over the face), and that share. None by default.
OCCLUDER_NETS = ()
OCCLUDER_P = 0.2
# Zone nets whose point loss is the wing loss (Feng et al. 2018) of each point's distance instead
# of the distance itself: ω·ln(1 + d/ε) below ω patch pixels, d − C above, so errors of a pixel
# or two, most of the jaw's, pull several times harder than with the plain distance. ω and ε in
# pixels of the patch's larger side (the paper's 10 and 2 on 128 px, scaled to about 48). None
# by default.
WING_NETS = ()
WING_W = 4.0
WING_EPS = 0.8
# Trunks (m3nets.trunk spec strings) of the shipped models; --level1-trunk / --zone-trunk override
# them for experiments.
LEVEL1_TRUNK = "16s-32s-48s-48c-64s"
LEVEL1_HIDDEN = 128
ZONE_TRUNK = {"eye": "8s-16s-16c-32s", "face": "16s-32s-48s-48c-96s", "mouth_fine": "8s-16s-32s-32c-32s",
              "default": "8s-16s-32s-32c-48s"}
STEPS = {"level1": 15000, "brows": 10000, "eye": 10000, "mouth": 12500, "face": 15000, "nose": 10000,
         "mouth_fine": 10000}
# The mouth's 5 (20261127) is the second of the two seeds its score head was trained with, the one
# with the lower validation NME (RESEARCH_LOG.md, "Teacher scores for the gesture features").
ZONE_SEED = {"brows": 2, "eye": 3, "mouth": 5, "face": 5, "nose": 6, "mouth_fine": 7}
# Standard deviation of the Gaussian jitter of a zone's two reference points in training, in units of
# the outer-eye-corner distance (zone_sample): the size of the reference errors the net must absorb.
REF_NOISE = {"default": 0.045}
# Probability per net of a lower-face shape warp on a training patch (zone_sample), e.g.
# --shape-warp face=0.5; none by default. Ranges: widening at the patch bottom, vertical stretch.
SHAPE_WARP = {}
SHAPE_WARP_WIDEN = 0.15
SHAPE_WARP_STRETCH = 0.1
DEVICE = torch.device("cpu")
# Weight averaging (exponential moving average of the weights and BN statistics); 0 = the last weights.
EMA_DECAYS = ()


class Data:
    """faces68 training images (and their mirror images), faces with labels in both; then the
    teacher-labelled faces (`pseudo`) and the turned faces (`turned`, rotate_faces.py) when given.
    Each group is a contiguous run of `faces`: annotated, pseudo, turned."""

    def __init__(self, split, pseudo=None, turned=None):
        paths, faces = D.load_faces68(split)
        self.imgs = [D.load_gray(p) for p in paths]
        self.paths, self.labelled = list(paths), list(faces)
        groups = [("annotated", len(faces))]
        if pseudo:
            # Teacher-labelled faces (pseudo_genki.py): 68 points, no other label; only the nets in
            # PSEUDO_NETS sample them (PSEUDO_SHARE of their batches).
            for line in open(pseudo):
                r = json.loads(line)
                pts = np.array(r["faces"][0]["pfld"], np.float32)
                img = D.load_gray(r["image"])
                yaw = D.pnp_yaw(pts.astype(np.float64), img.shape[1], img.shape[0])
                faces.append({"image": len(self.imgs), "line": -1, "path": r["image"], "pts": pts, "yaw": yaw,
                              "yaw_class": D.yaw_class(yaw), "mouth": -1, "brows": -1, "gaze": None,
                              "pseudo": True})
                self.imgs.append(img)
            groups.append(("pseudo", len(faces) - sum(n for _, n in groups)))
        if turned:
            # Turned faces (rotate_faces.py): the nets in TURNED_NETS sample them (TURNED_SHARE).
            imgs, tfaces = rotate_faces.load(turned)
            for f in tfaces:
                f["image"] += len(self.imgs)
            self.imgs += imgs
            faces += tfaces
            groups.append(("turned", len(tfaces)))
        self.faces = []
        for f in faces:
            self.faces.append(dict(f, mirror=False))
            img = self.imgs[f["image"]]
            W = img.shape[1]
            m = dict(f, mirror=True)
            pts = f["pts"].copy()
            pts[:, 0] = W - pts[:, 0]
            m["pts"] = pts[D.MIRROR68]
            m["yaw"] = -f["yaw"]
            m["yaw_class"] = 4 - f["yaw_class"]
            if f.get("pose") is not None:
                m["pose"] = f["pose"] * np.array([-1.0, 1.0], np.float32)
            if f["gaze"] is not None:
                r, l = f["gaze"]
                m["gaze"] = (l * [-1, 1, 1], r * [-1, 1, 1])
            self.faces.append(m)
        self.mirrored = [np.ascontiguousarray(im[:, ::-1]) for im in self.imgs]
        # group name -> (start, end) in self.faces (mirrors included).
        self.groups, start = {}, 0
        for name, n in groups:
            self.groups[name] = (start, start + 2 * n)
            start += 2 * n
        self.n_annotated = self.groups["annotated"][1]
        self.hard = []  # (image index, box) of detector false positives, by mine_hard_negatives

    def groups_for(self, net):
        """The groups `net` samples: the annotated faces, plus the teacher-labelled ones for
        PSEUDO_NETS and the turned ones for TURNED_NETS. A net that samples only the annotated
        faces draws the same batches as without the other groups."""
        out = ["annotated"]
        if net in PSEUDO_NETS and "pseudo" in self.groups:
            out.append("pseudo")
        if net in TURNED_NETS and "turned" in self.groups:
            out.append("turned")
        return out

    def faces_for(self, net):
        """The faces `net` samples (groups_for), in order."""
        return [f for g in self.groups_for(net) for f in self.faces[slice(*self.groups[g])]]

    def mix(self, weights, net):
        """Sampling weights over faces_for(net): the teacher-labelled faces get PSEUDO_SHARE, the
        turned ones TURNED_SHARE, the annotated ones the rest."""
        groups = self.groups_for(net)
        if len(groups) == 1:
            return weights
        share = {"pseudo": PSEUDO_SHARE, "turned": TURNED_SHARE}
        share["annotated"] = 1.0 - sum(share[g] for g in groups[1:])
        out, i = [], 0
        for g in groups:
            a, b = self.groups[g]
            w = weights[i:i + b - a]
            out.append(w * share[g] / w.sum())
            i += b - a
        return np.concatenate(out)

    def mine_hard_negatives(self):
        self.hard = D.detector_false_positives(self.paths, self.labelled)
        return len(self.hard)

    def image(self, f):
        return self.mirrored[f["image"]] if f["mirror"] else self.imgs[f["image"]]


def motion_blur(p, rng, k):
    """A box blur along a random direction, `k` patch pixels long (k ≥ 2): a moving face's smear
    in a phone frame, as `track_eval --blur` makes it."""
    n = int(np.ceil(k)) | 1
    kern = np.zeros((n, n), np.float32)
    a = rng.uniform(0, np.pi)
    c = (n - 1) / 2
    for t in np.linspace(-k / 2, k / 2, 4 * n):
        x, y = int(round(c + t * np.cos(a))), int(round(c + t * np.sin(a)))
        kern[y, x] = 1.0
    return cv2.filter2D(p, -1, kern / kern.sum(), borderType=cv2.BORDER_REPLICATE)


def smear(p, rng, scale):
    """`p` (float) smeared by a motion blur whose length is drawn up to 2 × MOTION_BLUR_MAX_PX image
    pixels (`scale`: image pixels per patch pixel), and whether it was: a smear under 1.5 patch
    pixels is left out."""
    k = rng.uniform(2.0, 2.0 * MOTION_BLUR_MAX_PX) / scale
    return (motion_blur(p, rng, k), True) if k >= 1.5 else (p, False)


def photometric(p, rng, occlude=True, scale=1.0):
    """Illumination, blur, noise and occlusion on a patch; `scale`: image pixels per patch pixel
    (the motion blur's length is drawn in image pixels)."""
    p = p.astype(np.float32)
    if MOTION_BLUR_P > 0 and rng.random() < MOTION_BLUR_P:
        p, _ = smear(p, rng, scale)
    # illumination: contrast, brightness, gamma, a linear gradient
    p = p * rng.uniform(0.6, 1.4) + rng.uniform(-40, 40)
    if rng.random() < 0.3:
        h, w = p.shape
        gx = np.linspace(-1, 1, w)[None, :] * rng.uniform(-40, 40)
        gy = np.linspace(-1, 1, h)[:, None] * rng.uniform(-40, 40)
        p = p + gx + gy
    p = np.clip(p, 0, 255)
    if rng.random() < 0.3:
        p = 255.0 * (p / 255.0) ** rng.uniform(0.6, 1.6)
    if rng.random() < 0.25:
        k = rng.choice([3, 5])
        p = cv2.GaussianBlur(p, (k, k), 0)
    if rng.random() < 0.4:
        p = p + rng.normal(0, rng.uniform(2, 10), p.shape)
    if occlude and rng.random() < 0.1:
        h, w = p.shape
        ow, oh = int(w * rng.uniform(0.15, 0.45)), int(h * rng.uniform(0.15, 0.45))
        x0, y0 = rng.integers(0, w - ow + 1), rng.integers(0, h - oh + 1)
        p[y0:y0 + oh, x0:x0 + ow] = rng.uniform(0, 255) if rng.random() < 0.5 else rng.uniform(0, 255, (oh, ow))
    return np.clip(np.floor(p + 0.5), 0, 255).astype(np.uint8)


def balanced_weights(labels, n):
    labels = np.asarray(labels)
    counts = np.bincount(labels[labels >= 0], minlength=n).astype(float)
    w = np.ones(len(labels))
    for c in range(n):
        if counts[c] > 0:
            w[labels == c] = 1.0 / counts[c] ** 0.5  # square root: balance without overfitting rare classes
    return w / w.sum()


def level1_batch(data, faces, rng, weights):
    S, cs = D.LEVEL1["input_size"], D.LEVEL1["crop_scale"]
    X = np.zeros((BATCH, 1, S, S), np.float32)
    Y = np.zeros((BATCH, 64), np.float32)
    yaw = np.zeros(BATCH, np.int64)
    face = np.zeros(BATCH, np.float32)
    sharp = np.ones(BATCH, np.float32)
    idx = rng.choice(len(weights), BATCH, p=weights)
    for k, i in enumerate(idx):
        f = faces[i]
        img = data.image(f)
        c, s = D.square_of_box(D.box_of(f["pts"]))
        s *= np.exp(rng.uniform(-0.15, 0.15))
        c = c + rng.uniform(-0.1, 0.1, 2) * s
        angle = np.radians(rng.uniform(-25, 25)) if rng.random() < 0.4 else 0.0
        positive = rng.random() > 0.25
        if not positive and data.hard and rng.random() < HARD_NEGATIVE_P:
            # A detector false positive, at the detector's box (± as a tracker's), either way round.
            j, (x, y, w, h) = data.hard[int(rng.integers(len(data.hard)))]
            img = data.imgs[j]
            if rng.random() < 0.5:
                img, x = data.mirrored[j], img.shape[1] - x - w
            c, s = D.square_of_box((x, y, w, h))
            s *= np.exp(rng.uniform(-0.1, 0.1))
            c = c + rng.uniform(-0.05, 0.05, 2) * s
        elif not positive:
            c, s = D.level1_negative(c, s, img.shape, rng)
        A = D.level1_map(c, s, S, cs, angle)
        patch = photometric(D.sample(img, A, S, S), rng, scale=float(np.hypot(A[0, 0], A[1, 0])))
        if FACE_BLUR_P > 0 and rng.random() < FACE_BLUR_P:
            smeared, done = smear(patch.astype(np.float32), rng, float(np.hypot(A[0, 0], A[1, 0])))
            if done:
                patch = smeared.clip(0, 255).astype(np.uint8)
                sharp[k] = 0.0
        X[k, 0] = patch / 255.0
        pts = D.apply(D.invert(A), f["pts"][D.LEVEL1_INDICES]) / S
        Y[k] = pts.reshape(-1)
        yaw[k] = f["yaw_class"]
        face[k] = 1.0 if positive else 0.0
    t = torch.from_numpy
    return t(X), t(Y), t(yaw), t(face), t(sharp)


def soft_yaw(cls, rng):
    logits = np.zeros(5)
    logits[cls] = rng.uniform(1.0, 6.0)
    logits += rng.normal(0, 0.7, 5)
    e = np.exp(logits - logits.max())
    return e / e.sum()


def lower_face_warp(W, H, y0, a, t):
    """A smooth change of face shape below the patch's eye line y0: the lower face stretched
    vertically by t and widened by 1 + a at the patch's bottom (linearly from the eye line).
    Returns (forward map of patch points, inverse map of patch points)."""
    def widen(y):
        return 1.0 + a * np.clip((y - y0) / (H - y0), 0.0, 1.0)

    def forward(x, y):
        return W / 2 + (x - W / 2) * widen(y), np.where(y > y0, y0 + (y - y0) * t, y)

    def inverse(x, y):
        yu = np.where(y > y0, y0 + (y - y0) / t, y)
        return W / 2 + (x - W / 2) / widen(yu), yu
    return forward, inverse


def warped_sample(img, A, W, H, inverse):
    """D.sample through a non-rigid patch warp (`inverse` maps output patch points to the
    unwarped patch), in D.sample's pixel convention."""
    u, v = np.meshgrid(np.arange(W) + 0.5, np.arange(H) + 0.5)
    x, y = inverse(u, v)
    X = A[0, 0] * x + A[0, 1] * y + A[0, 2] - 0.5
    Y = A[1, 0] * x + A[1, 1] * y + A[1, 2] - 0.5
    return cv2.remap(img, X.astype(np.float32), Y.astype(np.float32), cv2.INTER_LINEAR,
                     borderMode=cv2.BORDER_REPLICATE)


def zone_sample(zone, img, pts, rng, ref_noise=0.045, aug=True, shape_warp=0.0):
    """Patch of a zone from jittered reference points (level-1 errors are a few % of the
    inter-ocular distance, so the refs move by that much in training). With probability
    `shape_warp` the lower face is reshaped (lower_face_warp): new jaw and chin shapes for a zone
    that otherwise sees 1,079 faces' worth of them."""
    iod = D.outer_eye_distance(pts)
    r0, r1 = pts[zone["ref68"][0]].astype(float), pts[zone["ref68"][1]].astype(float)
    if aug:
        r0 = r0 + rng.normal(0, ref_noise * iod, 2)
        r1 = r1 + rng.normal(0, ref_noise * iod, 2)
    A = D.zone_map(zone, r0, r1)
    W, H = zone["width"], zone["height"]
    tgt = D.apply(D.invert(A), pts[zone["indices68"]])
    if aug and shape_warp > 0 and rng.random() < shape_warp:
        y0 = zone["template"][0][1] * H
        forward, inverse = lower_face_warp(W, H, y0, rng.uniform(-SHAPE_WARP_WIDEN, SHAPE_WARP_WIDEN),
                                           rng.uniform(1 - SHAPE_WARP_STRETCH, 1 + SHAPE_WARP_STRETCH))
        patch = warped_sample(img, A, W, H, inverse)
        tgt = np.stack(forward(tgt[:, 0], tgt[:, 1]), axis=1)
    else:
        patch = D.sample(img, A, W, H)
    if aug:
        patch = photometric(patch, rng, occlude=False, scale=float(np.hypot(A[0, 0], A[1, 0])))
    patch = D.zone_filter(zone, patch)
    return patch, tgt / [W, H], A


def occlude_patch(patch, data, rng):
    """`patch` partly covered by an ellipse (15–50 % of each side, anywhere, soft-edged) of pixels
    from a random place, scale and angle of another training image, brightness-shifted at random:
    occluders with texture and edges like a face's own, which flat rectangles are not."""
    h, w = patch.shape
    src = data.imgs[rng.integers(len(data.imgs))]
    ih, iw = src.shape
    side = min(ih, iw) * rng.uniform(0.05, 0.3)
    c = np.array([rng.uniform(0, iw), rng.uniform(0, ih)])
    a = rng.uniform(-np.pi, np.pi)
    k = side / max(w, h)
    L = k * np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    A = np.concatenate([L, (c - L @ np.array([w / 2, h / 2]))[:, None]], axis=1)
    occ = D.sample(src, A, w, h).astype(np.float32) + rng.uniform(-30, 30)
    ax, ay = w * rng.uniform(0.15, 0.5) / 2, h * rng.uniform(0.15, 0.5) / 2
    cx, cy = rng.uniform(0, w), rng.uniform(0, h)
    yy, xx = np.mgrid[0:h, 0:w] + 0.5
    r = np.sqrt(((xx - cx) / ax) ** 2 + ((yy - cy) / ay) ** 2)
    m = np.clip((1.15 - r) / 0.3, 0, 1)
    out = patch.astype(np.float32) * (1 - m) + occ * m
    return np.clip(np.floor(out + 0.5), 0, 255).astype(np.uint8)


def score_head(name):
    """What net `name`'s training-only head learns, and its width: the 68 points outside its zone
    (AUX_POINT_NETS: "points", the list of those points), the head pose (POSE_NETS: "pose"), its
    gestures' teacher scores (SCORE_NETS: "gestures", m3data.gesture_scores), or nothing
    (None, 0)."""
    if name in AUX_POINT_NETS:
        others = [j for j in range(68) if j not in D.ZONES[name]["indices68"]]
        return "points", 2 * len(others), others
    if name in POSE_NETS:
        return "pose", 2, None
    if name in SCORE_NETS and D.ZONES[name].get("gestures"):
        return "gestures", 3 if name == "mouth" else 2, None
    return None, 0, None


def zone_batch(name, data, faces, rng, weights, genki=None):
    zone = D.ZONES[name]
    W, H = zone["width"], zone["height"]
    n = len(zone["indices68"])
    X = np.zeros((BATCH, 1, H, W), np.float32)
    Y = np.zeros((BATCH, 2 * n), np.float32)
    YAW = np.zeros((BATCH, 5), np.float32)
    G = np.full(BATCH, -1, np.int64)
    GZ = np.zeros((BATCH, 3), np.float32)
    GZM = np.zeros(BATCH, np.float32)
    SM = np.full(BATCH, -1.0, np.float32)  # GENKI smile label (mouth only)
    LM = np.ones(BATCH, np.float32)
    head, n_sc, others = score_head(name)
    SC = np.zeros((BATCH, n_sc), np.float32)
    SCM = np.zeros(BATCH, np.float32)
    idx = rng.choice(len(weights), BATCH, p=weights)
    n_genki = BATCH // 4 if genki is not None else 0
    for k, i in enumerate(idx):
        if k < n_genki:
            g_img, g_pts, g_label, g_mouth, g_brows = genki[rng.integers(len(genki))]
            patch, _, _ = zone_sample(zone, g_img, g_pts, rng, ref_noise=0.02)
            X[k, 0] = patch / 255.0
            LM[k] = 0.0  # predicted refs only: no landmark truth on GENKI
            if name == "mouth":
                SM[k] = g_label
                G[k] = g_mouth
            else:
                G[k] = g_brows
            YAW[k] = soft_yaw(2, rng)
            continue
        f = faces[i]
        patch, tgt, A = zone_sample(zone, data.image(f), f["pts"], rng,
                                    ref_noise=REF_NOISE.get(name, REF_NOISE["default"]),
                                    shape_warp=SHAPE_WARP.get(name, 0.0))
        if name in OCCLUDER_NETS and rng.random() < OCCLUDER_P:
            patch = occlude_patch(patch, data, rng)
        X[k, 0] = patch / 255.0
        Y[k] = tgt.reshape(-1)
        YAW[k] = soft_yaw(f["yaw_class"], rng)
        target = None
        if head == "points":
            target = (D.apply(D.invert(A), f["pts"][others]) / [W, H]).reshape(-1)
        elif head == "pose":
            target = f.get("pose")
        elif head == "gestures":
            target = f.get(name + "_scores")
        if target is not None:
            SC[k] = target
            SCM[k] = 1.0
        if name in ("mouth", "brows"):
            G[k] = f[name]
        elif name == "eye" and f["gaze"] is not None:
            g = f["gaze"][0]  # the right eye's (the mirrored faces carry the other eye here)
            # camera frame -> patch frame: undo the patch's in-plane rotation
            phi = np.arctan2(A[1, 0], A[0, 0])
            c, s = np.cos(phi), np.sin(phi)
            GZ[k] = [c * g[0] + s * g[1], -s * g[0] + c * g[1], g[2]]
            GZM[k] = 1.0
    t = torch.from_numpy
    return t(X), t(Y), t(YAW), t(G), t(GZ), t(GZM), t(SM), t(LM), t(SC), t(SCM)


def point_distances(pred, tgt, scale):
    """Each point's Euclidean distance, in `scale` per patch unit, per sample (samples × points)."""
    d = ((pred - tgt) * scale).view(pred.shape[0], -1, 2)
    return (d.pow(2).sum(2) + 1e-6).sqrt()


def point_loss(pred, tgt):
    """Sum over points of the Euclidean distance (scaled), per sample."""
    return point_distances(pred, tgt, LM_SCALE).sum(1)


def wing_point_loss(pred, tgt, side):
    """point_loss with each distance through the wing loss (WING_NETS); `side`: patch pixels per
    patch unit. Linear above WING_W pixels with point_loss's slope, so large errors weigh the same."""
    d = point_distances(pred, tgt, side)
    c = WING_W - WING_W * np.log(1.0 + WING_W / WING_EPS)
    w = torch.where(d < WING_W, WING_W * torch.log1p(d / WING_EPS), d - c)
    return (w * LM_SCALE / side).sum(1)


def log(fh, msg):
    print(msg, flush=True)
    fh.write(msg + "\n")
    fh.flush()


def train_level1(data, steps, fh):
    torch.manual_seed(SEED + 1)
    model = Level1(size=D.LEVEL1["input_size"], spec=LEVEL1_TRUNK, hidden=LEVEL1_HIDDEN).to(DEVICE)
    log(fh, f"level1: {n_params(model)} parameters, {steps} steps of {BATCH}")
    opt = torch.optim.AdamW(model.parameters(), lr=2e-3, weight_decay=WEIGHT_DECAY)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=3e-3, total_steps=steps, pct_start=0.1)
    rng = np.random.default_rng(SEED + 1)
    faces = data.faces_for("level1")
    weights = data.mix(balanced_weights([f["yaw_class"] for f in faces], 5), "level1")
    yaw_w = torch.ones(5, device=DEVICE)
    emas = ema_models(model)
    t0, acc = time.time(), np.zeros(3)
    model.train()
    for step in range(steps):
        X, Y, yaw, face, sharp = (t.to(DEVICE) for t in level1_batch(data, faces, rng, weights))
        lm, yl, fl = model(X)
        # Blurred crops (FACE_BLUR_P) teach the face output only.
        pos = (face > 0.5) & (sharp > 0.5)
        l_lm = point_loss(lm[pos], Y[pos]).mean() if pos.any() else lm.sum() * 0
        l_yaw = F.cross_entropy(yl[pos], yaw[pos], weight=yaw_w) if pos.any() else yl.sum() * 0
        l_face = F.binary_cross_entropy_with_logits(fl[:, 0], face)
        loss = l_lm + YAW_WEIGHT * l_yaw + FACE_WEIGHT * l_face
        opt.zero_grad()
        loss.backward()
        opt.step()
        sched.step()
        for e in emas:
            e.update_parameters(model)
        acc += [l_lm.item(), l_yaw.item(), l_face.item()]
        if (step + 1) % 200 == 0:
            a = acc / 200
            log(fh, f"level1 step {step + 1}: lm {a[0]:.4f} yaw {a[1]:.4f} face {a[2]:.4f} ({time.time() - t0:.0f} s)")
            acc[:] = 0
    return finals(model, emas)


def train_zone(name, data, steps, fh, genki=None):
    zone = D.ZONES[name]
    gest = len(zone.get("gestures", []))
    spec = ZONE_TRUNK.get(name, ZONE_TRUNK["default"])
    # Each net seeds its own initialisation so it does not depend on which nets ran before it.
    torch.manual_seed(SEED + ZONE_SEED[name])
    head, n_scores, _ = score_head(name)
    model = Level2(zone["width"], zone["height"], len(zone["indices68"]), gest, bool(zone.get("gaze")),
                   spec=spec, n_scores=n_scores).to(DEVICE)
    log(fh, f"{name}: {n_params(model)} parameters, {steps} steps of {BATCH}")
    opt = torch.optim.AdamW(model.parameters(), lr=2e-3, weight_decay=WEIGHT_DECAY)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=3e-3, total_steps=steps, pct_start=0.1)
    rng = np.random.default_rng(SEED + ZONE_SEED[name])
    faces = data.faces_for(name)
    if gest:
        labels = [f[name] for f in faces]
        weights = balanced_weights(labels, gest)
        counts = np.bincount([x for x in labels if x >= 0], minlength=gest).astype(np.float32)
        # Sampling balances by the square root; the loss weight does the other square root.
        cw = torch.from_numpy((counts.sum() / np.maximum(counts, 1)) ** 0.5)
        cw = (cw / cw.mean()).to(DEVICE)
    else:
        n = len(faces)
        weights = np.full(n, 1.0 / n)
        cw = None
    weights = data.mix(weights, name)
    emas = ema_models(model)
    t0, acc = time.time(), np.zeros(3)
    model.train()
    for step in range(steps):
        X, Y, YAW, G, GZ, GZM, SM, LM, SC, SCM = (t.to(DEVICE) for t in
                                                  zone_batch(name, data, faces, rng, weights, genki))
        h = model.features(X, YAW)
        out = model.heads(h)
        lm, extra = out[0], out[-1]
        if name in WING_NETS:
            l_lm = (wing_point_loss(lm, Y, max(zone["width"], zone["height"])) * LM).sum() / LM.sum().clamp(min=1)
        else:
            l_lm = (point_loss(lm, Y) * LM).sum() / LM.sum().clamp(min=1)
        l_x = lm.sum() * 0
        if gest:
            m = G >= 0
            if m.any():
                l_x = F.cross_entropy(extra[m], G[m], weight=cw)
            s = SM >= 0
            if s.any():
                # GENKI: smile vs not-smile on the softmax's smile probability
                p = F.softmax(extra[s], dim=1)[:, 0].clamp(1e-6, 1 - 1e-6)
                l_x = l_x + F.binary_cross_entropy(p, SM[s])
            loss = l_lm + GESTURE_WEIGHT * l_x
        elif not zone.get("gaze"):
            loss = l_lm
        else:
            g = F.normalize(extra, dim=1)
            l_x = ((1 - (g * GZ).sum(1)) * GZM).sum() / GZM.sum().clamp(min=1)
            loss = l_lm + GAZE_WEIGHT * 10 * l_x
        if head == "points":
            e = point_loss(model.scores(h), SC)
            loss = loss + AUX_POINT_WEIGHT * (e * SCM).sum() / SCM.sum().clamp(min=1)
        elif head:
            e = (model.scores(h) - SC).pow(2).sum(1)
            loss = loss + SCORE_WEIGHT * (e * SCM).sum() / SCM.sum().clamp(min=1)
        opt.zero_grad()
        loss.backward()
        opt.step()
        sched.step()
        for e in emas:
            e.update_parameters(model)
        acc += [l_lm.item(), l_x.item(), 0]
        if (step + 1) % 200 == 0:
            a = acc / 200
            log(fh, f"{name} step {step + 1}: lm {a[0]:.4f} {'gest' if gest else 'gaze'} {a[1]:.4f} ({time.time() - t0:.0f} s)")
            acc[:] = 0
    return finals(model, emas)


def ema_models(model):
    from torch.optim.swa_utils import AveragedModel, get_ema_multi_avg_fn
    return [AveragedModel(model, multi_avg_fn=get_ema_multi_avg_fn(d), use_buffers=True) for d in EMA_DECAYS]


def export_tags():
    """File-name tags of what `finals` returns: "" for the last weights, then ".ema<decay>"."""
    return [""] + [f".ema{d}" for d in EMA_DECAYS]


def finals(model, emas):
    """The last weights, then each EMA's (in EMA_DECAYS order)."""
    return [model.cpu().eval()] + [e.module.cpu().eval() for e in emas]


def export(model, path, names_in, shapes_in, names_out):
    args = tuple(torch.zeros(s) for s in shapes_in)
    torch.onnx.export(model, args, path, input_names=names_in, output_names=names_out, opset_version=17,
                      dynamo=False, do_constant_folding=True)
    # Storage: weights as float16, then int8 per output channel (half the bytes again; 4.285 ->
    # 4.286 % NME); ReLU written in the form tract fuses (same outputs, 6-7 % faster).
    onnx_f16.to_f16(path)
    onnx_q8.to_q8(path)
    onnx_tract.fusable_relu(path)


def genki_with_refs(level1_path, split, teacher=None, only_found=False):
    """GENKI-4K crops with the zone references (33, 8, 36, 45) predicted by our level 1 (the crops
    carry no landmarks). Level 1 runs twice: on the whole crop, then on the box of its own points.
    Items: (image, 68 points with the references set, smile 0/1, mouth class, brow class); the
    classes are the MediaPipe teacher's (`teacher`: teacher_genki.load's dict), -1 where there is
    none, and the mouth class is -1 where the teacher's smile disagrees with GENKI's label.
    `only_found` keeps only the crops the teacher labelled."""
    import m3_reference as R
    l1 = R.Level1Runner(level1_path)
    teacher = teacher or {}
    out = []
    for img, label, name in D.load_genki(split):
        mouth, brows = teacher.get(name, (-1, -1))
        if mouth >= 0 and (mouth == 0) != (label == 1):
            mouth = -1
        if only_found and name not in teacher:
            continue
        box = np.array(D.GENKI_START_BOX)
        pts = None
        for _ in range(2):
            pts, _, _ = l1.run(img, box)
            box = D.box_of(pts)
        full = np.zeros((68, 2), np.float32)
        full[D.LEVEL1_INDICES] = pts
        full[36], full[45] = pts[D.LEVEL1_INDICES.index(36)], pts[D.LEVEL1_INDICES.index(45)]
        out.append((img, full, float(label), mouth, brows))
    return out


def net_names(arg):
    """"mouth,brows" -> ("mouth", "brows"); "" -> () (the value a flag gives for none)."""
    return tuple(n for n in arg.split(",") if n)


def floats(arg):
    """"0.999,0.9995" -> (0.999, 0.9995); "" -> ()."""
    return tuple(float(v) for v in arg.split(",") if v)


def key_values(arg):
    """"face=0.5,nose=0.25" -> {"face": "0.5", "nose": "0.25"}."""
    return dict(item.split("=") for item in arg.split(",") if item)


# Flags that set one module setting each (default: the setting as shipped, see its comment above):
# flag -> (setting, parser of the flag's value, help).
SETTING_FLAGS = {
    "--level1-trunk": ("LEVEL1_TRUNK", str, "level 1's m3nets.trunk spec, e.g. 16s-32s-48s-64s"),
    "--level1-hidden": ("LEVEL1_HIDDEN", int, "level 1's hidden FC width"),
    "--pseudo-nets": ("PSEUDO_NETS", net_names, "nets that learn from the teacher-labelled GENKI-4K faces too, e.g. face,mouth"),
    "--pseudo-share": ("PSEUDO_SHARE", float, "their share of those nets' batches"),
    "--turned-nets": ("TURNED_NETS", net_names, "nets that learn from the turned faces too (empty for none), e.g. level1,face"),
    "--turned-share": ("TURNED_SHARE", float, "their share of those nets' batches"),
    "--genki-gesture-nets": ("GENKI_GESTURE_NETS", net_names, "e.g. mouth,brows"),
    "--occluder-nets": ("OCCLUDER_NETS", net_names, "e.g. mouth,face"),
    "--occluder-p": ("OCCLUDER_P", float, "share of those nets' patches with an occluder"),
    "--score-nets": ("SCORE_NETS", net_names, "e.g. brows,mouth"),
    "--score-weight": ("SCORE_WEIGHT", float, "weight of the teacher-score loss"),
    "--face-blur": ("FACE_BLUR_P", float, "share of level 1's crops blurred for its face output only"),
    "--pose-nets": ("POSE_NETS", net_names, "e.g. face,nose"),
    "--aux-point-nets": ("AUX_POINT_NETS", net_names, "e.g. face,nose"),
    "--aux-point-weight": ("AUX_POINT_WEIGHT", float, "weight of the other points' loss"),
    "--motion-blur": ("MOTION_BLUR_P", float, "share of patches with motion blur"),
    "--wing-nets": ("WING_NETS", net_names, "e.g. face"),
    "--seed": ("SEED", int, "another seed for a run-to-run spread check (the shipped weights use SEED)"),
    "--ema": ("EMA_DECAYS", floats, "e.g. 0.999,0.9995: also write NAME.ema0.999.onnx ... (weight averages of the same run)"),
}
# Flags that change entries of a per-net table: flag -> (table, parser of each value, help).
TABLE_FLAGS = {
    "--zone-trunk": (ZONE_TRUNK, str, "e.g. eye=8s-16s-32s,default=8s-16s-32s-48s (m3nets.trunk specs)"),
    "--ref-noise": (REF_NOISE, float, "e.g. face=0.025,nose=0.025"),
    "--shape-warp": (SHAPE_WARP, float, "e.g. face=0.5"),
}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--steps-scale", type=float, default=1.0)
    ap.add_argument("--only", default="level1,brows,eye,mouth,face,nose,mouth_fine")
    for flag, (_, _, doc) in SETTING_FLAGS.items():
        ap.add_argument(flag, default=None, help=doc)
    for flag, (_, _, doc) in TABLE_FLAGS.items():
        ap.add_argument(flag, default=None, help=doc)
    ap.add_argument("--zone-size", default=None, help="e.g. face=48x48 (the patch size in m3.json follows)")
    # Results differ from the CPU run's in the last bits (GPU kernels); the shipped weights are CPU's.
    ap.add_argument("--device", default="cpu")
    # Zone nets train in this many processes at once after level 1 (each net seeds itself, so the
    # result does not depend on it).
    ap.add_argument("--jobs", type=int, default=min(4, os.cpu_count() or 1))
    # Set for the zone processes run_zones_in_processes starts: their parent calibrates at the end.
    ap.add_argument("--no-calibrate", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args()
    global DEVICE
    for flag, (name, parse, _) in SETTING_FLAGS.items():
        value = getattr(a, flag[2:].replace("-", "_"))
        if value is not None:
            globals()[name] = parse(value)
    for flag, (table, parse, _) in TABLE_FLAGS.items():
        for k, v in key_values(getattr(a, flag[2:].replace("-", "_")) or "").items():
            table[k] = parse(v)
    for k, v in key_values(a.zone_size or "").items():
        D.ZONES[k]["width"], D.ZONES[k]["height"] = (int(n) for n in v.split("x"))
    DEVICE = torch.device(a.device)
    random.seed(SEED)
    np.random.seed(SEED)
    torch.manual_seed(SEED)
    torch.set_num_threads(int(os.environ.get("MONOTRACK_TRAIN_THREADS", "1")))
    cv2.setNumThreads(1)
    os.makedirs(OUT, exist_ok=True)
    only = a.only.split(",")
    fh = open(os.path.join(OUT, f"train_log_{a.only.replace(',', '_')}.txt"), "w")
    log(fh, f"== train_m3 {time.strftime('%Y-%m-%d %H:%M:%S')} only={only} steps_scale={a.steps_scale} seed={SEED}"
            f" level1={LEVEL1_TRUNK}/{LEVEL1_HIDDEN} zones={ZONE_TRUNK} pseudo={PSEUDO_NETS}@{PSEUDO_SHARE} turned={TURNED_NETS}@{TURNED_SHARE} genki_gestures={GENKI_GESTURE_NETS} scores={SCORE_NETS}@{SCORE_WEIGHT} occluders={OCCLUDER_NETS}@{OCCLUDER_P} pose={POSE_NETS} aux_points={AUX_POINT_NETS}@{AUX_POINT_WEIGHT} motion_blur={MOTION_BLUR_P} face_blur={FACE_BLUR_P} wing={WING_NETS} ref_noise={REF_NOISE}"
            f"{f' shape_warp={SHAPE_WARP}' if SHAPE_WARP else ''} device={DEVICE}")
    pseudo = None
    if any(n in only for n in PSEUDO_NETS):
        pseudo = os.environ.get("MONOTRACK_PSEUDO") or pseudo_genki.default_path()
        if not os.path.exists(pseudo):
            pseudo_genki.main(pseudo)
    turned = None
    if any(n in only for n in TURNED_NETS):
        turned = os.environ.get("MONOTRACK_TURNED") or os.path.join(rotate_faces.default_dir(), "train.jsonl")
        if not os.path.exists(turned):
            turned, n = rotate_faces.build(os.path.dirname(turned), "train")
            log(fh, f"turned faces: {n} made by rotate_faces.py -> {turned}")
    data = Data("train", pseudo, turned)
    log(fh, f"train faces (with mirrors): {len(data.faces)} from {len(data.imgs)} images")
    steps = {k: int(v * a.steps_scale) for k, v in STEPS.items()}
    if "level1" in only:
        log(fh, f"level1 hard negatives: {data.mine_hard_negatives()} detector false positives on the training images")
        for tag, m in zip(export_tags(), train_level1(data, steps["level1"], fh)):
            export(m, os.path.join(OUT, f"level1{tag}.onnx"), ["image"], [(1, 1, 64, 64)], ["landmarks", "yaw_logits", "face_logit"])
    zones = [n for n in ("face", "mouth", "brows", "mouth_fine", "nose", "eye") if n in only]  # longest first
    if a.jobs > 1 and len(zones) > 1:
        run_zones_in_processes(zones, a, fh)
        zones = []
    for name in zones:
        z = D.ZONES[name]
        teacher = None
        if name in GENKI_GESTURE_NETS:
            path = os.environ.get("MONOTRACK_GENKI_TEACHER") or teacher_genki.default_path()
            if not os.path.exists(path):
                raise SystemExit(f"{path} is missing: run teacher_genki.py (it needs mediapipe==0.10.14)")
            teacher = teacher_genki.load(path, "train")
        genki = None
        if name == "mouth" or teacher is not None:
            genki = genki_with_refs(os.path.join(OUT, "level1.onnx"), "train", teacher, only_found=name != "mouth")
            log(fh, f"GENKI-4K train crops for the {name} gesture head: {len(genki)}"
                    f"{f', teacher-labelled: {len(teacher)}' if teacher is not None else ''}")
        outs = ["landmarks"] + (["gaze"] if z.get("gaze") else ["gesture_logits"] if z.get("gestures") else [])
        for tag, m in zip(export_tags(), train_zone(name, data, steps[name], fh, genki)):
            export(m, os.path.join(OUT, f"{name}{tag}.onnx"), ["patch", "yaw"], [(1, 1, z["height"], z["width"]), (1, 5)], outs)
    write_config()
    # The label-convention offset and shape prior (calibrate_m3.py) depend on every net: fitted once they all exist.
    if not a.no_calibrate and all(os.path.exists(os.path.join(OUT, f))
                                  for f in ["level1.onnx"] + [f"{n}.onnx" for n in D.ZONES]):
        value, n = calibrate_m3.write(OUT)
        log(fh, f"x_offset_iod = {value}, shape prior fitted (calibrate_m3.py, {n} training faces)")
    # The brow net's gesture decision offsets (calibrate_gestures.py), fitted on GENKI-4K crops no
    # net learns from, once the nets that place its patch exist.
    if not a.no_calibrate and "brows" in only and os.path.exists(os.path.join(OUT, "brows.onnx")):
        import calibrate_gestures
        calibrate_gestures.main(OUT)
    log(fh, f"done {only}")


def run_zones_in_processes(zones, a, fh):
    # Each process gets this run's own flags (the later --jobs and --only win), so it trains its
    # net exactly as this process would.
    base = [sys.executable, os.path.abspath(__file__)] + sys.argv[1:] + ["--jobs", "1", "--no-calibrate"]
    pending, running = list(zones), []
    while pending or running:
        while pending and len(running) < a.jobs:
            name = pending.pop(0)
            log(fh, f"{name}: training in a process of its own (train_log_{name}.txt)")
            running.append((name, subprocess.Popen(base + ["--only", name], stdout=subprocess.DEVNULL)))
        time.sleep(2)
        for item in [r for r in running if r[1].poll() is not None]:
            running.remove(item)
            if item[1].returncode != 0:
                raise SystemExit(f"{item[0]}: training failed ({item[1].returncode})")


def write_config():
    cfg = {"version": 1,
           "level1": {"file": "level1.onnx", "input_size": D.LEVEL1["input_size"], "crop_scale": D.LEVEL1["crop_scale"],
                      "indices68": D.LEVEL1_INDICES, "yaw_classes_deg": D.YAW_CLASSES},
           "zones": {}}
    for name, z in D.ZONES.items():
        e = {"file": f"{name}.onnx"}
        e.update({k: v for k, v in z.items()})
        e.setdefault("bilateral", None)
        e.setdefault("equalize", False)
        if name in D.MIRROR_AVERAGE:
            e["mirror_average"] = True
        cfg["zones"][name] = e
    if "level1" in D.MIRROR_AVERAGE:
        cfg["level1"]["mirror_average"] = True
    with open(os.path.join(OUT, "m3.json"), "w") as fh:
        json.dump(cfg, fh, indent=1)


if __name__ == "__main__":
    main()

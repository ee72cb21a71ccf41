"""M3 training data: faces68 images + landmarks, teacher labels, and the M3_IO.md sampling.

Everything here follows `core/models/M3_IO.md` (the contract with the Rust inference in
`core::landmarks`): the validation split rule, the face box convention, the affine sampling convention
(pixel centres at +0.5, bilinear, border replicated) and the patch definitions.

Labels the data lacks come from teachers (see `core/models/MODEL_CARD.md`):
- head yaw: the MediaPipe teacher's yaw where it found the face, else a PnP fit of the project's mean
  face (core/models/face_model) to the annotated 68 points (agrees with the teacher: r = 0.96);
- gestures: thresholds on the teacher's blendshapes (THRESHOLDS below) + GENKI-4K smile labels;
- gaze: the teacher's eyeLook* blendshapes (eye-in-head angles) composed with its head rotation.
"""
import json
import os

import cv2
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.abspath(os.path.join(HERE, "..", "..", ".."))
DATA = os.environ.get("MONOTRACK_SHARED_DATA", os.path.join(REPO, "..", "shared", "data"))

YAW_CLASSES = [-60, -30, 0, 30, 60]
MOUTH_GESTURES = ["smile", "frown", "kiss", "neutral"]
BROW_GESTURES = ["raise", "frown", "neutral"]

# Teacher thresholds on MediaPipe blendshapes (values 0..1). Chosen from their distribution on
# faces68 (see RESEARCH_LOG.md): mean mouthSmile > 0.5 holds for 35 % of faces (visibly smiling in the
# images); mouthFrown is rare (99th percentile 0.12) so 0.1 keeps only clear frowns; mouthPucker > 0.5
# with little smile marks kisses (the 95th percentile is 0.73); browInnerUp / browOuterUp above 0.4
# (90th percentile) marks raised brows and mean browDown above 0.45 frowning brows.
THRESHOLDS = {
    "smile": 0.5,
    "frown": 0.1,
    "kiss": 0.5,
    "kiss_max_smile": 0.3,
    "brow_raise": 0.4,
    "brow_frown": 0.45,
}
# eyeLook* = 1 taken as this many degrees of eye-in-head rotation (the eye's comfortable range).
GAZE_H_DEG = 35.0
GAZE_V_DEG = 25.0

# 68-point mirror permutation (image flipped left-right).
MIRROR68 = np.array(
    list(range(16, -1, -1))
    + list(range(26, 16, -1))
    + [27, 28, 29, 30, 35, 34, 33, 32, 31]
    + [45, 44, 43, 42, 47, 46, 39, 38, 37, 36, 41, 40]
    + [54, 53, 52, 51, 50, 49, 48, 59, 58, 57, 56, 55]
    + [64, 63, 62, 61, 60, 67, 66, 65]
)

# Level 1: jaw, nose, eye corners, mouth corners (the zone nets give brows, eyes and mouth in full).
LEVEL1_INDICES = list(range(0, 17)) + list(range(27, 36)) + [36, 39, 42, 45, 48, 54]
assert len(LEVEL1_INDICES) == 32

ZONES = {
    "brows": {"width": 64, "height": 32, "ref68": [36, 45], "template": [[0.2, 0.78], [0.8, 0.78]],
              "indices68": list(range(17, 27)), "gestures": BROW_GESTURES,
              "bilateral": {"d": 5, "sigma_color": 20.0, "sigma_space": 3.0}, "equalize": False},
    "eye": {"width": 40, "height": 24, "ref68": [36, 39], "template": [[0.2, 0.55], [0.8, 0.55]],
            "mirror_ref68": [45, 42], "indices68": list(range(36, 42)),
            "mirror_indices68": [45, 44, 43, 42, 47, 46], "gaze": True,
            "bilateral": {"d": 5, "sigma_color": 20.0, "sigma_space": 3.0}, "equalize": True},
    "mouth": {"width": 48, "height": 48, "ref68": [33, 8], "template": [[0.5, 0.12], [0.5, 0.92]],
              "indices68": list(range(48, 68)), "gestures": MOUTH_GESTURES,
              "bilateral": {"d": 5, "sigma_color": 20.0, "sigma_space": 3.0}, "equalize": False},
    # Level 2 for the jaw contour and the nose (an addition to the thesis' three zones): level 1 sees
    # the face at any roll and scale; this patch is aligned on the outer eye corners. Its points are
    # averaged with level 1's (level1_weight, M3_IO.md): on the validation split the zone alone gives
    # jaw 7.68 / nose 4.05 %, level 1 alone 7.31 / 4.14 %, the blend 6.91 / 3.77 % (RESEARCH_LOG.md);
    # blended, 48x48 is as accurate as 64x64 and cheaper.
    "face": {"width": 48, "height": 48, "ref68": [36, 45], "template": [[0.32, 0.3], [0.68, 0.3]],
             "indices68": list(range(0, 17)) + list(range(27, 36)), "bilateral": None, "equalize": False,
             "level1_weight": [0.5] * 17 + [0.3] * 9},
    # The nose at a finer scale (another addition): a 24x40 patch on the face zone's nostril corners
    # 31 and 35 ("refs": "merged"; it runs after the face zone by name), about 44 px per outer-eye
    # distance against the face zone's 17, reaching up to the bridge between the eyes. Its points
    # replace the face zone's. On the validation split the nose NME falls 2.82 -> 2.48 % against a
    # 32x32 patch on the outer eye corners at the same cost (RESEARCH_LOG.md). Trained on the
    # annotated nostril corners jittered like every zone's references.
    "nose": {"width": 24, "height": 40, "ref68": [31, 35], "template": [[0.1875, 0.85], [0.8125, 0.85]],
             "indices68": list(range(27, 36)), "refs": "merged", "bilateral": None, "equalize": False},
    # The lips at a finer scale (another addition): a 48x40 patch on the mouth zone's corners 48 and
    # 54 ("refs": "merged"; it runs after the mouth zone by name), blended 0.7 / 0.3 with the mouth
    # zone's points (prior_weight). Trained on the annotated corners jittered like every zone's
    # references. On the validation split the mouth NME falls 3.74 -> 3.16 % (the zone alone 3.25 %;
    # RESEARCH_LOG.md). No bilateral filter: with it 0.03 % better in one run (within the run-to-run
    # spread) at more time per face.
    "mouth_fine": {"width": 48, "height": 40, "ref68": [48, 54], "template": [[0.1, 0.4], [0.9, 0.4]],
                   "indices68": list(range(48, 68)), "refs": "merged", "bilateral": None, "equalize": False,
                   "prior_weight": [0.3] * 20},
}
LEVEL1 = {"input_size": 64, "crop_scale": 1.3}

# The nets that run a second time on their mirrored input in mirror-average mode (M3_IO.md), written
# into m3.json as `"mirror_average": true`: level 1 and zones but the eye (mirrored per side
# already). Validation NME (RESEARCH_LOG.md): 3.98 % in the default mode; 3.875 % with level 1 and
# all five other zones; 3.890 % with level 1, brows, mouth and mouth_fine; 3.925 % with the five
# zones without level 1. Over eight box-jitter seeds (Python reference): 3.9074 % with all six, 3.9066 % without mouth_fine's second run (the set below: it
# gains nothing; in two warm per-face timing runs it cost 14 µs in one and nothing measurable in the
# other), 3.9167 % without face's too (58–61 µs less in those runs; kept: the margin over PFLD is a
# few hundredths of a point).
MIRROR_AVERAGE = ("level1", "brows", "face", "mouth", "nose")

assert sorted(set(LEVEL1_INDICES) | {i for z in ZONES.values() for i in z["indices68"] + z.get("mirror_indices68", [])}) == list(range(68))


def outer_eye_distance(pts):
    """Distance between the outer eye corners (points 36 and 45): NME's normaliser and the unit of
    m3.json's x_offset_iod (M3_IO.md)."""
    return np.linalg.norm(pts[36] - pts[45])


def with_x_offset(pts, x_offset_iod):
    """pts moved along x by x_offset_iod times their own outer-eye-corner distance (m3.json's label
    offset, M3_IO.md)."""
    out = np.array(pts, dtype=float)
    out[:, 0] += x_offset_iod * outer_eye_distance(out)
    return out


def luma(rgb):
    """BT.601 full-range luma, rounded (M3_IO.md)."""
    y = 0.299 * rgb[..., 0] + 0.587 * rgb[..., 1] + 0.114 * rgb[..., 2]
    return np.floor(y + 0.5).clip(0, 255).astype(np.uint8)


def load_gray(path):
    bgr = cv2.imread(path, cv2.IMREAD_COLOR)
    if bgr is None:
        raise FileNotFoundError(path)
    return luma(bgr[..., ::-1].astype(np.float32))


def sample(img, A, w, h):
    """Patch of w x h from `img` by the affine map A (2x3, patch coords -> image coords), with the
    M3_IO.md convention: patch pixel (u, v) = bilinear sample at A(u + .5, v + .5) - .5 in index space."""
    L, b = A[:, :2], A[:, 2]
    M = np.concatenate([L, (L @ np.array([0.5, 0.5]) + b - 0.5)[:, None]], axis=1)
    return cv2.warpAffine(img, M, (w, h), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                          borderMode=cv2.BORDER_REPLICATE)


def apply(A, pts):
    return pts @ A[:, :2].T + A[:, 2]


def invert(A):
    L = np.linalg.inv(A[:, :2])
    return np.concatenate([L, (-L @ A[:, 2])[:, None]], axis=1)


def square_of_box(box):
    x, y, w, h = box
    return np.array([x + w / 2, y + h / 2]), max(w, h)


def level1_map(c, s, size, crop_scale, angle=0.0):
    """Crop map: patch (0..size)^2 -> image square of side crop_scale*s centred on c (optionally
    rotated, for augmentation; inference uses angle 0)."""
    k = crop_scale * s / size
    ca, sa = np.cos(angle), np.sin(angle)
    L = k * np.array([[ca, -sa], [sa, ca]])
    b = c - L @ np.array([size / 2, size / 2])
    return np.concatenate([L, b[:, None]], axis=1)


def similarity_map(p0, p1, q0, q1):
    """Similarity (patch -> image) sending patch points q0, q1 to image points p0, p1."""
    dq = np.asarray(q1, float) - q0
    dp = np.asarray(p1, float) - p0
    # complex ratio z = dp / dq: rotation + scale
    zq = complex(*dq)
    zp = complex(*dp)
    z = zp / zq
    L = np.array([[z.real, -z.imag], [z.imag, z.real]])
    b = np.asarray(p0, float) - L @ q0
    return np.concatenate([L, b[:, None]], axis=1)


def zone_map(zone, p_ref0, p_ref1):
    W, H = zone["width"], zone["height"]
    t = np.array(zone["template"], float) * [W, H]
    return similarity_map(p_ref0, p_ref1, t[0], t[1])


def zone_filter(zone, patch):
    bf = zone.get("bilateral")
    if bf:
        patch = cv2.bilateralFilter(patch, bf["d"], bf["sigma_color"], bf["sigma_space"],
                                    borderType=cv2.BORDER_REFLECT_101)
    if zone.get("equalize"):
        patch = cv2.equalizeHist(patch)
    return patch


def box_of(pts):
    lo, hi = pts.min(0), pts.max(0)
    return np.array([lo[0], lo[1], hi[0] - lo[0], hi[1] - lo[1]])


def rot_from_euler(yaw, pitch, roll):
    y, p, r = np.radians([yaw, pitch, roll])
    Rx = np.array([[1, 0, 0], [0, np.cos(p), -np.sin(p)], [0, np.sin(p), np.cos(p)]])
    Ry = np.array([[np.cos(y), 0, np.sin(y)], [0, 1, 0], [-np.sin(y), 0, np.cos(y)]])
    Rz = np.array([[np.cos(r), -np.sin(r), 0], [np.sin(r), np.cos(r), 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


def gaze_from_teacher(t):
    """(right_eye, left_eye) unit gaze vectors, camera frame (towards the camera is -z)."""
    b = t["blendshapes"]
    R = rot_from_euler(t["yaw_deg"], t["pitch_deg"], t["roll_deg"])
    out = []
    for side in ("Right", "Left"):
        # Model frame x points to the subject's left: for the right eye "in" (nasal) is +x,
        # for the left eye "out" (temporal) is +x.
        inward = b["eyeLookIn" + side] - b["eyeLookOut" + side]
        h = np.radians(GAZE_H_DEG) * (inward if side == "Right" else -inward)
        v = np.radians(GAZE_V_DEG) * (b["eyeLookDown" + side] - b["eyeLookUp" + side])
        g = np.array([np.sin(h) * np.cos(v), np.sin(v), -np.cos(h) * np.cos(v)])
        g = R @ g
        out.append(g / np.linalg.norm(g))
    return out


def gestures_from_teacher(t):
    b = t["blendshapes"]
    smile = 0.5 * (b["mouthSmileLeft"] + b["mouthSmileRight"])
    frown = 0.5 * (b["mouthFrownLeft"] + b["mouthFrownRight"])
    th = THRESHOLDS
    if smile > th["smile"]:
        mouth = 0
    elif b["mouthPucker"] > th["kiss"] and smile < th["kiss_max_smile"]:
        mouth = 2
    elif frown > th["frown"]:
        mouth = 1
    else:
        mouth = 3
    raise_ = max(b["browInnerUp"], 0.5 * (b["browOuterUpLeft"] + b["browOuterUpRight"]))
    bdown = 0.5 * (b["browDownLeft"] + b["browDownRight"])
    if bdown > th["brow_frown"] and bdown > raise_:
        brows = 1
    elif raise_ > th["brow_raise"]:
        brows = 0
    else:
        brows = 2
    return mouth, brows


def gesture_scores(t):
    """The teacher's continuous scores behind gestures_from_teacher's classes: (mouth [smile, pucker,
    frown], brows [raise, down]), each the same mean or maximum of blendshapes the thresholds read.
    Symmetric in left and right, so a mirrored face keeps them."""
    b = t["blendshapes"]
    mouth = [0.5 * (b["mouthSmileLeft"] + b["mouthSmileRight"]), b["mouthPucker"],
             0.5 * (b["mouthFrownLeft"] + b["mouthFrownRight"])]
    brows = [max(b["browInnerUp"], 0.5 * (b["browOuterUpLeft"] + b["browOuterUpRight"])),
             0.5 * (b["browDownLeft"] + b["browDownRight"])]
    return np.array(mouth, np.float32), np.array(brows, np.float32)


def yaw_class(yaw):
    if yaw < -60:
        return 0
    if yaw < -30:
        return 1
    if yaw <= 30:
        return 2
    if yaw <= 60:
        return 3
    return 4


_MEAN = None


def pnp_yaw(pts, W, H):
    global _MEAN
    if _MEAN is None:
        m = json.load(open(os.path.join(REPO, "core", "models", "face_model", "face_model.json")))
        _MEAN = np.array(m["mean"], float)
    f = 0.9 * max(W, H)
    K = np.array([[f, 0, W / 2], [0, f, H / 2], [0, 0, 1.0]])
    ok, rv, tv = cv2.solvePnP(_MEAN, pts, K, None, flags=cv2.SOLVEPNP_EPNP)
    ok, rv, tv = cv2.solvePnP(_MEAN, pts, K, None, rv, tv, True, flags=cv2.SOLVEPNP_ITERATIVE)
    R = cv2.Rodrigues(rv)[0]
    return float(np.degrees(-np.arcsin(np.clip(R[2, 0], -1, 1))))


def level1_negative(c, s, shape, rng):
    """A not-a-face level-1 square (centre, side) drawn near the face square (c, s) of an image of
    `shape`: shifted off the face, far too large, a part of the face, or anywhere in the image.
    Level 1's face/not-face training and eval_face_check.py draw their negatives here."""
    kind = rng.random()
    if kind < 0.5:  # shifted off the face
        th = rng.uniform(0, 2 * np.pi)
        c = c + rng.uniform(0.5, 1.2) * s * np.array([np.cos(th), np.sin(th)])
    elif kind < 0.7:  # far too large
        s *= rng.uniform(2.3, 3.5)
    elif kind < 0.85:  # a part of the face
        s *= rng.uniform(0.25, 0.45)
        c = c + rng.uniform(-0.3, 0.3, 2) * s / 0.35
    else:  # anywhere in the image, away from this face
        h, w = shape
        s = rng.uniform(0.3, 1.0) * s
        c = np.array([rng.uniform(0, w), rng.uniform(0, h)])
    return c, s


# Font for rendered caption text (`text_negative`): WenQuanYi Micro Hei (Debian `fonts-wqy-microhei`,
# Apache-2.0 / GPL), CJK and Latin glyphs. Evaluation data only, never shipped.
TEXT_FONT = "/usr/share/fonts/truetype/wqy/wqy-microhei.ttc"
_FONTS = {}


def text_negative(img, rng):
    """Rendered caption text as a level-1 negative: returns (canvas, centre, side) with a square over
    one or two glyphs. Why: news video captions (white CJK or Latin glyphs of about 20 px, often
    outlined, on a dark band) reach the face check as detector candidates, and level 1 passes some at
    0.97-1.0 (eval_face_check.py measures it; training level 1 with them was tried and not kept,
    RESEARCH_LOG.md). The background is a region of `img`, darkened or under a flat band; glyph size,
    colour, outline, characters and the square are drawn from `rng`."""
    from PIL import Image, ImageDraw, ImageFont
    if not os.path.exists(TEXT_FONT):
        raise SystemExit(f"{TEXT_FONT} missing: apt-get install fonts-wqy-microhei (level 1's text negatives)")
    g = int(rng.integers(14, 49))  # glyph size, canvas pixels
    n = 6
    H, W = 3 * g, (n + 2) * g
    h, w = img.shape
    y0, x0 = int(rng.integers(0, max(1, h - H))), int(rng.integers(0, max(1, w - W)))
    bg = img[y0:y0 + H, x0:x0 + W].astype(np.float32)
    if bg.shape != (H, W):
        bg = cv2.resize(bg, (W, H), interpolation=cv2.INTER_LINEAR)
    bg *= rng.uniform(0.25, 1.0)
    if rng.random() < 0.4:  # a flat caption band behind the text
        bg[:] = rng.uniform(0, 255) if rng.random() < 0.3 else rng.uniform(0, 80)
    canvas = Image.fromarray(bg.clip(0, 255).astype(np.uint8))
    if g not in _FONTS:
        _FONTS[g] = ImageFont.truetype(TEXT_FONT, g)
    chars = []
    for _ in range(n):
        if rng.random() < 0.7:
            chars.append(chr(int(rng.integers(0x4E00, 0x9FA6))))
        else:
            chars.append("ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789"[int(rng.integers(62))])
    dark = rng.random() < 0.2  # dark text on light ground, sometimes
    fill = int(rng.uniform(0, 60)) if dark else int(rng.uniform(170, 256))
    stroke = int(rng.integers(0, 3)) if rng.random() < 0.5 else 0
    ImageDraw.Draw(canvas).text((0.5 * g, H / 2 - 0.6 * g), "".join(chars), font=_FONTS[g], fill=fill,
                                stroke_width=stroke, stroke_fill=255 - fill)
    k = int(rng.integers(0, n - 1))
    c = np.array([0.5 * g + (k + rng.uniform(0.5, 1.5)) * g, H / 2 + rng.uniform(-0.2, 0.2) * g])
    return np.asarray(canvas), c, g * rng.uniform(0.8, 1.8)


def load_faces68(split):
    """Faces of the faces68 split ('train' | 'val'): dicts with image index, landmarks, labels."""
    teacher = {}
    for line in open(os.path.join(DATA, "faces68", "teacher_mediapipe.jsonl")):
        t = json.loads(line)
        teacher[(t["image"], t["face_index"])] = t
    images, faces = [], []
    for i, line in enumerate(open(os.path.join(DATA, "faces68", "train.jsonl"))):
        is_val = i % 10 == 0
        if is_val != (split == "val"):
            continue
        r = json.loads(line)
        img_idx = len(images)
        images.append(os.path.join(DATA, "faces68", r["image"]))
        for fi, fc in enumerate(r["faces"]):
            pts = np.array(fc["landmarks68"], np.float32)
            t = teacher.get((r["image"], fi))
            found = bool(t and t.get("found"))
            yaw = t["yaw_deg"] if found else pnp_yaw(pts.astype(np.float64), r["width"], r["height"])
            face = {"image": img_idx, "line": i, "path": r["image"], "pts": pts, "yaw": yaw,
                    "yaw_class": yaw_class(yaw), "mouth": -1, "brows": -1, "gaze": None}
            if found:
                face["mouth"], face["brows"] = gestures_from_teacher(t)
                face["mouth_scores"], face["brows_scores"] = gesture_scores(t)
                face["pose"] = np.array([t["yaw_deg"], t["pitch_deg"]], np.float32) / 60.0
                face["gaze"] = gaze_from_teacher(t)
            faces.append(face)
    return images, faces


def genki_files(split):
    """GENKI-4K crops of our split ('train' | 'test'): (path, smile 0/1, file name). File number
    % 5 == 0 is held out ('test')."""
    base = os.path.join(DATA, "expression", "genki4k", "train")
    out = []
    for label in (0, 1):
        d = os.path.join(base, str(label))
        for f in sorted(os.listdir(d)):
            n = int("".join(ch for ch in f if ch.isdigit()))
            if (n % 5 == 0) == (split == "test"):
                out.append((os.path.join(d, f), label, f))
    return out


# Where a GENKI-4K crop's face is first looked for (the crops are 64x64, the face about 52 px):
# level 1 reads it there, then again on the box of its own points.
GENKI_START_BOX = (6.0, 8.0, 52.0, 52.0)


def load_genki(split):
    """GENKI-4K crops: (gray 64x64, smile 0/1, file name) of genki_files(split)."""
    return [(load_gray(path), label, f) for path, label, f in genki_files(split)]


# Level-1 hard negatives: the shipped detector's false positives (detector/train.py's decoding, run
# with onnxruntime on detector.onnx at these minimum face sizes and this score, lower than the
# detector's standalone threshold so that near misses count too). A false positive overlaps no annotated face (IoU < 0.3)
# and has its centre outside every unannotated face (detector/unlabeled.py).
DETECTOR_FP_MIN_SCORE = 0.3
DETECTOR_FP_MIN_FACES = (16.0, 24.0, 32.0, 48.0)


def detector_false_positives(img_paths, faces):
    """[(image index, box x, y, w, h)] of the shipped detector's false positives on the images
    `img_paths` whose annotated faces are `faces` (load_faces68's output)."""
    import sys
    import onnxruntime as ort
    sys.path.insert(0, os.path.join(HERE, "detector"))
    import train as det  # the detector's own decoding and pyramid (imports torch)
    import unlabeled
    unannotated = unlabeled.load()
    so = ort.SessionOptions()
    so.intra_op_num_threads = 1
    so.log_severity_level = 3
    sess = ort.InferenceSession(os.path.join(REPO, "core", "models", "detector", "detector.onnx"), so,
                                providers=["CPUExecutionProvider"])
    gts = [[] for _ in img_paths]
    rels = [None] * len(img_paths)
    for f in faces:
        gts[f["image"]].append(det.tight_box(f["pts"]))
        rels[f["image"]] = f["path"]
    out = []
    for k, path in enumerate(img_paths):
        img = load_gray(path)
        h0, w0 = img.shape
        dets = []
        for mf in DETECTOR_FP_MIN_FACES:
            for sc in det.pyramid_scales(w0, h0, mf):
                nw, nh = max(1, round(w0 * sc)), max(1, round(h0 * sc))
                small = cv2.resize(img, (nw, nh), interpolation=cv2.INTER_AREA) if sc < 1 else img
                outs = sess.run(None, {"image": small[None, None].astype(np.float32) / 255.0})
                dets += det.detect_np([o[0] for o in outs], w0 / nw, h0 / nh, DETECTOR_FP_MIN_SCORE, 0.4)
        for d in det.nms_list(dets, 0.4):
            if all(det.iou(d, g) < 0.3 for g in gts[k]) and not det.ignored(d, unannotated.get(rels[k], [])):
                out.append((k, np.array(d[:4], np.float64)))
    return out


# The shape prior (M3_IO.md "Shape prior"): per zone, a ridge regression from the other zones'
# points, in the frame that maps the outer eye corners to (-1, 0) and (1, 0).
PRIOR_FRAME = (36, 45)


def prior_frame(pts):
    """(centre, half-vector) of the frame: the midpoint of points 36 and 45 and half their
    difference."""
    a, b = pts[PRIOR_FRAME[0]], pts[PRIOR_FRAME[1]]
    return (a + b) / 2, (b - a) / 2


def to_prior_frame(pts, frame):
    c, v = frame
    q = (pts - c) / (v @ v)
    return np.stack([q[..., 0] * v[0] + q[..., 1] * v[1], -q[..., 0] * v[1] + q[..., 1] * v[0]], -1)


def from_prior_frame(q, frame):
    c, v = frame
    return np.stack([q[..., 0] * v[0] - q[..., 1] * v[1], q[..., 0] * v[1] + q[..., 1] * v[0]], -1) + c


def prior_inputs(indices):
    """The points a zone's regression reads: every point not in the zone, ascending."""
    zone = set(indices)
    return [i for i in range(68) if i not in zone]


def prior_features(pts, indices):
    """A zone's regression input: the other points in the frame, (x, y) each, then 1."""
    q = to_prior_frame(pts[prior_inputs(indices)], prior_frame(pts))
    return np.append(q.reshape(-1), 1.0)


def contour_tangents(p):
    """Unit tangents of an open contour (central differences inside, one-sided at the ends, as
    numpy.gradient); a zero tangent stays zero."""
    t = np.gradient(p, axis=0)
    n = np.linalg.norm(t, axis=1, keepdims=True)
    return np.where(n > 0, t / np.where(n > 0, n, 1), 0.0)


def apply_shape_prior(pts, zones, matrices):
    """pts (68, 2) moved towards each zone's regression (M3_IO.md): all zones read the same input
    points; `weight` along the zone (the whole move when there is no `normal_weight`),
    `normal_weight` across it."""
    out = pts.copy()
    for z, m in zip(zones, matrices):
        idx = z["indices68"]
        r = from_prior_frame((prior_features(pts, idx) @ m).reshape(-1, 2), prior_frame(pts))
        d = r - pts[idx]
        if "normal_weight" in z:
            t = contour_tangents(pts[idx])
            along = (d * t).sum(1, keepdims=True) * t
            out[idx] = pts[idx] + z["weight"] * along + z["normal_weight"] * (d - along)
        else:
            out[idx] = pts[idx] + z["weight"] * d
    return out


def load_shape_prior(model_dir, cfg):
    """(zones, matrices) of m3.json's `shape_prior`, or None: float32 little-endian, zone after
    zone, each (2 * (68 - n) + 1) x 2n row-major."""
    sp = cfg.get("shape_prior")
    if not sp:
        return None
    flat = np.fromfile(os.path.join(model_dir, sp["file"]), dtype="<f4").astype(np.float64)
    mats, k = [], 0
    for z in sp["zones"]:
        n = len(z["indices68"])
        rows, cols = 2 * (68 - n) + 1, 2 * n
        mats.append(flat[k:k + rows * cols].reshape(rows, cols))
        k += rows * cols
    assert k == flat.size, f"{sp['file']}: {flat.size} numbers, zones need {k}"
    return sp["zones"], mats

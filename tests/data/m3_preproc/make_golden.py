"""Golden fixtures for the M3 preprocessing (core::landmarks::{warp, filter}) against OpenCV.

Run from the repository root: `python3 tests/data/m3_preproc/make_golden.py` (numpy + opencv-python;
writes next to this file; deterministic).

Where the expected values come from (the training side of core/models/M3_IO.md calls OpenCV, so
OpenCV is the yardstick):
- `src.pgm`: a 96x80 gray crop of samples/data/astronaut.jpg around the face (luma by the M3_IO.md
  formula), the input of every case; committed, so JPEG decoders never enter the comparison.
- `warp_<k>.pgm`: `cv2.warpAffine(src, M, (w, h), INTER_LINEAR | WARP_INVERSE_MAP, BORDER_REPLICATE)`
  with M = the M3_IO.md sampling of the patch map A (the half-pixel shift folded in), for the maps
  listed in `cases.json` (a plain crop, a rotated similarity, a mirrored one, one reaching past the
  image border). Also recomputed here exactly (float64 bilinear, round half up, the contract's
  definition): the script prints how many pixels OpenCV puts one level off it.
  `warp_<k>_exact.pgm` holds that exact result: the Rust sampler must equal it to within one level
  on at most 0.15 % of the pixels (its f32 path for patches inside the image rounds differently
  on ~1 pixel in 7,000; its f64 paths are bit-exact); against
  OpenCV the tolerance is |diff| <= 1 everywhere and on at most 2 % of the pixels (OpenCV's border
  handling rounds differently on ~1 % of the pixels of the `border` case).
- `patch_<w>x<h>.pgm` (crops of src at the zone sizes), `bilateral_<w>x<h>.pgm` =
  `cv2.bilateralFilter(patch, 5, 20, 3, borderType=BORDER_REFLECT_101)` (the zones' filter):
  the installed OpenCV 5 truncates the weighted mean to u8 (so does core::landmarks::filter); its
  vectorised kernel sums in another order with fused multiply-adds and a polynomial exp, so results
  within float rounding of an integer land one level off: measured ~3 % of the pixels.
  Tolerance: |diff| <= 1 everywhere and on at most 5 % of the pixels.
- `equalize_<w>x<h>.pgm` = `cv2.equalizeHist(bilateral_<w>x<h>)`. Tolerance: exact.
"""
import json
import os

import cv2
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.abspath(os.path.join(HERE, "..", "..", ".."))


def write_pgm(path, img):
    h, w = img.shape
    with open(path, "wb") as f:
        f.write(b"P5\n%d %d\n255\n" % (w, h))
        f.write(np.ascontiguousarray(img, np.uint8).tobytes())


def luma(bgr):
    rgb = bgr[..., ::-1].astype(np.float64)
    y = 0.299 * rgb[..., 0] + 0.587 * rgb[..., 1] + 0.114 * rgb[..., 2]
    return np.floor(y + 0.5).clip(0, 255).astype(np.uint8)


def opencv_sample(img, A, w, h):
    L, b = A[:, :2], A[:, 2]
    M = np.concatenate([L, (L @ np.array([0.5, 0.5]) + b - 0.5)[:, None]], axis=1)
    return cv2.warpAffine(img, M, (w, h), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                          borderMode=cv2.BORDER_REPLICATE)


def exact_sample(img, A, w, h):
    H, W = img.shape
    f = img.astype(np.float64)
    u, v = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    x = np.clip(A[0, 0] * u + A[0, 1] * v + A[0, 2] - 0.5, -1, W)
    y = np.clip(A[1, 0] * u + A[1, 1] * v + A[1, 2] - 0.5, -1, H)
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = x - x0, y - y0
    x0, y0 = x0.astype(int), y0.astype(int)

    def px(yy, xx):
        return f[np.clip(yy, 0, H - 1), np.clip(xx, 0, W - 1)]

    val = (1 - fy) * ((1 - fx) * px(y0, x0) + fx * px(y0, x0 + 1)) + fy * ((1 - fx) * px(y0 + 1, x0) + fx * px(y0 + 1, x0 + 1))
    return np.floor(val + 0.5).clip(0, 255).astype(np.uint8)


def similarity(p0, p1, q0, q1):
    z = complex(*(np.subtract(p1, p0))) / complex(*(np.subtract(q1, q0)))
    L = np.array([[z.real, -z.imag], [z.imag, z.real]])
    return np.concatenate([L, (np.asarray(p0, float) - L @ q0)[:, None]], axis=1)


def main():
    bgr = cv2.imread(os.path.join(REPO, "samples", "data", "astronaut.jpg"), cv2.IMREAD_COLOR)
    gray = luma(bgr)
    # The face of the astronaut sits around (250, 130) in the 512x512 image: a 2.5x smaller crop.
    big = gray[40:240, 150:390]
    src = cv2.resize(big, (96, 80), interpolation=cv2.INTER_AREA)
    write_pgm(os.path.join(HERE, "src.pgm"), src)

    mirror = np.array([[-1.0, 0, 40], [0, 1, 0], [0, 0, 1]])
    cases = [
        {"name": "crop", "width": 64, "height": 64,
         "map": [[1.3 * 60 / 64, 0, 18.0], [0, 1.3 * 60 / 64, 6.5]]},
        {"name": "rotated", "width": 64, "height": 32,
         "map": similarity([30.2, 41.7], [66.9, 37.1], [12.8, 24.96], [51.2, 24.96]).tolist()},
        {"name": "mirrored", "width": 40, "height": 24,
         "map": (similarity([61.3, 40.2], [50.1, 41.0], [32.0, 13.2], [8.0, 13.2]) @ mirror).tolist()},
        {"name": "border", "width": 48, "height": 48,
         "map": [[2.1, 0.4, -30.0], [-0.4, 2.1, 20.0]]},
    ]
    for c in cases:
        A = np.array(c["map"], float)
        ocv = opencv_sample(src, A, c["width"], c["height"])
        ex = exact_sample(src, A, c["width"], c["height"])
        d = np.abs(ocv.astype(int) - ex)
        print(f"warp {c['name']}: OpenCV vs exact: max {d.max()}, {int((d > 0).sum())} of {d.size} pixels differ")
        write_pgm(os.path.join(HERE, f"warp_{c['name']}.pgm"), ocv)
        write_pgm(os.path.join(HERE, f"warp_{c['name']}_exact.pgm"), ex)
    for w, h, x, y in ((64, 64, 16, 8), (64, 32, 16, 20), (40, 24, 20, 30), (48, 48, 24, 28)):
        patch = np.ascontiguousarray(src[y:y + h, x:x + w])
        if patch.shape != (h, w):
            patch = cv2.resize(src, (w, h), interpolation=cv2.INTER_AREA)
        bf = cv2.bilateralFilter(patch, 5, 20, 3, borderType=cv2.BORDER_REFLECT_101)
        eq = cv2.equalizeHist(bf)
        tag = f"{w}x{h}"
        write_pgm(os.path.join(HERE, f"patch_{tag}.pgm"), patch)
        write_pgm(os.path.join(HERE, f"bilateral_{tag}.pgm"), bf)
        write_pgm(os.path.join(HERE, f"equalize_{tag}.pgm"), eq)
    json.dump({"opencv": cv2.__version__, "bilateral": {"d": 5, "sigma_color": 20.0, "sigma_space": 3.0},
               "patch_sizes": [[64, 64], [64, 32], [40, 24], [48, 48]], "warps": cases},
              open(os.path.join(HERE, "cases.json"), "w"), indent=1)


if __name__ == "__main__":
    main()

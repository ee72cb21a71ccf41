//! Affine sampling of crops and patches (`models/M3_IO.md`, "Sampling convention").
//!
//! A crop or patch of W×H pixels is defined by an affine map A from patch coordinates to image
//! coordinates. Both use the CONTRACT pixel convention (pixel (i, j) has its centre at
//! (i + 0.5, j + 0.5)), so output pixel (u, v) is the bilinear sample of the image at
//! A(u + 0.5, v + 0.5) − (0.5, 0.5) in array-index space, with border pixels replicated outside the
//! image, rounded half up to u8. The training side (OpenCV `warpAffine`, `WARP_INVERSE_MAP`,
//! `BORDER_REPLICATE`, float kernels of OpenCV ≥ 4.11) agrees with this to ±1 on a small share of
//! the pixels (`tests/data/m3_preproc/make_golden.py` measures it).
//!
//! The sampling kernels with a form per instruction set (rotated maps in f32, axis-aligned maps
//! row by row) are `crate::kernels::warp`'s; this module validates, chooses the path and keeps
//! the per-pixel f64 loop of the cases those kernels do not take.

use crate::error::{Error, Result};
use crate::image::GrayImage;
use crate::kernels::warp::{AXIS_MAX_SIDE, ClampedMap, sample_axis_aligned};
use crate::math::Libm;

/// A 2×3 affine map from patch coordinates (u, v) to image coordinates (x, y):
/// `x = m[0]·u + m[1]·v + m[2]`, `y = m[3]·u + m[4]·v + m[5]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Affine {
    /// Row-major coefficients.
    pub m: [f64; 6],
}

impl Affine {
    /// The identity map.
    pub const IDENTITY: Self = Self {
        m: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0],
    };

    /// The level-1 crop map: the `size`² crop covers the axis-aligned square of side `side` centred
    /// on `center` (image pixels).
    pub fn square_crop(center: [f64; 2], side: f64, size: usize) -> Self {
        let k = side / size as f64;
        let half = 0.5 * size as f64;
        Self {
            m: [k, 0.0, center[0] - k * half, 0.0, k, center[1] - k * half],
        }
    }

    /// [`Self::square_crop`] turned by `roll` (radians, image y down) about `center`: the crop's x
    /// axis runs along the image direction (cos roll, sin roll), so a face whose eye line is
    /// turned by `roll` stands upright in the crop. `roll = 0` is [`Self::square_crop`] exactly.
    pub fn turned_square_crop(center: [f64; 2], side: f64, size: usize, roll: f64) -> Self {
        if roll == 0.0 {
            return Self::square_crop(center, side, size);
        }
        let k = side / size as f64;
        let half = 0.5 * size as f64;
        let (c, s) = (roll.mcos(), roll.msin());
        Self {
            m: [
                k * c,
                -k * s,
                center[0] - k * (c - s) * half,
                k * s,
                k * c,
                center[1] - k * (s + c) * half,
            ],
        }
    }

    /// The similarity (rotation + uniform scale + translation, no reflection) that sends patch
    /// points `q0`, `q1` to image points `p0`, `p1`. `None` when `q0 == q1` or any input is not
    /// finite (the map is then undefined); `p0 == p1` gives a degenerate (zero-scale) map, which
    /// samples one pixel everywhere rather than failing.
    pub fn similarity(p0: [f64; 2], p1: [f64; 2], q0: [f64; 2], q1: [f64; 2]) -> Option<Self> {
        let (dqx, dqy) = (q1[0] - q0[0], q1[1] - q0[1]);
        let (dpx, dpy) = (p1[0] - p0[0], p1[1] - p0[1]);
        let n = dqx * dqx + dqy * dqy;
        // z = dp / dq as complex numbers: z = a + i b is the rotation-scale.
        let a = (dpx * dqx + dpy * dqy) / n;
        let b = (dpy * dqx - dpx * dqy) / n;
        let m = [
            a,
            -b,
            p0[0] - (a * q0[0] - b * q0[1]),
            b,
            a,
            p0[1] - (b * q0[0] + a * q0[1]),
        ];
        (n > 0.0 && m.iter().all(|v| v.is_finite())).then_some(Self { m })
    }

    /// The map `(u, v) ↦ self(width − u, v)`: the patch mirrored left–right (`M3_IO.md`, eye
    /// mirroring).
    pub fn mirrored_x(&self, width: f64) -> Self {
        let m = &self.m;
        Self {
            m: [
                -m[0],
                m[1],
                m[0] * width + m[2],
                -m[3],
                m[4],
                m[3] * width + m[5],
            ],
        }
    }

    /// Image point of patch point `p`.
    #[inline]
    pub fn apply(&self, p: [f64; 2]) -> [f64; 2] {
        let m = &self.m;
        [
            m[0] * p[0] + m[1] * p[1] + m[2],
            m[3] * p[0] + m[4] * p[1] + m[5],
        ]
    }

    /// Image direction of patch vector `d` divided by the map's scale (`sqrt|det|`): for a
    /// similarity, the patch axes expressed in the image as unit vectors (reflection included).
    /// `d` unchanged when the map is degenerate.
    pub fn rotate_unit(&self, d: [f64; 2]) -> [f64; 2] {
        let m = &self.m;
        let s = (m[0] * m[4] - m[1] * m[3]).abs().sqrt();
        if s > 0.0 && s.is_finite() {
            [
                (m[0] * d[0] + m[1] * d[1]) / s,
                (m[3] * d[0] + m[4] * d[1]) / s,
            ]
        } else {
            d
        }
    }
}

/// Samples the `width`×`height` patch of `image` under `map` into `out` (row-major, resized to
/// `width·height`; its allocation is reused).
///
/// # Errors
/// [`Error::InvalidInput`] when the image or the patch is empty, or the map is not finite.
pub fn sample(
    image: &GrayImage,
    map: &Affine,
    width: usize,
    height: usize,
    out: &mut Vec<u8>,
) -> Result<()> {
    let (iw, ih) = (image.width(), image.height());
    if iw == 0 || ih == 0 || width == 0 || height == 0 {
        return Err(Error::InvalidInput(format!(
            "cannot sample a {width}x{height} patch from a {iw}x{ih} image"
        )));
    }
    if !map.m.iter().all(|v| v.is_finite()) {
        return Err(Error::InvalidInput(format!(
            "non-finite patch map {:?}",
            map.m
        )));
    }
    out.resize(width * height, 0);
    let m = &map.m;
    if m[1] == 0.0 && m[3] == 0.0 && width <= AXIS_MAX_SIDE && height <= AXIS_MAX_SIDE {
        sample_axis_aligned(image.data(), iw, ih, m, width, out);
    } else if let Some(clamped) = ClampedMap::new(m, iw, ih) {
        clamped.sample(image.data(), iw, ih, width, out);
    } else {
        sample_general(image, m, width, out);
    }
    Ok(())
}

/// [`sample`]'s formula pixel by pixel in f64: the path of images with a side of one pixel or
/// beyond [`ClampedMap::MAX_SIDE`].
fn sample_general(image: &GrayImage, m: &[f64; 6], width: usize, out: &mut [u8]) {
    let (iw, ih) = (image.width(), image.height());
    let data = image.data();
    let (xmax, ymax) = ((iw - 1) as isize, (ih - 1) as isize);
    // Beyond one pixel outside the image every replicated sample equals the edge pixel, so clamping
    // the coordinate there changes nothing and keeps the integer conversion in range.
    let (xlo, xhi) = (-1.0, iw as f64);
    let (ylo, yhi) = (-1.0, ih as f64);
    for (v, row) in out.chunks_exact_mut(width).enumerate() {
        let vc = v as f64 + 0.5;
        for (u, o) in row.iter_mut().enumerate() {
            let uc = u as f64 + 0.5;
            let x = (m[0] * uc + m[1] * vc + m[2] - 0.5).clamp(xlo, xhi);
            let y = (m[3] * uc + m[4] * vc + m[5] - 0.5).clamp(ylo, yhi);
            // x, y ≥ −1 after the clamp, so truncating x + 1 is the floor: no libm `floor` call
            // (x86-64's baseline has no rounding instruction).
            let (x0, y0) = ((x + 1.0) as isize - 1, (y + 1.0) as isize - 1);
            let (fx, fy) = (x - x0 as f64, y - y0 as f64);
            let xa = x0.clamp(0, xmax) as usize;
            let xb = (x0 + 1).clamp(0, xmax) as usize;
            let ra = y0.clamp(0, ymax) as usize * iw;
            let rb = (y0 + 1).clamp(0, ymax) as usize * iw;
            let p00 = f64::from(data[ra + xa]);
            let p01 = f64::from(data[ra + xb]);
            let p10 = f64::from(data[rb + xa]);
            let p11 = f64::from(data[rb + xb]);
            let val =
                (1.0 - fy) * ((1.0 - fx) * p00 + fx * p01) + fy * ((1.0 - fx) * p10 + fx * p11);
            // val ≥ 0: the saturating cast truncates, i.e. floors, and clamps to 255.
            *o = (val + 0.5) as u8;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp(w: usize, h: usize) -> GrayImage {
        let data = (0..w * h)
            .map(|i| ((i % w) * 3 + (i / w) * 5) as u8)
            .collect();
        GrayImage::from_vec(w, h, data).unwrap()
    }

    /// The contract's formula pixel by pixel, as the module docs state it: the reference
    /// [`sample`]'s f64 paths (axis-aligned and general) must equal to the bit, and its f32
    /// interior path to within one level.
    fn sample_per_pixel(image: &GrayImage, m: &[f64; 6], width: usize, height: usize) -> Vec<u8> {
        let (iw, ih) = (image.width() as isize, image.height() as isize);
        let at = |x: isize, y: isize| {
            f64::from(image.get(x.clamp(0, iw - 1) as usize, y.clamp(0, ih - 1) as usize))
        };
        let mut out = Vec::with_capacity(width * height);
        for v in 0..height {
            for u in 0..width {
                let (uc, vc) = (u as f64 + 0.5, v as f64 + 0.5);
                let x = (m[0] * uc + m[1] * vc + m[2] - 0.5).clamp(-1.0, iw as f64);
                let y = (m[3] * uc + m[4] * vc + m[5] - 0.5).clamp(-1.0, ih as f64);
                let (x0, y0) = (x.floor(), y.floor());
                let (fx, fy) = (x - x0, y - y0);
                let (xi, yi) = (x0 as isize, y0 as isize);
                let val = (1.0 - fy) * ((1.0 - fx) * at(xi, yi) + fx * at(xi + 1, yi))
                    + fy * ((1.0 - fx) * at(xi, yi + 1) + fx * at(xi + 1, yi + 1));
                out.push((val + 0.5) as u8);
            }
        }
        out
    }

    /// A 97×61 image of hashed noise (`i · mul >> shift`).
    fn noise(mul: usize, shift: u32) -> GrayImage {
        let data = (0..97 * 61)
            .map(|i: usize| (i.wrapping_mul(mul) >> shift) as u8)
            .collect();
        GrayImage::from_vec(97, 61, data).unwrap()
    }

    /// Uniform numbers in [0, 1) from a 64-bit LCG seeded with `seed`.
    fn uniform(mut seed: u64) -> impl FnMut() -> f64 {
        move || {
            seed = seed
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    /// A rotated map of scale `scale` and angle `angle` putting the `w`×`h` patch's centre at
    /// (cx, cy).
    fn rotated(angle: f64, scale: f64, w: usize, h: usize, cx: f64, cy: f64) -> [f64; 6] {
        let (c, s) = (scale * angle.mcos(), scale * angle.msin());
        let (hw, hh) = (0.5 * w as f64, 0.5 * h as f64);
        [c, -s, cx - c * hw + s * hh, s, c, cy - s * hw - c * hh]
    }

    #[test]
    fn the_f64_paths_equal_the_per_pixel_formula() {
        let img = noise(2_654_435_761, 13);
        let mut rnd = uniform(12345);
        let mut out = Vec::new();
        for case in 0..200 {
            // Rotations, scales from 0.2 to 5, patches inside, across and far outside the image,
            // sizes up to past the axis path's limit.
            let angle = 6.3 * rnd();
            let scale = 0.2 + 4.8 * rnd();
            // Every other case without rotation: the axis-aligned path, with unequal axis scales;
            // the others (and axis-aligned ones past its limit) through the general loop, which
            // `sample` takes for degenerate images.
            let axis = case % 2 == 0;
            let (c, s) = if axis {
                (scale, 0.0)
            } else {
                (scale * angle.mcos(), scale * angle.msin())
            };
            let m = [
                c,
                -s,
                200.0 * rnd() - 50.0,
                s,
                c * (0.5 + rnd()),
                140.0 * rnd() - 40.0,
            ];
            let (w, h) = (1 + (300.0 * rnd()) as usize, 1 + (20.0 * rnd()) as usize);
            if axis && w <= AXIS_MAX_SIDE {
                sample(&img, &Affine { m }, w, h, &mut out).unwrap();
            } else {
                out.resize(w * h, 0);
                sample_general(&img, &m, w, &mut out);
            }
            assert_eq!(
                out,
                sample_per_pixel(&img, &m, w, h),
                "case {case}: {m:?} {w}x{h}"
            );
        }
    }

    #[test]
    fn the_axis_rows_equal_the_formula_at_every_edge_and_width() {
        // Crops over the whole image and past it: first and last rows and columns, the last row
        // through the word ending at its tap, widths with a partial last group of 16, and small
        // images (three columns is the narrowest the gathers take).
        for (iw, ih) in [(97, 61), (3, 2), (5, 1), (2, 7), (40, 3)] {
            let data = (0..iw * ih).map(|i: usize| (i * 37 % 251) as u8).collect();
            let img = GrayImage::from_vec(iw, ih, data).unwrap();
            for (w, h) in [(16, 16), (17, 5), (31, 40), (64, 64), (200, 3)] {
                for (sx, ox) in [(iw as f64 / w as f64, 0.0), (1.7, -20.0), (0.3, 1.1)] {
                    let sy = ih as f64 / h as f64;
                    for oy in [0.0, -3.0, 2.5] {
                        let m = [sx, 0.0, ox, 0.0, sy, oy];
                        let mut out = Vec::new();
                        sample(&img, &Affine { m }, w, h, &mut out).unwrap();
                        let want = sample_per_pixel(&img, &m, w, h);
                        assert_eq!(out, want, "{iw}x{ih} image, {w}x{h} patch, {m:?}");
                    }
                }
            }
        }
    }

    #[test]
    fn the_clamped_path_is_within_one_of_the_per_pixel_formula() {
        let img = noise(2_246_822_519, 11);
        let mut rnd = uniform(777);
        let (mut out, mut pixels, mut off_by_one, mut across) = (Vec::new(), 0, 0, 0);
        for case in 0..600 {
            // Rotated patches around the image, inside, across an edge or a corner, and (every
            // tenth case) far outside it.
            let (angle, scale) = (6.3 * rnd(), 0.1 + 1.4 * rnd());
            let (w, h) = (1 + (64.0 * rnd()) as usize, 1 + (48.0 * rnd()) as usize);
            let far = if case % 10 == 0 { 1e4 } else { 1.0 };
            let (cx, cy) = (
                48.5 + far * 130.0 * (rnd() - 0.5),
                30.5 + far * 90.0 * (rnd() - 0.5),
            );
            let m = rotated(angle, scale, w, h, cx, cy);
            sample(&img, &Affine { m }, w, h, &mut out).unwrap();
            let want = sample_per_pixel(&img, &m, w, h);
            // An affine map takes its extremes over the patch at the corners' pixel centres.
            let (ul, vl) = (w as f64 - 0.5, h as f64 - 0.5);
            let inside = [(0.5, 0.5), (ul, 0.5), (0.5, vl), (ul, vl)]
                .into_iter()
                .all(|(uc, vc)| {
                    let x = m[0] * uc + m[1] * vc + m[2] - 0.5;
                    let y = m[3] * uc + m[4] * vc + m[5] - 0.5;
                    (0.0..96.0).contains(&x) && (0.0..60.0).contains(&y)
                });
            across += usize::from(!inside);
            for (i, (&a, &b)) in out.iter().zip(&want).enumerate() {
                let d = (i32::from(a) - i32::from(b)).abs();
                assert!(d <= 1, "case {case} pixel {i}: {a} vs {b}; {m:?} {w}x{h}");
                off_by_one += usize::from(d == 1);
            }
            pixels += out.len();
        }
        assert!(across > 200, "only {across} of 600 patches reach outside");
        // f32 rounding moves a value across a .5 boundary only when it lies within ~1e-3 of it.
        assert!(
            off_by_one * 200 < pixels,
            "{off_by_one} of {pixels} pixels off by one"
        );
        eprintln!("{off_by_one} of {pixels} pixels off by one");
    }

    #[test]
    fn the_clamped_path_handles_the_smallest_images() {
        // Two-pixel sides: the top-left tap is capped at index 0 there and every read must stay
        // inside the 4-, 6- or 10-byte image (the gathers read four bytes from each tap).
        let mut rnd = uniform(99);
        let mut out = Vec::new();
        for (iw, ih) in [(2, 2), (3, 2), (2, 3), (5, 2), (2, 5)] {
            let data = (0..iw * ih).map(|i| (i * 37 + 11) as u8).collect();
            let img = GrayImage::from_vec(iw, ih, data).unwrap();
            for _ in 0..50 {
                let m = rotated(
                    6.3 * rnd(),
                    0.05 + 0.5 * rnd(),
                    9,
                    7,
                    iw as f64 * (2.0 * rnd() - 0.5),
                    ih as f64 * (2.0 * rnd() - 0.5),
                );
                sample(&img, &Affine { m }, 9, 7, &mut out).unwrap();
                let want = sample_per_pixel(&img, &m, 9, 7);
                for (&a, &b) in out.iter().zip(&want) {
                    assert!(a.abs_diff(b) <= 1, "{iw}x{ih} {m:?}: {a} vs {b}");
                }
            }
        }
    }

    #[test]
    fn identity_map_copies_the_image() {
        let img = ramp(20, 10);
        let mut out = Vec::new();
        sample(&img, &Affine::IDENTITY, 20, 10, &mut out).unwrap();
        assert_eq!(out, img.data());
    }

    #[test]
    fn half_pixel_shift_averages_neighbours_and_rounds_half_up() {
        let img = GrayImage::from_vec(2, 1, vec![10, 13]).unwrap();
        let map = Affine {
            m: [1.0, 0.0, 0.5, 0.0, 1.0, 0.0],
        };
        let mut out = Vec::new();
        sample(&img, &map, 2, 1, &mut out).unwrap();
        // 11.5 rounds up to 12; beyond the right edge the border pixel is replicated.
        assert_eq!(out, vec![12, 13]);
    }

    #[test]
    fn far_outside_replicates_the_border() {
        let img = ramp(8, 8);
        let map = Affine {
            m: [1.0, 0.0, -1e9, 0.0, 1.0, 1e9],
        };
        let mut out = Vec::new();
        sample(&img, &map, 3, 3, &mut out).unwrap();
        assert!(out.iter().all(|&v| v == img.get(0, 7)));
    }

    #[test]
    fn similarity_sends_q_to_p_and_mirroring_flips_u() {
        let (p0, p1) = ([10.0, 20.0], [30.0, 25.0]);
        let (q0, q1) = ([8.0, 13.0], [32.0, 13.0]);
        let a = Affine::similarity(p0, p1, q0, q1).unwrap();
        for (p, q) in [(p0, q0), (p1, q1)] {
            let r = a.apply(q);
            assert!((r[0] - p[0]).abs() < 1e-9 && (r[1] - p[1]).abs() < 1e-9);
        }
        let w = 40.0;
        let mirrored = a.mirrored_x(w);
        let r = mirrored.apply([w - q0[0], q0[1]]);
        assert!((r[0] - p0[0]).abs() < 1e-9 && (r[1] - p0[1]).abs() < 1e-9);
        // Unit axes: the mirrored map's u axis points the other way.
        let (e, f) = (a.rotate_unit([1.0, 0.0]), mirrored.rotate_unit([1.0, 0.0]));
        assert!((e[0] + f[0]).abs() < 1e-12 && (e[1] + f[1]).abs() < 1e-12);
        assert!(((e[0] * e[0] + e[1] * e[1]) - 1.0).abs() < 1e-12);
        assert!(Affine::similarity(p0, p1, q0, q0).is_none());
    }

    #[test]
    fn bad_input_is_an_error() {
        let img = ramp(4, 4);
        let mut out = Vec::new();
        assert!(sample(&GrayImage::new(0, 0), &Affine::IDENTITY, 2, 2, &mut out).is_err());
        assert!(sample(&img, &Affine::IDENTITY, 0, 2, &mut out).is_err());
        let nan = Affine {
            m: [f64::NAN, 0.0, 0.0, 0.0, 1.0, 0.0],
        };
        assert!(matches!(
            sample(&img, &nan, 2, 2, &mut out),
            Err(Error::InvalidInput(_))
        ));
    }
}

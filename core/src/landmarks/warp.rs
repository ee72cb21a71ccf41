//! Affine sampling of crops and patches (`models/M3_IO.md`, "Sampling convention").
//!
//! A crop or patch of W×H pixels is defined by an affine map A from patch coordinates to image
//! coordinates. Both use the CONTRACT pixel convention (pixel (i, j) has its centre at
//! (i + 0.5, j + 0.5)), so output pixel (u, v) is the bilinear sample of the image at
//! A(u + 0.5, v + 0.5) − (0.5, 0.5) in array-index space, with border pixels replicated outside the
//! image, rounded half up to u8. The training side (OpenCV `warpAffine`, `WARP_INVERSE_MAP`,
//! `BORDER_REPLICATE`, float kernels of OpenCV ≥ 4.11) agrees with this to ±1 on about 1 pixel in
//! 15,000 (measured by `tests/data/m3_preproc/make_golden.py`).

use crate::error::{Error, Result};
use crate::image::GrayImage;

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
        let (c, s) = (roll.cos(), roll.sin());
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
        sample_axis_aligned(image, m, width, out);
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

/// A rotated map sampled in f32 over chunks of [`ClampedMap::CHUNK`] pixels, so the coordinate
/// and blend passes vectorise, for any placement of the patch: each coordinate is clamped to the
/// rectangle of the image's pixel centres, which is exact (beyond the last centre the replicated
/// border makes the bilinear sample the edge pixel's value), and the top-left tap to one pixel
/// inside the last column and row, with the weight then 1 on the far tap. One level off the f64
/// formula on about 1 pixel in 7,000 (unit test), far inside the training side's own ±1 agreement
/// (module docs). On x86-64 with AVX2 the taps come from hardware gathers (same bytes).
///
/// Why every placement: faces whose patches reach past the image edge (large faces, faces at the
/// border) took the f64 loop before (about 20 µs a patch); on the faces68 validation faces M3's
/// time per face in mirror average (each face warm, median of 30 runs) ranged 350–514 µs
/// before, the slow end being such faces, and 356–436 µs after.
struct ClampedMap<'a> {
    m: &'a [f64; 6],
}

impl<'a> ClampedMap<'a> {
    /// Pixels per vectorised chunk: two AVX-512 or four NEON f32 registers.
    const CHUNK: usize = 16;
    /// Largest image side: f32 coordinates below 2^14 round by under 0.001 px.
    const MAX_SIDE: usize = 1 << 14;

    fn new(m: &'a [f64; 6], iw: usize, ih: usize) -> Option<Self> {
        (iw >= 2 && ih >= 2 && iw.max(ih) <= Self::MAX_SIDE).then_some(Self { m })
    }

    /// Samples the patch: through hardware gathers where the CPU has AVX2 (the same bytes as
    /// [`ClampedMap::sample_body`]: unit test), else through the body.
    fn sample(&self, data: &[u8], iw: usize, ih: usize, width: usize, out: &mut [u8]) {
        // The gathers' bounds rest on `data` being the whole iw × ih image: checked here, not
        // assumed, since a violation would be a read out of bounds rather than a panic.
        #[cfg(target_arch = "x86_64")]
        if data.len() == iw * ih && crate::kernels::cpu::has_avx2_fma() {
            #[allow(unsafe_code)]
            // SAFETY: the CPU has the features each function is compiled for (AVX-512F through
            // `Products::Avx512`, which includes AVX2 and FMA).
            unsafe {
                if crate::nn::conv::Products::Avx512.supported() {
                    self.sample_gather_avx512(data, iw, ih, width, out)
                } else {
                    self.sample_gather_avx2(data, iw, ih, width, out)
                }
            };
            return;
        }
        self.sample_scalar(data, iw, ih, width, out);
    }

    crate::kernels::cpu::with_avx2_copy! {
        fn sample_scalar / sample_avx2 (&self, data: &[u8], iw: usize, ih: usize, width: usize,
            out: &mut [u8]) => sample_body
    }

    /// [`ClampedMap::sample_body`] with the four taps of eight pixels read by two AVX2 gathers of
    /// four bytes each (a tap pair of the upper and of the lower row per pixel), the u8 → f32
    /// conversions and the final rounding in vector registers. The body's compiled loop spent its
    /// time in scalar conversions, stores of single lanes reloaded as vectors (store-forwarding
    /// stalls) and a scalar saturating cast per pixel; the arithmetic and its order are the body's,
    /// so the bytes are too.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn sample_gather_avx2(&self, data: &[u8], iw: usize, ih: usize, width: usize, out: &mut [u8]) {
        use crate::kernels::cpu::avx2::store_u8x8;
        use std::arch::x86_64::{
            __m256, __m256i, _mm256_add_epi32, _mm256_add_ps, _mm256_and_si256, _mm256_cvtepi32_ps,
            _mm256_cvttps_epi32, _mm256_i32gather_epi32, _mm256_max_ps, _mm256_min_epi32,
            _mm256_min_ps, _mm256_mul_ps, _mm256_mullo_epi32, _mm256_set1_epi32, _mm256_set1_ps,
            _mm256_setr_ps, _mm256_setzero_ps, _mm256_srli_epi32, _mm256_sub_ps,
        };
        const N: usize = ClampedMap::CHUNK;
        assert!(iw >= 2 && ih >= 2 && data.len() == iw * ih);
        let m = self.m;
        let (dx, dy) = (_mm256_set1_ps(m[0] as f32), _mm256_set1_ps(m[3] as f32));
        let ramps = [
            _mm256_setr_ps(0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0),
            _mm256_setr_ps(8.0, 9.0, 10.0, 11.0, 12.0, 13.0, 14.0, 15.0),
        ];
        // The body's offsets within a chunk, `d · k`, computed once.
        let steps = ramps.map(|r| (_mm256_mul_ps(dx, r), _mm256_mul_ps(dy, r)));
        let zero = _mm256_setzero_ps();
        let (x_cap, y_cap) = (
            _mm256_set1_ps((iw - 1) as f32),
            _mm256_set1_ps((ih - 1) as f32),
        );
        let (x0_cap, y0_cap) = (
            _mm256_set1_epi32(iw as i32 - 2),
            _mm256_set1_epi32(ih as i32 - 2),
        );
        let (half, byte, stride) = (
            _mm256_set1_ps(0.5),
            _mm256_set1_epi32(0xff),
            _mm256_set1_epi32(iw as i32),
        );
        // The lower tap pair is read as bytes 2 and 3 of the word two bytes before it, so that
        // the word of the last pair of the image ends at its last byte.
        let upper = data.as_ptr().cast::<i32>();
        let lower = data[iw - 2..].as_ptr().cast::<i32>();
        // Lanes 0..8 of a tap pair word as f32: its first and second byte.
        let taps = |w: __m256i| -> (__m256, __m256) {
            (
                _mm256_cvtepi32_ps(_mm256_and_si256(w, byte)),
                _mm256_cvtepi32_ps(_mm256_and_si256(_mm256_srli_epi32::<8>(w), byte)),
            )
        };
        let mut bytes = [0u8; N];
        for (v, row) in out.chunks_exact_mut(width).enumerate() {
            let vc = v as f64 + 0.5;
            for (c, chunk) in row.chunks_mut(N).enumerate() {
                let uc = (c * N) as f64 + 0.5;
                let x_org = _mm256_set1_ps((m[0] * uc + m[1] * vc + m[2] - 0.5) as f32);
                let y_org = _mm256_set1_ps((m[3] * uc + m[4] * vc + m[5] - 0.5) as f32);
                for (half_chunk, &(sx, sy)) in steps.iter().enumerate() {
                    // max first: it returns its second operand (0) for a NaN lane.
                    let x = _mm256_min_ps(_mm256_max_ps(_mm256_add_ps(x_org, sx), zero), x_cap);
                    let y = _mm256_min_ps(_mm256_max_ps(_mm256_add_ps(y_org, sy), zero), y_cap);
                    let x0 = _mm256_min_epi32(_mm256_cvttps_epi32(x), x0_cap);
                    let y0 = _mm256_min_epi32(_mm256_cvttps_epi32(y), y0_cap);
                    let fx = _mm256_sub_ps(x, _mm256_cvtepi32_ps(x0));
                    let fy = _mm256_sub_ps(y, _mm256_cvtepi32_ps(y0));
                    let idx = _mm256_add_epi32(_mm256_mullo_epi32(y0, stride), x0);
                    #[allow(unsafe_code)]
                    // SAFETY: 0 ≤ idx ≤ (ih − 2)·iw + iw − 2 (the clamps above), so the four
                    // bytes at `upper + idx` end by (ih − 1)·iw + 1 < iw·ih, and those at
                    // `lower + idx` = `upper + iw − 2 + idx` start at iw − 2 ≥ 0 and end by
                    // iw·ih − 1.
                    let (t, b) = unsafe {
                        (
                            _mm256_i32gather_epi32::<1>(upper, idx),
                            _mm256_i32gather_epi32::<1>(lower, idx),
                        )
                    };
                    let (p00, p01) = taps(t);
                    let (p10, p11) = taps(_mm256_srli_epi32::<16>(b));
                    let top = _mm256_add_ps(p00, _mm256_mul_ps(fx, _mm256_sub_ps(p01, p00)));
                    let bottom = _mm256_add_ps(p10, _mm256_mul_ps(fx, _mm256_sub_ps(p11, p10)));
                    let val = _mm256_add_ps(
                        _mm256_add_ps(top, _mm256_mul_ps(fy, _mm256_sub_ps(bottom, top))),
                        half,
                    );
                    // val ≥ 0.5: truncation floors it, and the packs saturate at 255 as the
                    // body's cast does.
                    let dst = &mut bytes[half_chunk * 8..half_chunk * 8 + 8];
                    store_u8x8(_mm256_cvttps_epi32(val), dst);
                }
                chunk.copy_from_slice(&bytes[..chunk.len()]);
            }
        }
    }

    /// [`ClampedMap::sample_gather_avx2`] on 16 lanes: one gather per tap pair and row for the
    /// whole chunk, the same arithmetic per lane, so the same bytes.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f,avx2,fma")]
    fn sample_gather_avx512(
        &self,
        data: &[u8],
        iw: usize,
        ih: usize,
        width: usize,
        out: &mut [u8],
    ) {
        use std::arch::x86_64::{
            __m128i, __m512, __m512i, _mm_storeu_si128, _mm512_add_epi32, _mm512_add_ps,
            _mm512_and_si512, _mm512_cvtepi32_ps, _mm512_cvttps_epi32, _mm512_cvtusepi32_epi8,
            _mm512_i32gather_epi32, _mm512_max_ps, _mm512_min_epi32, _mm512_min_ps, _mm512_mul_ps,
            _mm512_mullo_epi32, _mm512_set1_epi32, _mm512_set1_ps, _mm512_setr_ps,
            _mm512_setzero_ps, _mm512_srli_epi32, _mm512_sub_ps,
        };
        const N: usize = ClampedMap::CHUNK;
        assert!(iw >= 2 && ih >= 2 && data.len() == iw * ih);
        let m = self.m;
        let ramp = _mm512_setr_ps(
            0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0, 10.0, 11.0, 12.0, 13.0, 14.0, 15.0,
        );
        let sx = _mm512_mul_ps(_mm512_set1_ps(m[0] as f32), ramp);
        let sy = _mm512_mul_ps(_mm512_set1_ps(m[3] as f32), ramp);
        let zero = _mm512_setzero_ps();
        let (x_cap, y_cap) = (
            _mm512_set1_ps((iw - 1) as f32),
            _mm512_set1_ps((ih - 1) as f32),
        );
        let (x0_cap, y0_cap) = (
            _mm512_set1_epi32(iw as i32 - 2),
            _mm512_set1_epi32(ih as i32 - 2),
        );
        let (half, byte, stride) = (
            _mm512_set1_ps(0.5),
            _mm512_set1_epi32(0xff),
            _mm512_set1_epi32(iw as i32),
        );
        // As in the AVX2 kernel: the lower tap pair is bytes 2 and 3 of the word two bytes
        // before it.
        let upper = data.as_ptr();
        let lower = data[iw - 2..].as_ptr();
        let taps = |w: __m512i| -> (__m512, __m512) {
            (
                _mm512_cvtepi32_ps(_mm512_and_si512(w, byte)),
                _mm512_cvtepi32_ps(_mm512_and_si512(_mm512_srli_epi32::<8>(w), byte)),
            )
        };
        let mut bytes = [0u8; N];
        for (v, row) in out.chunks_exact_mut(width).enumerate() {
            let vc = v as f64 + 0.5;
            for (c, chunk) in row.chunks_mut(N).enumerate() {
                let uc = (c * N) as f64 + 0.5;
                let x_org = _mm512_set1_ps((m[0] * uc + m[1] * vc + m[2] - 0.5) as f32);
                let y_org = _mm512_set1_ps((m[3] * uc + m[4] * vc + m[5] - 0.5) as f32);
                // max first: it returns its second operand (0) for a NaN lane.
                let x = _mm512_min_ps(_mm512_max_ps(_mm512_add_ps(x_org, sx), zero), x_cap);
                let y = _mm512_min_ps(_mm512_max_ps(_mm512_add_ps(y_org, sy), zero), y_cap);
                let x0 = _mm512_min_epi32(_mm512_cvttps_epi32(x), x0_cap);
                let y0 = _mm512_min_epi32(_mm512_cvttps_epi32(y), y0_cap);
                let fx = _mm512_sub_ps(x, _mm512_cvtepi32_ps(x0));
                let fy = _mm512_sub_ps(y, _mm512_cvtepi32_ps(y0));
                let idx = _mm512_add_epi32(_mm512_mullo_epi32(y0, stride), x0);
                #[allow(unsafe_code)]
                // SAFETY: as in the AVX2 kernel, 0 ≤ idx ≤ (ih − 2)·iw + iw − 2, so the words
                // at `upper + idx` and `lower + idx` lie inside `data`.
                let (t, b) = unsafe {
                    (
                        _mm512_i32gather_epi32::<1>(idx, upper.cast()),
                        _mm512_i32gather_epi32::<1>(idx, lower.cast()),
                    )
                };
                let (p00, p01) = taps(t);
                let (p10, p11) = taps(_mm512_srli_epi32::<16>(b));
                let top = _mm512_add_ps(p00, _mm512_mul_ps(fx, _mm512_sub_ps(p01, p00)));
                let bottom = _mm512_add_ps(p10, _mm512_mul_ps(fx, _mm512_sub_ps(p11, p10)));
                let val = _mm512_add_ps(
                    _mm512_add_ps(top, _mm512_mul_ps(fy, _mm512_sub_ps(bottom, top))),
                    half,
                );
                // val ≥ 0.5: truncation floors it; the narrowing saturates at 255 as the body's
                // cast does.
                #[allow(unsafe_code)]
                // SAFETY: `bytes` holds the 16 bytes stored.
                unsafe {
                    _mm_storeu_si128(
                        bytes.as_mut_ptr().cast::<__m128i>(),
                        _mm512_cvtusepi32_epi8(_mm512_cvttps_epi32(val)),
                    )
                };
                chunk.copy_from_slice(&bytes[..chunk.len()]);
            }
        }
    }

    #[inline(always)]
    fn sample_body(&self, data: &[u8], iw: usize, ih: usize, width: usize, out: &mut [u8]) {
        const N: usize = ClampedMap::CHUNK;
        let m = self.m;
        let (dx, dy) = (m[0] as f32, m[3] as f32);
        let ramp: [f32; N] = std::array::from_fn(|k| k as f32);
        let (x_cap, y_cap) = ((iw - 1) as f32, (ih - 1) as f32);
        let (x0_cap, y0_cap) = (iw as u32 - 2, ih as u32 - 2);
        // Each tap pair's lower row, and the largest index of a top-left tap.
        let below = &data[iw..];
        let last = below.len() - 2;
        let (mut idx, mut fx, mut fy) = ([0usize; N], [0f32; N], [0f32; N]);
        let (mut p00, mut p01, mut p10, mut p11) = ([0f32; N], [0f32; N], [0f32; N], [0f32; N]);
        for (v, row) in out.chunks_exact_mut(width).enumerate() {
            let vc = v as f64 + 0.5;
            for (c, chunk) in row.chunks_mut(N).enumerate() {
                // Chunk origins in f64, offsets within a chunk in f32: errors stay ~1e-4 px.
                let uc = (c * N) as f64 + 0.5;
                let x_org = (m[0] * uc + m[1] * vc + m[2] - 0.5) as f32;
                let y_org = (m[3] * uc + m[4] * vc + m[5] - 0.5) as f32;
                let n = chunk.len();
                for k in 0..N {
                    // `as u32` saturates (NaN → 0), so every lane's taps stay in the image.
                    let x = (x_org + dx * ramp[k]).clamp(0.0, x_cap);
                    let y = (y_org + dy * ramp[k]).clamp(0.0, y_cap);
                    let (x0, y0) = ((x as u32).min(x0_cap), (y as u32).min(y0_cap));
                    fx[k] = x - x0 as f32;
                    fy[k] = y - y0 as f32;
                    idx[k] = y0 as usize * iw + x0 as usize;
                }
                for k in 0..n {
                    // An identity (the clamps above bound idx by `last`) that lets the compiler
                    // drop the four bounds checks: 25 % off this kernel in a standalone loop over
                    // a 640×480 image, within run-to-run noise in the criterion bench.
                    let i = idx[k].min(last);
                    p00[k] = f32::from(data[i]);
                    p01[k] = f32::from(data[i + 1]);
                    p10[k] = f32::from(below[i]);
                    p11[k] = f32::from(below[i + 1]);
                }
                for k in 0..N {
                    let top = p00[k] + fx[k] * (p01[k] - p00[k]);
                    let bottom = p10[k] + fx[k] * (p11[k] - p10[k]);
                    fx[k] = top + fy[k] * (bottom - top) + 0.5;
                }
                for (o, &val) in chunk.iter_mut().zip(&fx) {
                    // The saturating cast floors val ≥ 0 and keeps f32 overshoot at 255.
                    *o = val as u8;
                }
            }
        }
    }
}

/// Largest side [`sample`]'s axis-aligned path handles (its tap tables live on the stack).
const AXIS_MAX_SIDE: usize = 256;

/// One source tap pair and the weight of the second.
type Tap = (usize, usize, f64);

/// One axis of an axis-aligned map: for each of the first `n` output indices the two source taps
/// (multiplied by `stride`) and the weight of the second, clamped as in [`sample`].
fn axis_taps(scale: f64, offset: f64, len: usize, stride: usize, taps: &mut [Tap]) {
    let max = (len - 1) as isize;
    for (i, t) in taps.iter_mut().enumerate() {
        // The general formula's value: its cross term is an exact zero.
        let c = i as f64 + 0.5;
        let x = (scale * c + offset - 0.5).clamp(-1.0, len as f64);
        let x0 = (x + 1.0) as isize - 1;
        let a = x0.clamp(0, max) as usize * stride;
        let b = (x0 + 1).clamp(0, max) as usize * stride;
        *t = (a, b, x - x0 as f64);
    }
}

/// [`sample`] for maps without rotation (the level-1 crop): x depends on u only and y on v only,
/// so taps and weights are computed once per column and once per row instead of per pixel, with
/// the same f64 operations (the same bytes out). With AVX-512 the rows go 16 pixels at a time
/// ([`axis_row_avx512`]): the per-pixel loop spent its time on a scalar conversion and a byte
/// store per pixel (8 % of `m3_per_face`).
fn sample_axis_aligned(image: &GrayImage, m: &[f64; 6], width: usize, out: &mut [u8]) {
    let (iw, ih) = (image.width(), image.height());
    let height = out.len() / width;
    let mut cols = [(0, 0, 0.0); AXIS_MAX_SIDE];
    let mut rows = [(0, 0, 0.0); AXIS_MAX_SIDE];
    axis_taps(m[0], m[2], iw, 1, &mut cols[..width]);
    axis_taps(m[4], m[5], ih, iw, &mut rows[..height]);
    let (cols, rows) = (&cols[..width], &rows[..height]);
    let data = image.data();
    #[cfg(target_arch = "x86_64")]
    if width >= AXIS_LANES
        && data.len() == iw * ih
        && i32::try_from(data.len()).is_ok()
        && crate::nn::conv::Products::Avx512.supported()
    {
        let mut taps = AxisColumns {
            a: [0; AXIS_MAX_SIDE],
            b: [0; AXIS_MAX_SIDE],
            wa: [0.0; AXIS_MAX_SIDE],
            wb: [0.0; AXIS_MAX_SIDE],
        };
        for (c, &(xa, xb, fx)) in cols.iter().enumerate() {
            // Both below iw, which fits i32 (checked above).
            (taps.a[c], taps.b[c]) = (xa as i32, xb as i32);
            (taps.wa[c], taps.wb[c]) = (1.0 - fx, fx);
        }
        for (row, &(ra, rb, fy)) in out.chunks_exact_mut(width).zip(rows) {
            #[allow(unsafe_code)]
            // SAFETY: the CPU has AVX-512F, AVX2 and FMA (`Products::Avx512`); `data` is the
            // whole image and its length fits i32; ra and rb start rows of it.
            unsafe {
                axis_row_avx512(data, iw, ra, rb, fy, &taps, cols, row)
            };
        }
        return;
    }
    for (row, &(ra, rb, fy)) in out.chunks_exact_mut(width).zip(rows) {
        axis_row(data, iw, ra, rb, fy, cols, row);
    }
}

/// One output row of [`sample_axis_aligned`] pixel by pixel: source rows starting at `ra` and
/// `rb`, their weights `1 − fy` and `fy`.
fn axis_row(data: &[u8], iw: usize, ra: usize, rb: usize, fy: f64, cols: &[Tap], row: &mut [u8]) {
    let (top, bottom) = (&data[ra..ra + iw], &data[rb..rb + iw]);
    for (o, &(xa, xb, fx)) in row.iter_mut().zip(cols) {
        let (p00, p01) = (f64::from(top[xa]), f64::from(top[xb]));
        let (p10, p11) = (f64::from(bottom[xa]), f64::from(bottom[xb]));
        let val = (1.0 - fy) * ((1.0 - fx) * p00 + fx * p01) + fy * ((1.0 - fx) * p10 + fx * p11);
        *o = (val + 0.5) as u8;
    }
}

/// Pixels per step of [`axis_row_avx512`]: one 16-lane gather of each tap.
#[cfg(target_arch = "x86_64")]
const AXIS_LANES: usize = 16;

/// The column taps of [`sample_axis_aligned`] as the AVX-512 rows read them: the two taps'
/// indices in a row and their weights `1 − fx` and `fx`.
#[cfg(target_arch = "x86_64")]
struct AxisColumns {
    a: [i32; AXIS_MAX_SIDE],
    b: [i32; AXIS_MAX_SIDE],
    wa: [f64; AXIS_MAX_SIDE],
    wb: [f64; AXIS_MAX_SIDE],
}

/// [`axis_row`] 16 pixels at a time: each tap of 16 pixels is one gather of 32-bit words whose
/// first byte (or, for a row too near the end of the image for a word to fit after the tap, the
/// last byte of the word ending at the tap) is the pixel; then the formula's f64 products and sums
/// in the same order, so the same bytes. The last, partial group overlaps the one before it.
///
/// # Safety
/// The CPU has AVX-512F, AVX2 and FMA; `data` is the whole `iw`-wide image, its length fits i32,
/// `ra` and `rb` are the offsets of two of its rows, and `taps` holds `cols` (at least
/// [`AXIS_LANES`] of them, each below `iw`).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx2,fma")]
#[allow(unsafe_code, clippy::too_many_arguments)]
unsafe fn axis_row_avx512(
    data: &[u8],
    iw: usize,
    ra: usize,
    rb: usize,
    fy: f64,
    taps: &AxisColumns,
    cols: &[Tap],
    row: &mut [u8],
) {
    use std::arch::x86_64::{
        __m128i, __m512d, __m512i, _mm_storeu_si128, _mm512_add_pd, _mm512_and_si512,
        _mm512_castsi256_si512, _mm512_castsi512_si256, _mm512_cvtepi32_pd, _mm512_cvttpd_epi32,
        _mm512_cvtusepi32_epi8, _mm512_extracti64x4_epi64, _mm512_i32gather_epi32,
        _mm512_inserti64x4, _mm512_loadu_pd, _mm512_loadu_si512, _mm512_mul_pd, _mm512_set1_epi32,
        _mm512_set1_pd, _mm512_srli_epi32,
    };
    let width = row.len();
    assert!(width >= AXIS_LANES && width == cols.len() && width <= AXIS_MAX_SIDE);
    // Where the four bytes after a tap stay inside the image the word starts at the tap;
    // otherwise (the last row) it ends there, which needs three bytes before the row.
    let base = |r: usize| -> Option<(*const u8, bool)> {
        if r + iw + 3 <= data.len() {
            Some((data[r..].as_ptr(), true))
        } else if r >= 3 {
            Some((data[r - 3..].as_ptr(), false))
        } else {
            None
        }
    };
    let (Some((top, top_fwd)), Some((bottom, bottom_fwd))) = (base(ra), base(rb)) else {
        axis_row(data, iw, ra, rb, fy, cols, row);
        return;
    };
    let byte = _mm512_set1_epi32(0xff);
    let pixel = |w: __m512i, forward: bool| -> [__m512d; 2] {
        let v = if forward {
            _mm512_and_si512(w, byte)
        } else {
            _mm512_srli_epi32::<24>(w)
        };
        [
            _mm512_cvtepi32_pd(_mm512_castsi512_si256(v)),
            _mm512_cvtepi32_pd(_mm512_extracti64x4_epi64::<1>(v)),
        ]
    };
    let (gy, fyv, half) = (
        _mm512_set1_pd(1.0 - fy),
        _mm512_set1_pd(fy),
        _mm512_set1_pd(0.5),
    );
    let mut c0 = 0;
    loop {
        let c = c0.min(width - AXIS_LANES);
        // SAFETY: c + 16 ≤ width ≤ AXIS_MAX_SIDE, so the loads stay inside the arrays.
        let (xa, xb) = unsafe {
            (
                _mm512_loadu_si512(taps.a[c..c + AXIS_LANES].as_ptr().cast()),
                _mm512_loadu_si512(taps.b[c..c + AXIS_LANES].as_ptr().cast()),
            )
        };
        // SAFETY: every index is below iw, so each gathered word lies inside `data` (`base`).
        let (p00, p01, p10, p11) = unsafe {
            (
                pixel(_mm512_i32gather_epi32::<1>(xa, top.cast()), top_fwd),
                pixel(_mm512_i32gather_epi32::<1>(xb, top.cast()), top_fwd),
                pixel(_mm512_i32gather_epi32::<1>(xa, bottom.cast()), bottom_fwd),
                pixel(_mm512_i32gather_epi32::<1>(xb, bottom.cast()), bottom_fwd),
            )
        };
        let ints: [_; 2] = std::array::from_fn(|h| {
            let at = c + 8 * h;
            // SAFETY: at + 8 ≤ c + 16 ≤ AXIS_MAX_SIDE.
            let (wa, wb) = unsafe {
                (
                    _mm512_loadu_pd(taps.wa[at..at + 8].as_ptr()),
                    _mm512_loadu_pd(taps.wb[at..at + 8].as_ptr()),
                )
            };
            let upper = _mm512_add_pd(_mm512_mul_pd(wa, p00[h]), _mm512_mul_pd(wb, p01[h]));
            let lower = _mm512_add_pd(_mm512_mul_pd(wa, p10[h]), _mm512_mul_pd(wb, p11[h]));
            let val = _mm512_add_pd(
                _mm512_add_pd(_mm512_mul_pd(gy, upper), _mm512_mul_pd(fyv, lower)),
                half,
            );
            // val ≥ 0.5: truncation floors it, as the scalar cast does.
            _mm512_cvttpd_epi32(val)
        });
        let words = _mm512_inserti64x4::<1>(_mm512_castsi256_si512(ints[0]), ints[1]);
        let dst: &mut [u8; AXIS_LANES] = (&mut row[c..c + AXIS_LANES]).try_into().expect("16");
        // SAFETY: `dst` holds the 16 bytes stored; the narrowing saturates at 255 as the cast.
        unsafe {
            _mm_storeu_si128(
                dst.as_mut_ptr().cast::<__m128i>(),
                _mm512_cvtusepi32_epi8(words),
            )
        };
        c0 += AXIS_LANES;
        if c0 >= width {
            break;
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
        let (c, s) = (scale * angle.cos(), scale * angle.sin());
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
                (scale * angle.cos(), scale * angle.sin())
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

    #[cfg(target_arch = "x86_64")]
    #[test]
    #[cfg_attr(not(host_avx2_fma), ignore = "this CPU runs no AVX2 + FMA kernels")]
    fn the_avx2_and_avx512_copies_of_the_clamped_path_give_the_same_bytes() {
        crate::kernels::cpu::assert_avx2_fma_path();
        let mut rnd = uniform(4242);
        for (iw, ih) in [(97, 61), (2, 2), (3, 5)] {
            let data = (0..iw * ih)
                .map(|i: usize| (i.wrapping_mul(2_654_435_761) >> 12) as u8)
                .collect();
            let img = GrayImage::from_vec(iw, ih, data).unwrap();
            for case in 0..300 {
                let (w, h) = (1 + (70.0 * rnd()) as usize, 1 + (50.0 * rnd()) as usize);
                // Patches inside, across the edges (the last row and column included) and around
                // the image.
                let (fw, fh) = (iw as f64, ih as f64);
                let m = rotated(
                    6.3 * rnd(),
                    0.05 + 1.2 * rnd(),
                    w,
                    h,
                    fw * (1.6 * rnd() - 0.3),
                    fh * (1.6 * rnd() - 0.3),
                );
                let map = ClampedMap::new(&m, iw, ih).unwrap();
                let (mut base, mut avx2) = (vec![0u8; w * h], vec![1u8; w * h]);
                map.sample_body(img.data(), iw, ih, w, &mut base);
                #[allow(unsafe_code)]
                // SAFETY: the CPU has AVX2 and FMA (checked above).
                unsafe {
                    map.sample_avx2(img.data(), iw, ih, w, &mut avx2)
                };
                assert_eq!(base, avx2, "case {case}: {m:?} {w}x{h}");
                let mut gathered = vec![2u8; w * h];
                #[allow(unsafe_code)]
                // SAFETY: as above.
                unsafe {
                    map.sample_gather_avx2(img.data(), iw, ih, w, &mut gathered)
                };
                assert_eq!(base, gathered, "gathers, case {case}: {m:?} {w}x{h}");
                if crate::nn::conv::Products::Avx512.supported() {
                    let mut wide = vec![3u8; w * h];
                    #[allow(unsafe_code)]
                    // SAFETY: the CPU has AVX-512F (checked just above), AVX2 and FMA.
                    unsafe {
                        map.sample_gather_avx512(img.data(), iw, ih, w, &mut wide)
                    };
                    assert_eq!(base, wide, "16-lane gathers, case {case}: {m:?} {w}x{h}");
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

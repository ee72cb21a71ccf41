//! NEON forms of the Lucas–Kanade window kernels ([`super::Windows::gradients`] and
//! [`super::Windows::mismatch`]): a lane group of sixteen cells in four registers, the portable
//! path's operations in its order — multiplies and adds kept apart, never fused — so the same
//! bits. NEON is baseline on aarch64: no run-time check (the callers' `unsafe` blocks rest on
//! that).

use super::{LANES, window_inside};
use crate::image::GrayImage;
use std::arch::aarch64::{
    float32x4_t, uint32x4_t, vabsq_f32, vadd_f32, vaddq_f32, vandq_u32, vcltq_u32, vcvtq_f32_u32,
    vdupq_n_f32, vdupq_n_u32, vextq_f32, vget_high_f32, vget_high_u16, vget_low_f32, vget_low_u8,
    vget_low_u16, vld1q_f32, vld1q_u8, vld1q_u32, vmovl_high_u8, vmovl_u8, vmovl_u16, vmulq_f32,
    vpadds_f32, vreinterpretq_f32_u32, vreinterpretq_u32_f32, vst1q_f32, vsubq_f32,
};

/// Sixteen cells: lanes 0–3, 4–7, 8–11, 12–15.
type Row = [float32x4_t; 4];

/// Sixteen bytes from `bytes[..16]` as f32.
#[target_feature(enable = "neon")]
#[inline]
fn widen(bytes: &[u8]) -> Row {
    let bytes: &[u8; 16] = bytes[..16].try_into().expect("sixteen bytes");
    // SAFETY: `bytes` is sixteen readable bytes, the width of the load.
    #[allow(unsafe_code)]
    let v = unsafe { vld1q_u8(bytes.as_ptr()) };
    let (lo, hi) = (vmovl_u8(vget_low_u8(v)), vmovl_high_u8(v));
    [
        vcvtq_f32_u32(vmovl_u16(vget_low_u16(lo))),
        vcvtq_f32_u32(vmovl_u16(vget_high_u16(lo))),
        vcvtq_f32_u32(vmovl_u16(vget_low_u16(hi))),
        vcvtq_f32_u32(vmovl_u16(vget_high_u16(hi))),
    ]
}

/// Four f32 from `s[at..]`.
#[target_feature(enable = "neon")]
#[inline]
fn load4(s: &[f32], at: usize) -> float32x4_t {
    let lanes: &[f32; 4] = s[at..at + 4].try_into().expect("lanes");
    // SAFETY: `lanes` is four readable f32, the width of the load.
    #[allow(unsafe_code)]
    unsafe {
        vld1q_f32(lanes.as_ptr())
    }
}

/// Four f32 into `s[at..]`.
#[target_feature(enable = "neon")]
#[inline]
fn store4(s: &mut [f32], at: usize, v: float32x4_t) {
    let lanes: &mut [f32; 4] = (&mut s[at..at + 4]).try_into().expect("lanes");
    // SAFETY: `lanes` is four writable f32, the width of the store.
    #[allow(unsafe_code)]
    unsafe {
        vst1q_f32(lanes.as_mut_ptr(), v)
    }
}

/// Masks of the first `count` of sixteen lanes (all bits set there, zero in the others).
#[target_feature(enable = "neon")]
#[inline]
fn first_lanes(count: usize) -> [uint32x4_t; 4] {
    const INDEX: [u32; 16] = [0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15];
    let count = vdupq_n_u32(count.min(LANES) as u32);
    std::array::from_fn(|h| {
        let index: &[u32; 4] = INDEX[4 * h..4 * h + 4].try_into().expect("lanes");
        // SAFETY: `index` is four readable u32, the width of the load.
        #[allow(unsafe_code)]
        let index = unsafe { vld1q_u32(index.as_ptr()) };
        vcltq_u32(index, count)
    })
}

#[target_feature(enable = "neon")]
#[inline]
fn and(v: float32x4_t, mask: uint32x4_t) -> float32x4_t {
    vreinterpretq_f32_u32(vandq_u32(vreinterpretq_u32_f32(v), mask))
}

/// `a + t·(b − a)` on four lanes ([`super::lerp`]).
#[target_feature(enable = "neon")]
#[inline]
fn lerp(a: float32x4_t, b: float32x4_t, t: float32x4_t) -> float32x4_t {
    vaddq_f32(a, vmulq_f32(t, vsubq_f32(b, a)))
}

/// Image row `bytes[..17]` interpolated along x at fraction `fx`: sixteen cells.
#[target_feature(enable = "neon")]
#[inline]
fn along_x(bytes: &[u8], fx: float32x4_t) -> Row {
    let (a, b) = (widen(bytes), widen(&bytes[1..]));
    std::array::from_fn(|h| lerp(a[h], b[h], fx))
}

/// [`super::reduce`] of the accumulators of even and odd rows: lane k + lane k + 8, then + 4,
/// + 2, + 1.
#[target_feature(enable = "neon")]
#[inline]
fn reduce(even: [float32x4_t; 4], odd: [float32x4_t; 4]) -> f32 {
    let t: [float32x4_t; 4] = std::array::from_fn(|h| vaddq_f32(even[h], odd[h]));
    let t8 = [vaddq_f32(t[0], t[2]), vaddq_f32(t[1], t[3])];
    let t4 = vaddq_f32(t8[0], t8[1]);
    vpadds_f32(vadd_f32(vget_low_f32(t4), vget_high_f32(t4)))
}

/// The row's cells moved down by `S` lanes (lane k holds cell k + S), zero past the row.
#[target_feature(enable = "neon")]
#[inline]
fn next<const S: i32>(v: Row) -> Row {
    let zero = vdupq_n_f32(0.0);
    [
        vextq_f32::<S>(v[0], v[1]),
        vextq_f32::<S>(v[1], v[2]),
        vextq_f32::<S>(v[2], v[3]),
        vextq_f32::<S>(v[3], zero),
    ]
}

/// The NEON form of the x86 `bordered_gradients_*` kernels: the previous image's bordered window
/// sampled and its patch, gradients and gradient-matrix sums taken in one pass, each bordered row
/// in four registers and its cells one and two to the right by lane shifts. For windows whose
/// bordered rows fit a lane group (`n + 2 ≤ 16`) and whose rows of seventeen image bytes lie inside
/// the image; `None` otherwise (the portable path serves them).
#[target_feature(enable = "neon")]
pub(super) fn bordered_gradients(
    img: &GrayImage,
    x: f32,
    y: f32,
    n: usize,
    st: usize,
    [patch, gx, gy]: [&mut [f32]; 3],
) -> Option<[f32; 3]> {
    let size = n + 2;
    if size > LANES {
        return None;
    }
    let ([ix, iy], [fx, fy]) = window_inside(img, x, y, LANES, size)?;
    assert!(st.is_multiple_of(LANES) && [&*patch, &*gx, &*gy].iter().all(|b| b.len() >= n * st));
    let (w, d) = (img.width(), img.data());
    let (vfx, vfy, half) = (vdupq_n_f32(fx), vdupq_n_f32(fy), vdupq_n_f32(0.5));
    let inside = first_lanes(n);
    let along_x = |r: usize| along_x(&d[(iy + r) * w + ix..][..LANES + 1], vfx);
    let bordered = |r: usize, top: Row| -> (Row, Row) {
        let bottom = along_x(r + 1);
        (
            std::array::from_fn(|h| lerp(top[h], bottom[h], vfy)),
            bottom,
        )
    };
    let mut row = |r: usize, [up, mid, down]: [Row; 3], acc: [[float32x4_t; 3]; 4]| {
        let (centre, right, up1, down1) = (
            next::<1>(mid),
            next::<2>(mid),
            next::<1>(up),
            next::<1>(down),
        );
        std::array::from_fn(|h| {
            let x = and(vmulq_f32(half, vsubq_f32(right[h], mid[h])), inside[h]);
            let y = and(vmulq_f32(half, vsubq_f32(down1[h], up1[h])), inside[h]);
            let k = r * st + 4 * h;
            store4(patch, k, and(centre[h], inside[h]));
            store4(gx, k, x);
            store4(gy, k, y);
            [
                vaddq_f32(acc[h][0], vmulq_f32(x, x)),
                vaddq_f32(acc[h][1], vmulq_f32(x, y)),
                vaddq_f32(acc[h][2], vmulq_f32(y, y)),
            ]
        })
    };
    let zero = [[vdupq_n_f32(0.0); 3]; 4];
    let (even, odd) = walk_bordered_rows!(n, along_x, bordered, row, zero);
    Some(std::array::from_fn(|i| {
        reduce(even.map(|a| a[i]), odd.map(|a| a[i]))
    }))
}

/// The NEON form of the x86 `mismatch_*` kernels: the next image's window against the patch,
/// each image row interpolated along x once and used by the two window rows it lies between, the
/// sums taken in the same pass. For windows whose rows of `st + 1` image bytes lie inside the
/// image; `None` otherwise.
#[target_feature(enable = "neon")]
pub(super) fn mismatch(
    img: &GrayImage,
    x: f32,
    y: f32,
    n: usize,
    st: usize,
    [patch, gx, gy]: [&[f32]; 3],
) -> Option<[f32; 3]> {
    let ([ix, iy], [fx, fy]) = window_inside(img, x, y, st, n)?;
    assert!(st.is_multiple_of(LANES) && [patch, gx, gy].iter().all(|b| b.len() >= n * st));
    let (w, d) = (img.width(), img.data());
    let (vfx, vfy) = (vdupq_n_f32(fx), vdupq_n_f32(fy));
    let zero = [[vdupq_n_f32(0.0); 3]; 4];
    let (mut even, mut odd) = (zero, zero);
    for c in (0..st).step_by(LANES) {
        let inside = first_lanes(n.saturating_sub(c));
        // Image row `r`, cells c..c + 16 along x, zero past the window (as the portable path's
        // `moving`).
        let along_x = |r: usize| -> Row {
            let v = along_x(&d[(iy + r) * w + ix + c..][..LANES + 1], vfx);
            std::array::from_fn(|h| and(v[h], inside[h]))
        };
        // Window row `r` from image rows `top` and r + 1 into `acc`; returns row r + 1.
        let row = |r: usize, top: Row, acc: &mut [[float32x4_t; 3]; 4]| -> Row {
            let bottom = along_x(r + 1);
            for h in 0..4 {
                let moving = lerp(top[h], bottom[h], vfy);
                let k = r * st + c + 4 * h;
                let diff = vsubq_f32(load4(patch, k), moving);
                acc[h][0] = vaddq_f32(acc[h][0], vmulq_f32(diff, load4(gx, k)));
                acc[h][1] = vaddq_f32(acc[h][1], vmulq_f32(diff, load4(gy, k)));
                acc[h][2] = vaddq_f32(acc[h][2], vabsq_f32(diff));
            }
            bottom
        };
        let mut top = along_x(0);
        let mut r = 0;
        while r + 1 < n {
            top = row(r, top, &mut even);
            top = row(r + 1, top, &mut odd);
            r += 2;
        }
        if r < n {
            row(r, top, &mut even);
        }
    }
    Some(std::array::from_fn(|i| {
        reduce(even.map(|a| a[i]), odd.map(|a| a[i]))
    }))
}

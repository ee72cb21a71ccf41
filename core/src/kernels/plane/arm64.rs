//! NEON form of the plane transposition: 16×16 tiles in sixteen registers, four rounds of `trn`.

use super::Orientation;
use std::arch::aarch64::{
    uint8x16_t, vld1q_u8, vreinterpretq_u8_u16, vreinterpretq_u8_u32, vreinterpretq_u8_u64,
    vreinterpretq_u16_u8, vreinterpretq_u32_u8, vreinterpretq_u64_u8, vst1q_u8, vtrn1q_u8,
    vtrn1q_u16, vtrn1q_u32, vtrn1q_u64, vtrn2q_u8, vtrn2q_u16, vtrn2q_u32, vtrn2q_u64,
};

/// Transposes the whole 16×16 tiles of the plane into `dst` (see [`super::upright`]); returns the
/// source columns and rows they covered.
#[target_feature(enable = "neon")]
pub(super) fn transpose_tiles(
    src: &[u8],
    stride: usize,
    w: usize,
    h: usize,
    o: Orientation,
    dst: &mut [u8],
) -> (usize, usize) {
    let (tw, th) = (w / 16 * 16, h / 16 * 16);
    for y0 in (0..th).step_by(16) {
        let ox = o.tile_column(y0, 16, h);
        for x0 in (0..tw).step_by(16) {
            let rows: [uint8x16_t; 16] = std::array::from_fn(|r| {
                let row = &src[o.tile_row(y0, r, 16) * stride + x0..][..16];
                #[allow(unsafe_code)]
                // SAFETY: `row` holds the sixteen bytes loaded.
                unsafe {
                    vld1q_u8(row.as_ptr())
                }
            });
            for (c, col) in transpose16(rows).into_iter().enumerate() {
                let (_, oy) = o.upright(x0 + c, y0, w, h);
                let out = &mut dst[oy * h + ox..][..16];
                #[allow(unsafe_code)]
                // SAFETY: `out` holds the sixteen bytes stored.
                unsafe {
                    vst1q_u8(out.as_mut_ptr(), col)
                };
            }
        }
    }
    (tw, th)
}

/// Sixteen rows of sixteen bytes turned into sixteen columns: `trn` of neighbouring rows' bytes,
/// then of pairs of rows' 16-bit lanes, of quads' 32-bit lanes and of halves' 64-bit lanes.
#[target_feature(enable = "neon")]
#[inline]
fn transpose16(r: [uint8x16_t; 16]) -> [uint8x16_t; 16] {
    let mut a = r;
    for i in (0..16).step_by(2) {
        (a[i], a[i + 1]) = (vtrn1q_u8(r[i], r[i + 1]), vtrn2q_u8(r[i], r[i + 1]));
    }
    let b16 = a.map(|v| vreinterpretq_u16_u8(v));
    let mut b = a;
    for j in (0..16).step_by(4) {
        for m in j..j + 2 {
            b[m] = vreinterpretq_u8_u16(vtrn1q_u16(b16[m], b16[m + 2]));
            b[m + 2] = vreinterpretq_u8_u16(vtrn2q_u16(b16[m], b16[m + 2]));
        }
    }
    let c32 = b.map(|v| vreinterpretq_u32_u8(v));
    let mut c = b;
    for k in (0..16).step_by(8) {
        for m in k..k + 4 {
            c[m] = vreinterpretq_u8_u32(vtrn1q_u32(c32[m], c32[m + 4]));
            c[m + 4] = vreinterpretq_u8_u32(vtrn2q_u32(c32[m], c32[m + 4]));
        }
    }
    let d64 = c.map(|v| vreinterpretq_u64_u8(v));
    let mut d = c;
    for m in 0..8 {
        d[m] = vreinterpretq_u8_u64(vtrn1q_u64(d64[m], d64[m + 8]));
        d[m + 8] = vreinterpretq_u8_u64(vtrn2q_u64(d64[m], d64[m + 8]));
    }
    d
}

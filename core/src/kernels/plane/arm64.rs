//! NEON form of the plane transposition's 16×16 tile: four rounds of `trn`.

use std::arch::aarch64::{
    vld1q_u8, vreinterpretq_u8_u16, vreinterpretq_u8_u32, vreinterpretq_u8_u64,
    vreinterpretq_u16_u8, vreinterpretq_u32_u8, vreinterpretq_u64_u8, vst1q_u8, vtrn1q_u8,
    vtrn1q_u16, vtrn1q_u32, vtrn1q_u64, vtrn2q_u8, vtrn2q_u16, vtrn2q_u32, vtrn2q_u64,
};

/// Sixteen rows of sixteen bytes turned into sixteen columns in registers: `trn` of neighbouring
/// rows' bytes, then of pairs of rows' 16-bit lanes, of quads' 32-bit lanes and of halves' 64-bit
/// lanes.
#[target_feature(enable = "neon")]
pub(super) fn transpose16(rows: [&[u8; 16]; 16]) -> [[u8; 16]; 16] {
    #[allow(unsafe_code)]
    // SAFETY: each row holds the sixteen bytes loaded.
    let r = rows.map(|row| unsafe { vld1q_u8(row.as_ptr()) });
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
    let mut cols = [[0u8; 16]; 16];
    for m in 0..8 {
        let (lo, hi) = (
            vtrn1q_u64(d64[m], d64[m + 8]),
            vtrn2q_u64(d64[m], d64[m + 8]),
        );
        #[allow(unsafe_code)]
        // SAFETY: each column array holds the sixteen bytes stored.
        unsafe {
            vst1q_u8(cols[m].as_mut_ptr(), vreinterpretq_u8_u64(lo));
            vst1q_u8(cols[m + 8].as_mut_ptr(), vreinterpretq_u8_u64(hi));
        }
    }
    cols
}

//! SSE2 form of the plane transposition (SSE2 is baseline on x86-64: no run-time check): 16×16
//! tiles in sixteen registers, four rounds of byte `unpack` pairing row i with row i + 8.

use super::Orientation;
use std::arch::x86_64::{
    __m128i, _mm_loadu_si128, _mm_storeu_si128, _mm_unpackhi_epi8, _mm_unpacklo_epi8,
};

/// Transposes the whole 16×16 tiles of the plane into `dst` (see [`super::upright`]); returns the
/// source columns and rows they covered.
#[target_feature(enable = "sse2")]
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
            let mut rows: [__m128i; 16] = std::array::from_fn(|r| {
                let row = &src[o.tile_row(y0, r, 16) * stride + x0..][..16];
                #[allow(unsafe_code)]
                // SAFETY: `row` holds the sixteen bytes loaded (unaligned loads are allowed).
                unsafe {
                    _mm_loadu_si128(row.as_ptr().cast())
                }
            });
            // Each round interleaves row i with row i + 8; four rounds transpose 16×16 bytes.
            for _ in 0..4 {
                let r = rows;
                for i in 0..8 {
                    rows[2 * i] = _mm_unpacklo_epi8(r[i], r[i + 8]);
                    rows[2 * i + 1] = _mm_unpackhi_epi8(r[i], r[i + 8]);
                }
            }
            for (c, col) in rows.into_iter().enumerate() {
                let (_, oy) = o.upright(x0 + c, y0, w, h);
                let out = &mut dst[oy * h + ox..][..16];
                #[allow(unsafe_code)]
                // SAFETY: `out` holds the sixteen bytes stored (unaligned stores are allowed).
                unsafe {
                    _mm_storeu_si128(out.as_mut_ptr().cast(), col)
                };
            }
        }
    }
    (tw, th)
}

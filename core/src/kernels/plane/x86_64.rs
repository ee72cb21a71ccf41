//! SSE2 form of the plane transposition's 16×16 tile (SSE2 is baseline on x86-64: no run-time
//! check): four rounds of byte `unpack` pairing row i with row i + 8.

use std::arch::x86_64::{_mm_loadu_si128, _mm_storeu_si128, _mm_unpackhi_epi8, _mm_unpacklo_epi8};

/// Sixteen rows of sixteen bytes turned into sixteen columns in registers.
#[target_feature(enable = "sse2")]
pub(super) fn transpose16(rows: [&[u8; 16]; 16]) -> [[u8; 16]; 16] {
    #[allow(unsafe_code)]
    // SAFETY: each row holds the sixteen bytes loaded (unaligned loads are allowed).
    let mut v = rows.map(|row| unsafe { _mm_loadu_si128(row.as_ptr().cast()) });
    // Each round interleaves row i with row i + 8; four rounds transpose 16×16 bytes.
    for _ in 0..4 {
        let r = v;
        for i in 0..8 {
            v[2 * i] = _mm_unpacklo_epi8(r[i], r[i + 8]);
            v[2 * i + 1] = _mm_unpackhi_epi8(r[i], r[i + 8]);
        }
    }
    let mut cols = [[0u8; 16]; 16];
    for (col, x) in cols.iter_mut().zip(v) {
        #[allow(unsafe_code)]
        // SAFETY: each column array holds the sixteen bytes stored (unaligned stores are allowed).
        unsafe {
            _mm_storeu_si128(col.as_mut_ptr().cast(), x)
        };
    }
    cols
}

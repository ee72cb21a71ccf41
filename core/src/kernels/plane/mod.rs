//! An 8-bit plane made upright: the camera's Y plane (NV21, NV12, I420, or a `Gray8` frame) copied
//! into the upright luma image with the frame's rotation and mirroring.
//!
//! A quarter turn is a transposition: each upright row is a source column. The forms transpose
//! square tiles in registers — the portable one 8×8 tiles as eight `u64` words (three rounds of
//! masked shifts), NEON and SSE2 16×16 tiles in sixteen 128-bit registers (four rounds of
//! `trn` / `unpack`) — so every load reads a run of a source row and every store writes a run of
//! an upright row. Reversed upright columns come from loading the tile's rows bottom-up, so no form
//! reverses bytes. What the tiles leave at the right and bottom edges is copied pixel by pixel.
//! Half and no turns copy rows, forwards or backwards, which the compiler vectorises on every
//! target. Every form writes the same bytes (a copy): the tests compare each with the per-pixel
//! definition.

#[cfg(target_arch = "aarch64")]
mod arm64;
#[cfg(target_arch = "x86_64")]
mod x86_64;

use crate::camera::Rotation;

/// Where a source pixel lands in the upright image.
///
/// Without `transpose` (0° and 180°) source x runs along upright columns; with it (90° and 270°)
/// source y does, and source x along upright rows. `flip_x` then runs upright columns backwards,
/// `flip_y` upright rows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Orientation {
    transpose: bool,
    flip_x: bool,
    flip_y: bool,
}

impl Orientation {
    /// The orientation of a frame turned `rotation` clockwise, then mirrored left–right when
    /// `mirrored`.
    pub(crate) fn new(rotation: Rotation, mirrored: bool) -> Self {
        let (transpose, flip_x, flip_y) = match rotation {
            // (x, y) → (x, y)
            Rotation::R0 => (false, false, false),
            // (x, y) → (h - 1 - y, x)
            Rotation::R90 => (true, true, false),
            // (x, y) → (w - 1 - x, h - 1 - y)
            Rotation::R180 => (false, true, true),
            // (x, y) → (y, w - 1 - x)
            Rotation::R270 => (true, false, true),
        };
        Self {
            transpose,
            flip_x: flip_x != mirrored,
            flip_y,
        }
    }

    /// Whether upright rows are source columns (90° and 270°).
    pub(crate) fn transposes(self) -> bool {
        self.transpose
    }

    /// Whether upright columns run backwards against the source axis they come from.
    pub(crate) fn flips_x(self) -> bool {
        self.flip_x
    }

    /// The upright row that source row `y` (of `h`) becomes, for orientations that do not
    /// transpose.
    pub(crate) fn upright_row(self, y: usize, h: usize) -> usize {
        if self.flip_y { h - 1 - y } else { y }
    }

    /// The upright (column, row) of source pixel (x, y) of a w×h plane.
    #[inline]
    pub(crate) fn upright(self, x: usize, y: usize, w: usize, h: usize) -> (usize, usize) {
        let (along, across, n_along, n_across) = if self.transpose {
            (y, x, h, w)
        } else {
            (x, y, w, h)
        };
        (
            if self.flip_x {
                n_along - 1 - along
            } else {
                along
            },
            if self.flip_y {
                n_across - 1 - across
            } else {
                across
            },
        )
    }

    /// The source row a tile of `n` rows starting at `y0` loads as its `r`-th: bottom-up where
    /// upright columns run backwards, so that each tile column comes out in upright order.
    #[inline]
    fn tile_row(self, y0: usize, r: usize, n: usize) -> usize {
        if self.flip_x { y0 + n - 1 - r } else { y0 + r }
    }

    /// The upright column where a transposed tile of `n` source rows from `y0` starts (of `h`).
    #[inline]
    fn tile_column(self, y0: usize, n: usize, h: usize) -> usize {
        if self.flip_x { h - n - y0 } else { y0 }
    }
}

/// Writes the upright image of the `w`×`h` plane `src` (rows `stride` bytes apart; the last may
/// end at the width) into `dst`, packed (its width `h` when `o` transposes, else `w`).
///
/// # Panics
/// Where `src` or `dst` is shorter than the sizes say (callers validate frames first).
pub(crate) fn upright(
    src: &[u8],
    stride: usize,
    w: usize,
    h: usize,
    o: Orientation,
    dst: &mut [u8],
) {
    assert!(src.len() >= stride * (h - 1) + w && dst.len() >= w * h);
    if !o.transpose {
        for y in 0..h {
            let row = &src[y * stride..y * stride + w];
            let out = &mut dst[o.upright_row(y, h) * w..][..w];
            if o.flip_x {
                for (d, s) in out.iter_mut().zip(row.iter().rev()) {
                    *d = *s;
                }
            } else {
                out.copy_from_slice(row);
            }
        }
        return;
    }
    #[cfg(target_arch = "aarch64")]
    if crate::kernels::cpu::neon() {
        return transpose16_with(src, stride, w, h, o, dst, |rows| {
            #[allow(unsafe_code)]
            // SAFETY: NEON is part of every aarch64 target's baseline.
            unsafe {
                arm64::transpose16(rows)
            }
        });
    }
    #[cfg(target_arch = "x86_64")]
    if crate::kernels::kernel_path() == crate::kernels::KernelPath::Native {
        return transpose16_with(src, stride, w, h, o, dst, |rows| {
            #[allow(unsafe_code)]
            // SAFETY: SSE2 is part of the x86-64 baseline.
            unsafe {
                x86_64::transpose16(rows)
            }
        });
    }
    transpose_with(
        w,
        h,
        o,
        dst,
        |x0, y| u64::from_le_bytes(src[y * stride + x0..][..8].try_into().expect("8 bytes")),
        |x, y| src[y * stride + x],
    );
}

/// The portable transposition of any source of 8-bit values, for orientations that transpose:
/// `load8(x0, y)` gives source pixels x0..x0 + 8 of row y as a little-endian word, `pixel(x, y)`
/// one pixel (for the edges the 8×8 tiles leave).
pub(crate) fn transpose_with(
    w: usize,
    h: usize,
    o: Orientation,
    dst: &mut [u8],
    load8: impl Fn(usize, usize) -> u64,
    pixel: impl Fn(usize, usize) -> u8,
) {
    debug_assert!(o.transpose);
    let (tw, th) = (w / 8 * 8, h / 8 * 8);
    for y0 in (0..th).step_by(8) {
        let ox = o.tile_column(y0, 8, h);
        for x0 in (0..tw).step_by(8) {
            let cols = transpose8(std::array::from_fn(|r| load8(x0, o.tile_row(y0, r, 8))));
            for (c, col) in cols.into_iter().enumerate() {
                let (_, oy) = o.upright(x0 + c, y0, w, h);
                dst[oy * h + ox..][..8].copy_from_slice(&col.to_le_bytes());
            }
        }
    }
    transposed_edges(w, h, tw, th, o, dst, pixel);
}

/// The tile walk of the 16×16 forms: each whole tile's rows (bottom-up where upright columns run
/// backwards) go to `transpose16`, which gives the tile's columns; each column is stored as a run
/// of its upright row. The edges the tiles leave are copied pixel by pixel.
#[cfg(any(target_arch = "aarch64", target_arch = "x86_64"))]
#[inline]
fn transpose16_with(
    src: &[u8],
    stride: usize,
    w: usize,
    h: usize,
    o: Orientation,
    dst: &mut [u8],
    transpose16: impl Fn([&[u8; 16]; 16]) -> [[u8; 16]; 16],
) {
    let (tw, th) = (w / 16 * 16, h / 16 * 16);
    for y0 in (0..th).step_by(16) {
        let ox = o.tile_column(y0, 16, h);
        for x0 in (0..tw).step_by(16) {
            let rows = std::array::from_fn(|r| {
                src[o.tile_row(y0, r, 16) * stride + x0..][..16]
                    .try_into()
                    .expect("16 bytes")
            });
            for (c, col) in transpose16(rows).iter().enumerate() {
                let (_, oy) = o.upright(x0 + c, y0, w, h);
                dst[oy * h + ox..][..16].copy_from_slice(col);
            }
        }
    }
    transposed_edges(w, h, tw, th, o, dst, |x, y| src[y * stride + x]);
}

/// An 8×8 block of bytes, row `r` in word `r` (byte `c` of it column `c`, little-endian), turned
/// so that word `c` holds column `c`: the 4×4 corner blocks swap, then the 2×2 blocks inside
/// them, then single bytes.
#[inline]
fn transpose8(mut a: [u64; 8]) -> [u64; 8] {
    for (k, shift, mask) in [
        (4, 32, 0x0000_0000_FFFF_FFFF_u64),
        (2, 16, 0x0000_FFFF_0000_FFFF),
        (1, 8, 0x00FF_00FF_00FF_00FF),
    ] {
        for r in (0..8).filter(|r| r & k == 0) {
            let (lo, hi) = (a[r], a[r + k]);
            a[r] = (lo & mask) | ((hi << shift) & !mask);
            a[r + k] = ((lo >> shift) & mask) | (hi & !mask);
        }
    }
    a
}

/// Copies, pixel by pixel, what tiles covering source columns `..tw` and rows `..th` left of a
/// transposition: the columns from `tw` on (every row), then the rows from `th` on.
fn transposed_edges(
    w: usize,
    h: usize,
    tw: usize,
    th: usize,
    o: Orientation,
    dst: &mut [u8],
    pixel: impl Fn(usize, usize) -> u8,
) {
    let mut put = |x: usize, y: usize| {
        let (ox, oy) = o.upright(x, y, w, h);
        dst[oy * h + ox] = pixel(x, y);
    };
    for y in 0..h {
        for x in tw..w {
            put(x, y);
        }
    }
    for y in th..h {
        for x in 0..tw {
            put(x, y);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The definition: every pixel where [`Orientation::upright`] puts it, checked against the
    /// rotation formulas of `image::frame`'s docs.
    fn reference(src: &[u8], stride: usize, w: usize, h: usize, o: Orientation) -> Vec<u8> {
        let ow = if o.transpose { h } else { w };
        let mut out = vec![0; w * h];
        for y in 0..h {
            for x in 0..w {
                let (ox, oy) = o.upright(x, y, w, h);
                out[oy * ow + ox] = src[y * stride + x];
            }
        }
        out
    }

    fn all_orientations() -> impl Iterator<Item = (Rotation, bool)> {
        [Rotation::R0, Rotation::R90, Rotation::R180, Rotation::R270]
            .into_iter()
            .flat_map(|r| [(r, false), (r, true)])
    }

    #[test]
    fn orientations_follow_the_rotation_formulas() {
        let (w, h) = (5, 3);
        for (rot, mirrored) in all_orientations() {
            let o = Orientation::new(rot, mirrored);
            let ow = if o.transpose { h } else { w };
            for (x, y) in [(0, 0), (4, 0), (1, 2), (3, 1)] {
                let (mut ox, oy) = match rot {
                    Rotation::R0 => (x, y),
                    Rotation::R90 => (h - 1 - y, x),
                    Rotation::R180 => (w - 1 - x, h - 1 - y),
                    Rotation::R270 => (y, w - 1 - x),
                };
                if mirrored {
                    ox = ow - 1 - ox;
                }
                assert_eq!(o.upright(x, y, w, h), (ox, oy), "{rot:?} {mirrored}");
            }
        }
    }

    #[test]
    fn the_word_transposition_turns_rows_into_columns() {
        let rows: [u64; 8] =
            std::array::from_fn(|r| u64::from_le_bytes(std::array::from_fn(|c| (r * 8 + c) as u8)));
        let cols = transpose8(rows);
        for (c, col) in cols.iter().enumerate() {
            for (r, b) in col.to_le_bytes().iter().enumerate() {
                assert_eq!(*b as usize, r * 8 + c);
            }
        }
    }

    /// Every form this CPU runs, at sizes with and without whole tiles of 8 and 16, padded
    /// strides and a last row that ends at the width.
    #[test]
    fn every_orientation_gives_the_definitions_bytes() {
        for (w, h) in [
            (1, 1),
            (7, 3),
            (8, 8),
            (16, 16),
            (17, 33),
            (40, 24),
            (64, 48),
            (61, 45),
        ] {
            let stride = w + 3;
            let src: Vec<u8> = (0..stride * (h - 1) + w)
                .map(|i| (i * 131 % 251) as u8)
                .collect();
            for (rot, mirrored) in all_orientations() {
                let o = Orientation::new(rot, mirrored);
                let want = reference(&src, stride, w, h, o);
                let mut got = vec![0xEE; w * h];
                upright(&src, stride, w, h, o, &mut got);
                assert_eq!(got, want, "{w}x{h} {rot:?} mirrored {mirrored}");
                if o.transpose {
                    let mut portable = vec![0xEE; w * h];
                    transpose_with(
                        w,
                        h,
                        o,
                        &mut portable,
                        |x0, y| u64::from_le_bytes(src[y * stride + x0..][..8].try_into().unwrap()),
                        |x, y| src[y * stride + x],
                    );
                    assert_eq!(portable, want, "portable {w}x{h} {rot:?} {mirrored}");
                }
            }
        }
    }
}

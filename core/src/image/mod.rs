//! Images inside the core: the upright 8-bit luma image every stage works on, and the conversions
//! that produce it from camera frames.
//!
//! Pixel convention: see [`crate::camera`] — pixel (i, j) covers [i, i+1)×[j, j+1), its centre is
//! (i + 0.5, j + 0.5).

pub mod frame;

pub use frame::{Frame, FrameDesc, PixelFormat};

/// The luma of `models/M3_IO.md` that the models were trained with: `round(0.299 R + 0.587 G +
/// 0.114 B)` in f32. Image files take this exact form (the CLI, the tests); the camera path of
/// [`Frame`] uses a fixed-point form within ±1 of it, for speed.
#[inline]
pub fn contract_luma(r: u8, g: u8, b: u8) -> u8 {
    let v = 0.299 * f32::from(r) + 0.587 * f32::from(g) + 0.114 * f32::from(b);
    // `round` for v ≥ 0 on every one of the 2^24 inputs (unit test), without its libm call (x86-64's
    // baseline has no rounding instruction): that call and its loop were a large share of
    // `monotrack landmarks`' profile before. The saturating cast truncates, i.e. floors.
    (v + 0.5) as u8
}

/// [`contract_luma`] of every pixel of a packed RGB buffer into `out` (as many pixels as both
/// hold).
pub fn rgb_to_contract_luma(rgb: &[u8], out: &mut [u8]) {
    for (o, p) in out.iter_mut().zip(rgb.chunks_exact(3)) {
        *o = contract_luma(p[0], p[1], p[2]);
    }
}

/// An owned, tightly packed (stride = width) 8-bit grayscale image. Buffers are reused across
/// frames: [`GrayImage::resize`] only reallocates when the image grows beyond its capacity.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct GrayImage {
    width: usize,
    height: usize,
    data: Vec<u8>,
}

impl GrayImage {
    /// A black image.
    pub fn new(width: usize, height: usize) -> Self {
        Self {
            width,
            height,
            data: vec![0; width * height],
        }
    }

    /// Wraps packed row-major bytes; `None` when `data.len() != width * height`.
    pub fn from_vec(width: usize, height: usize, data: Vec<u8>) -> Option<Self> {
        // Checked: a caller's sizes can overflow a 32-bit usize.
        (width.checked_mul(height) == Some(data.len())).then_some(Self {
            width,
            height,
            data,
        })
    }

    /// Changes the size, keeping the allocation when it is large enough; contents are unspecified.
    pub fn resize(&mut self, width: usize, height: usize) {
        self.width = width;
        self.height = height;
        self.data.resize(width * height, 0);
    }

    /// Width in pixels.
    #[inline]
    pub fn width(&self) -> usize {
        self.width
    }

    /// Height in pixels.
    #[inline]
    pub fn height(&self) -> usize {
        self.height
    }

    /// Row-major pixels.
    #[inline]
    pub fn data(&self) -> &[u8] {
        &self.data
    }

    /// Row-major pixels, mutable.
    #[inline]
    pub fn data_mut(&mut self) -> &mut [u8] {
        &mut self.data
    }

    /// One row.
    #[inline]
    pub fn row(&self, y: usize) -> &[u8] {
        &self.data[y * self.width..(y + 1) * self.width]
    }

    /// Pixel value; panics out of bounds (callers index inside the image).
    #[inline]
    pub fn get(&self, x: usize, y: usize) -> u8 {
        self.data[y * self.width + x]
    }
}

/// An axis-aligned box in image pixels: top-left corner (x, y), width and height (CONTRACT's
/// `[x, y, w, h]`). Face boxes from the detector, the tracker and callers all use it; M3 turns any box
/// into the square of side `max(w, h)` around its centre (`models/M3_IO.md`).
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct Rect {
    /// Left edge, pixels.
    pub x: f32,
    /// Top edge, pixels.
    pub y: f32,
    /// Width, pixels.
    pub w: f32,
    /// Height, pixels.
    pub h: f32,
}

impl Rect {
    /// A box from its corner and size.
    pub const fn new(x: f32, y: f32, w: f32, h: f32) -> Self {
        Self { x, y, w, h }
    }

    /// The tight axis-aligned box of `points` (negative size for none).
    pub fn bounding(points: &[[f32; 2]]) -> Self {
        let (mut x0, mut y0, mut x1, mut y1) = (f32::MAX, f32::MAX, f32::MIN, f32::MIN);
        for p in points {
            x0 = x0.min(p[0]);
            y0 = y0.min(p[1]);
            x1 = x1.max(p[0]);
            y1 = y1.max(p[1]);
        }
        Self::new(x0, y0, x1 - x0, y1 - y0)
    }

    /// Centre point.
    pub fn center(&self) -> [f32; 2] {
        [self.x + 0.5 * self.w, self.y + 0.5 * self.h]
    }

    /// Area (0 for degenerate boxes).
    pub fn area(&self) -> f32 {
        self.w.max(0.0) * self.h.max(0.0)
    }

    /// Intersection over union with another box (0 when either is empty).
    pub fn iou(&self, other: &Rect) -> f32 {
        let x0 = self.x.max(other.x);
        let y0 = self.y.max(other.y);
        let x1 = (self.x + self.w).min(other.x + other.w);
        let y1 = (self.y + self.h).min(other.y + other.h);
        let inter = (x1 - x0).max(0.0) * (y1 - y0).max(0.0);
        let union = self.area() + other.area() - inter;
        if union > 0.0 { inter / union } else { 0.0 }
    }

    /// Whether every field is finite and the size positive.
    pub fn is_valid(&self) -> bool {
        self.x.is_finite()
            && self.y.is_finite()
            && self.w.is_finite()
            && self.h.is_finite()
            && self.w > 0.0
            && self.h > 0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Sizes whose product overflows `usize` (any target) are a mismatch, not a panic.
    #[test]
    fn from_vec_refuses_overflowing_sizes() {
        assert!(GrayImage::from_vec(usize::MAX, 2, vec![0; 4]).is_none());
        assert!(GrayImage::from_vec(2, 2, vec![0; 4]).is_some());
        assert!(GrayImage::from_vec(2, 3, vec![0; 4]).is_none());
    }

    #[test]
    fn contract_luma_is_the_rounded_f32_sum_on_every_input() {
        for rgb in 0..1u32 << 24 {
            let [r, g, b, _] = rgb.to_le_bytes();
            let v = 0.299 * f32::from(r) + 0.587 * f32::from(g) + 0.114 * f32::from(b);
            assert_eq!(contract_luma(r, g, b), v.round() as u8, "{r} {g} {b}");
        }
    }

    #[test]
    fn contract_luma_rounds_the_bt601_weights() {
        // 0.299·255 = 76.245 → 76; 0.299·10 + 0.587·200 + 0.114·30 = 123.81 → 124.
        assert_eq!(contract_luma(255, 0, 0), 76);
        assert_eq!(contract_luma(10, 200, 30), 124);
        assert_eq!(contract_luma(255, 255, 255), 255);
        let mut out = [0; 2];
        rgb_to_contract_luma(&[255, 0, 0, 10, 200, 30], &mut out);
        assert_eq!(out, [76, 124]);
    }
}

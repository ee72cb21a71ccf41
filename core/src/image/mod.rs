//! Images inside the core: the upright 8-bit luma image every stage works on, and the conversions
//! that produce it from camera frames.
//!
//! Pixel convention: see [`crate::camera`] — pixel (i, j) covers [i, i+1)×[j, j+1), its centre is
//! (i + 0.5, j + 0.5).

pub mod frame;

pub use frame::{Frame, FrameDesc, PixelFormat};

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
        (data.len() == width * height).then_some(Self {
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

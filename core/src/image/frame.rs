//! Camera frames as the app hands them over (borrowed bytes + a description) and their conversion
//! to the upright 8-bit luma image the pipeline works on.
//!
//! Byte layout of one buffer, by format (`row_stride` ≥ width × bytes per pixel; the last row may be
//! shorter than the stride, as Android's planes are):
//! - `Rgba8`, `Bgra8` (4 bytes/pixel), `Rgb8` (3), `Gray8` (1): `height` rows of `row_stride` bytes.
//!   `Gray8` is also how a YUV frame's Y plane alone is passed (zero copy from CameraX plane 0 or a
//!   CVPixelBuffer's plane 0), since tracking needs only luma.
//! - `Nv21` / `Nv12`: the Y plane (`height` rows of `row_stride`), then at offset
//!   `row_stride × height` one interleaved chroma plane of ⌈height/2⌉ rows of `chroma_row_stride`
//!   bytes, ⌈width/2⌉ samples per row `chroma_pixel_stride` (2) bytes apart (V first for NV21).
//! - `I420`: the Y plane, then the U plane at `row_stride × height` and the V plane
//!   `chroma_row_stride × ⌈height/2⌉` after it, samples `chroma_pixel_stride` (1) apart.
//!
//! Only the Y plane is read, but the whole description is validated against the buffer, so a
//! caller's stride bug surfaces as [`Error::InvalidFrame`] rather than as garbage.
//!
//! RGB → luma uses BT.601 full-range weights in 8-bit fixed point,
//! `(77 R + 150 G + 29 B + 128) >> 8`, within ±1 of `round(0.299 R + 0.587 G + 0.114 B)`.

use super::GrayImage;
use crate::camera::Rotation;
use crate::error::{Error, Result};
use crate::kernels::plane::{self, Orientation};
use serde::{Deserialize, Serialize};

/// Pixel formats a frame may arrive in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum PixelFormat {
    /// 8-bit R, G, B, A.
    Rgba8,
    /// 8-bit B, G, R, A (iOS `kCVPixelFormatType_32BGRA`).
    Bgra8,
    /// 8-bit R, G, B.
    Rgb8,
    /// 8-bit luma (or a YUV frame's Y plane alone).
    Gray8,
    /// Y plane + interleaved V/U (Android camera default).
    Nv21,
    /// Y plane + interleaved U/V (iOS bi-planar).
    Nv12,
    /// Y plane + U plane + V plane.
    I420,
}

impl PixelFormat {
    /// Bytes per pixel of the first (or only) plane.
    pub fn luma_bytes_per_pixel(self) -> usize {
        match self {
            Self::Rgba8 | Self::Bgra8 => 4,
            Self::Rgb8 => 3,
            Self::Gray8 | Self::Nv21 | Self::Nv12 | Self::I420 => 1,
        }
    }

    fn is_yuv(self) -> bool {
        matches!(self, Self::Nv21 | Self::Nv12 | Self::I420)
    }
}

/// Describes the bytes of one frame. See the module docs for the layouts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct FrameDesc {
    /// Buffer width in pixels (before rotation).
    pub width: u32,
    /// Buffer height in pixels (before rotation).
    pub height: u32,
    /// Pixel format.
    pub format: PixelFormat,
    /// Bytes from one row of the first plane to the next.
    pub row_stride: usize,
    /// Bytes from one chroma row to the next (YUV formats only).
    pub chroma_row_stride: usize,
    /// Bytes between consecutive chroma samples of one plane (2 interleaved, 1 planar).
    pub chroma_pixel_stride: usize,
    /// Clockwise rotation that makes the buffer upright.
    pub rotation: Rotation,
    /// Mirror the upright image left–right (front cameras' preview convention).
    pub mirrored: bool,
}

impl FrameDesc {
    /// A tightly packed frame of `format` (strides from the width), upright, not mirrored.
    /// Strides saturate rather than wrap where a 32-bit `usize` cannot hold them (a width near
    /// `u32::MAX`): [`Self::required_len`] then refuses the frame as it does on 64-bit targets.
    pub fn packed(width: u32, height: u32, format: PixelFormat) -> Self {
        let w = width as usize;
        let (crs, cps) = match format {
            PixelFormat::Nv21 | PixelFormat::Nv12 => (w.div_ceil(2).saturating_mul(2), 2),
            PixelFormat::I420 => (w.div_ceil(2), 1),
            _ => (0, 0),
        };
        Self {
            width,
            height,
            format,
            row_stride: w.saturating_mul(format.luma_bytes_per_pixel()),
            chroma_row_stride: crs,
            chroma_pixel_stride: cps,
            rotation: Rotation::R0,
            mirrored: false,
        }
    }

    /// Size of the upright image (width and height swap for 90° and 270°).
    pub fn upright_size(&self) -> (usize, usize) {
        let (w, h) = (self.width as usize, self.height as usize);
        if self.rotation.swaps_axes() {
            (h, w)
        } else {
            (w, h)
        }
    }

    /// Bytes a buffer must hold for this description (the last row of each plane may be short).
    ///
    /// # Errors
    /// [`Error::InvalidFrame`] for a zero size, a stride too small for the width, or sizes that
    /// overflow.
    pub fn required_len(&self) -> Result<usize> {
        let (w, h) = (u64::from(self.width), u64::from(self.height));
        if w == 0 || h == 0 {
            return Err(Error::InvalidFrame(format!(
                "zero-size frame {}x{}",
                self.width, self.height
            )));
        }
        if w > MAX_FRAME_SIDE || h > MAX_FRAME_SIDE {
            return Err(Error::InvalidFrame(format!(
                "frame {}x{} is larger than {MAX_FRAME_SIDE} pixels a side",
                self.width, self.height
            )));
        }
        // In u64 with checked steps, and refused above MAX_FRAME_BYTES, so that a 32-bit phone
        // (armv7: usize is 32 bits) and a 64-bit one accept and refuse exactly the same frames.
        let overflow = || {
            Error::InvalidFrame(format!(
                "{:?} {}x{} with strides {}/{}/{} needs more than {MAX_FRAME_BYTES} bytes",
                self.format,
                self.width,
                self.height,
                self.row_stride,
                self.chroma_row_stride,
                self.chroma_pixel_stride
            ))
        };
        let bpp = self.format.luma_bytes_per_pixel() as u64;
        let row = w * bpp;
        let stride = self.row_stride as u64;
        if stride < row {
            return Err(Error::InvalidFrame(format!(
                "row stride {} is smaller than width {} x {} bytes per pixel",
                self.row_stride, w, bpp
            )));
        }
        let fits = |v: Option<u64>| {
            v.filter(|&v| v <= MAX_FRAME_BYTES)
                .and_then(|v| usize::try_from(v).ok())
                .ok_or_else(overflow)
        };
        let y_plane = stride.checked_mul(h - 1).and_then(|v| v.checked_add(row));
        if !self.format.is_yuv() {
            return fits(y_plane);
        }
        let (cw, ch) = (w.div_ceil(2), h.div_ceil(2));
        let (crs, cps) = (
            self.chroma_row_stride as u64,
            self.chroma_pixel_stride as u64,
        );
        let interleaved = matches!(self.format, PixelFormat::Nv21 | PixelFormat::Nv12);
        let min_cps = if interleaved { 2 } else { 1 };
        if cps < min_cps {
            return Err(Error::InvalidFrame(format!(
                "chroma pixel stride {cps} must be at least {min_cps} for {:?}",
                self.format
            )));
        }
        // Bytes one chroma row needs: the last sample's offset plus its size.
        let chroma_row = (cw - 1)
            .checked_mul(cps)
            .and_then(|v| v.checked_add(if interleaved { 2 } else { 1 }))
            .ok_or_else(overflow)?;
        if crs < chroma_row {
            return Err(Error::InvalidFrame(format!(
                "chroma row stride {crs} is smaller than the {chroma_row} bytes a chroma row needs"
            )));
        }
        let y_full = stride.checked_mul(h);
        let plane = crs
            .checked_mul(ch - 1)
            .and_then(|v| v.checked_add(chroma_row));
        let total = if interleaved {
            y_full.zip(plane).and_then(|(y, p)| y.checked_add(p))
        } else {
            crs.checked_mul(ch)
                .zip(y_full)
                .and_then(|(u, y)| y.checked_add(u))
                .zip(plane)
                .and_then(|(v, p)| v.checked_add(p))
        };
        fits(total)
    }
}

/// Largest frame side accepted, pixels (camera frames are far smaller; the bound keeps every size
/// computation in range on 32-bit targets).
pub const MAX_FRAME_SIDE: u64 = 1 << 15;

/// Largest frame buffer accepted, bytes (1 GiB), on every target alike.
pub const MAX_FRAME_BYTES: u64 = 1 << 30;

/// BT.601 full-range luma in 8-bit fixed point (weights sum to 256).
#[inline]
fn luma(r: u8, g: u8, b: u8) -> u8 {
    ((77 * u32::from(r) + 150 * u32::from(g) + 29 * u32::from(b) + 128) >> 8) as u8
}

/// Borrowed frame bytes with their description.
#[derive(Debug, Clone, Copy)]
pub struct Frame<'a> {
    data: &'a [u8],
    desc: FrameDesc,
}

impl<'a> Frame<'a> {
    /// Wraps `data` after checking it against `desc`.
    ///
    /// # Errors
    /// [`Error::InvalidFrame`] when the description is inconsistent or `data` is too short for it.
    pub fn new(data: &'a [u8], desc: FrameDesc) -> Result<Self> {
        let need = desc.required_len()?;
        if data.len() < need {
            return Err(Error::InvalidFrame(format!(
                "{:?} {}x{} (row stride {}) needs {need} bytes, got {}",
                desc.format,
                desc.width,
                desc.height,
                desc.row_stride,
                data.len()
            )));
        }
        Ok(Self { data, desc })
    }

    /// The description.
    pub fn desc(&self) -> &FrameDesc {
        &self.desc
    }

    /// The bytes.
    pub fn data(&self) -> &'a [u8] {
        self.data
    }

    /// Converts to the upright (rotated, optionally mirrored) luma image in `out`, reusing its
    /// allocation.
    pub fn to_luma(&self, out: &mut GrayImage) {
        let d = &self.desc;
        let (w, h) = (d.width as usize, d.height as usize);
        let (ow, oh) = d.upright_size();
        out.resize(ow, oh);
        let dst = out.data_mut();
        let o = Orientation::new(d.rotation, d.mirrored);
        let bpp = d.format.luma_bytes_per_pixel();
        if bpp == 1 {
            // Gray8 and the YUV formats: only the Y plane is read.
            return plane::upright(self.data, d.row_stride, w, h, o, dst);
        }
        let (ri, bi) = if d.format == PixelFormat::Bgra8 {
            (2, 0)
        } else {
            (0, 2)
        };
        let stride = d.row_stride;
        if o.transposes() {
            // Each source row's luma written down an upright column. (Through the plane's 8×8
            // tiles, with the luma of eight pixels packed per word, it was slower for an RGBA
            // frame: the packing does not vectorise.)
            for y in 0..h {
                let row = &self.data[y * stride..y * stride + w * bpp];
                for (x, px) in row.chunks_exact(bpp).enumerate() {
                    let (ox, oy) = o.upright(x, y, w, h);
                    dst[oy * ow + ox] = luma(px[ri], px[1], px[bi]);
                }
            }
            return;
        }
        for y in 0..h {
            let row = &self.data[y * stride..y * stride + w * bpp];
            let dst_row = &mut dst[o.upright_row(y, h) * w..][..w];
            // A compile-time chunk size lets the compiler vectorise the loop.
            if bpp == 4 {
                for (o, px) in dst_row.iter_mut().zip(row.chunks_exact(4)) {
                    *o = luma(px[ri], px[1], px[bi]);
                }
            } else {
                for (o, px) in dst_row.iter_mut().zip(row.chunks_exact(3)) {
                    *o = luma(px[ri], px[1], px[bi]);
                }
            }
            if o.flips_x() {
                dst_row.reverse();
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A w×h RGB test pattern and its luma by the float formula.
    fn pattern(w: usize, h: usize) -> (Vec<[u8; 3]>, Vec<u8>) {
        let rgb: Vec<[u8; 3]> = (0..w * h)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                [
                    (x * 37 % 256) as u8,
                    (y * 53 % 256) as u8,
                    ((x + y) * 11 % 256) as u8,
                ]
            })
            .collect();
        let luma = rgb
            .iter()
            .map(|p| {
                (0.299 * f64::from(p[0]) + 0.587 * f64::from(p[1]) + 0.114 * f64::from(p[2]))
                    .round() as u8
            })
            .collect();
        (rgb, luma)
    }

    fn pack(
        rgb: &[[u8; 3]],
        w: usize,
        h: usize,
        format: PixelFormat,
        pad: usize,
    ) -> (Vec<u8>, FrameDesc) {
        let mut d = FrameDesc::packed(w as u32, h as u32, format);
        d.row_stride += pad;
        let bpp = format.luma_bytes_per_pixel();
        let mut buf = vec![0xAAu8; d.row_stride * h];
        for y in 0..h {
            for x in 0..w {
                let p = rgb[y * w + x];
                let o = y * d.row_stride + x * bpp;
                match format {
                    PixelFormat::Rgba8 => buf[o..o + 4].copy_from_slice(&[p[0], p[1], p[2], 255]),
                    PixelFormat::Bgra8 => buf[o..o + 4].copy_from_slice(&[p[2], p[1], p[0], 255]),
                    PixelFormat::Rgb8 => buf[o..o + 3].copy_from_slice(&p),
                    _ => unreachable!(),
                }
            }
        }
        // The last row may stop at the width.
        buf.truncate(d.row_stride * (h - 1) + w * bpp);
        (buf, d)
    }

    #[test]
    fn rgb_formats_give_bt601_luma_with_padded_strides() {
        let (w, h) = (13, 7);
        let (rgb, luma) = pattern(w, h);
        for format in [PixelFormat::Rgba8, PixelFormat::Bgra8, PixelFormat::Rgb8] {
            let (buf, d) = pack(&rgb, w, h, format, 5);
            let mut out = GrayImage::default();
            Frame::new(&buf, d).unwrap().to_luma(&mut out);
            assert_eq!((out.width(), out.height()), (w, h));
            for (a, b) in out.data().iter().zip(&luma) {
                assert!((i16::from(*a) - i16::from(*b)).abs() <= 1, "{format:?}");
            }
        }
    }

    fn yuv_buffer(
        luma: &[u8],
        w: usize,
        h: usize,
        format: PixelFormat,
        pad: usize,
    ) -> (Vec<u8>, FrameDesc) {
        let mut d = FrameDesc::packed(w as u32, h as u32, format);
        d.row_stride += pad;
        d.chroma_row_stride += pad;
        let need = d.required_len().unwrap();
        let mut buf = vec![128u8; need];
        for y in 0..h {
            buf[y * d.row_stride..y * d.row_stride + w].copy_from_slice(&luma[y * w..(y + 1) * w]);
        }
        (buf, d)
    }

    #[test]
    fn yuv_formats_read_the_y_plane_and_validate_chroma() {
        let (w, h) = (9, 5);
        let (_, luma) = pattern(w, h);
        for format in [
            PixelFormat::Nv21,
            PixelFormat::Nv12,
            PixelFormat::I420,
            PixelFormat::Gray8,
        ] {
            let (buf, d) = yuv_buffer(&luma, w, h, format, 3);
            let mut out = GrayImage::default();
            Frame::new(&buf, d).unwrap().to_luma(&mut out);
            assert_eq!(out.data(), &luma[..], "{format:?}");
            if format != PixelFormat::Gray8 {
                // One byte short of the chroma plane(s).
                assert!(matches!(
                    Frame::new(&buf[..buf.len() - 1], d),
                    Err(Error::InvalidFrame(_))
                ));
                let mut bad = d;
                bad.chroma_row_stride = 1;
                assert!(Frame::new(&buf, bad).is_err());
            }
        }
    }

    /// The size arithmetic gives the same answers on 32- and 64-bit targets: everything past the
    /// stated bounds is refused, never wrapped or panicking.
    #[test]
    fn sizes_past_the_bounds_are_refused_alike_on_every_target() {
        let side = MAX_FRAME_SIDE as u32;
        let gray = FrameDesc::packed(side, side, PixelFormat::Gray8);
        assert_eq!(gray.required_len().unwrap() as u64, MAX_FRAME_BYTES);
        // 4 GiB of RGBA: past the byte bound (and past a 32-bit usize).
        assert!(
            FrameDesc::packed(side, side, PixelFormat::Rgba8)
                .required_len()
                .is_err()
        );
        assert!(
            FrameDesc::packed(side + 1, 1, PixelFormat::Gray8)
                .required_len()
                .is_err()
        );
        assert!(
            FrameDesc::packed(u32::MAX, u32::MAX, PixelFormat::Rgba8)
                .required_len()
                .is_err()
        );
        let mut huge = FrameDesc::packed(640, 480, PixelFormat::Gray8);
        huge.row_stride = usize::MAX;
        assert!(huge.required_len().is_err());
        let mut nv = FrameDesc::packed(side, 2, PixelFormat::Nv21);
        nv.chroma_pixel_stride = u32::MAX as usize;
        nv.chroma_row_stride = usize::MAX;
        assert!(nv.required_len().is_err());
        let mut i420 = FrameDesc::packed(640, 480, PixelFormat::I420);
        i420.chroma_row_stride = 1 << 31;
        assert!(i420.required_len().is_err());
        assert_eq!(
            FrameDesc::packed(640, 480, PixelFormat::Nv21)
                .required_len()
                .unwrap(),
            640 * 480 * 3 / 2
        );
    }

    #[test]
    fn rotations_and_mirroring_match_a_reference() {
        for (w, h) in [(5, 3), (1, 4), (4, 1), (19, 13), (40, 33)] {
            let src: Vec<u8> = (0..w * h).map(|i| (i * 7 % 256) as u8).collect();
            let at = |x: usize, y: usize| src[y * w + x];
            for rot in [Rotation::R0, Rotation::R90, Rotation::R180, Rotation::R270] {
                for mirrored in [false, true] {
                    let mut d = FrameDesc::packed(w as u32, h as u32, PixelFormat::Gray8);
                    d.rotation = rot;
                    d.mirrored = mirrored;
                    let mut out = GrayImage::default();
                    Frame::new(&src, d).unwrap().to_luma(&mut out);
                    let (ow, oh) = d.upright_size();
                    assert_eq!((out.width(), out.height()), (ow, oh));
                    for oy in 0..oh {
                        for ox in 0..ow {
                            let cx = if mirrored { ow - 1 - ox } else { ox };
                            // Invert the clockwise rotation: upright (cx, oy) came from source (x, y).
                            let (x, y) = match rot {
                                Rotation::R0 => (cx, oy),
                                Rotation::R90 => (oy, h - 1 - cx),
                                Rotation::R180 => (w - 1 - cx, h - 1 - oy),
                                Rotation::R270 => (w - 1 - oy, cx),
                            };
                            assert_eq!(
                                out.get(ox, oy),
                                at(x, y),
                                "{rot:?} mirrored={mirrored} at ({ox},{oy})"
                            );
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn rgb_formats_turn_as_their_luma_does() {
        for (w, h) in [(5, 3), (19, 13), (40, 33)] {
            let (rgb, _) = pattern(w, h);
            for format in [PixelFormat::Rgba8, PixelFormat::Bgra8, PixelFormat::Rgb8] {
                let (buf, upright) = pack(&rgb, w, h, format, 5);
                let mut luma = GrayImage::default();
                Frame::new(&buf, upright).unwrap().to_luma(&mut luma);
                for rot in [Rotation::R0, Rotation::R90, Rotation::R180, Rotation::R270] {
                    for mirrored in [false, true] {
                        let turn = |format| FrameDesc {
                            rotation: rot,
                            mirrored,
                            ..FrameDesc::packed(w as u32, h as u32, format)
                        };
                        let (mut want, mut got) = (GrayImage::default(), GrayImage::default());
                        Frame::new(luma.data(), turn(PixelFormat::Gray8))
                            .unwrap()
                            .to_luma(&mut want);
                        let d = FrameDesc {
                            row_stride: upright.row_stride,
                            ..turn(format)
                        };
                        Frame::new(&buf, d).unwrap().to_luma(&mut got);
                        assert_eq!(got, want, "{format:?} {w}x{h} {rot:?} {mirrored}");
                    }
                }
            }
        }
    }

    #[test]
    fn bad_descriptions_are_typed_errors() {
        let buf = vec![0u8; 100];
        let d = FrameDesc::packed(0, 10, PixelFormat::Gray8);
        assert!(matches!(Frame::new(&buf, d), Err(Error::InvalidFrame(_))));
        let mut d = FrameDesc::packed(10, 10, PixelFormat::Rgba8);
        assert!(matches!(Frame::new(&buf, d), Err(Error::InvalidFrame(_)))); // too short
        d.row_stride = 39; // < 10 × 4
        assert!(matches!(
            Frame::new(&vec![0; 1000], d),
            Err(Error::InvalidFrame(_))
        ));
        let mut d = FrameDesc::packed(10, 10, PixelFormat::Nv21);
        d.chroma_pixel_stride = 1;
        assert!(Frame::new(&vec![0; 1000], d).is_err());
        let huge = FrameDesc {
            row_stride: usize::MAX / 2,
            ..FrameDesc::packed(u32::MAX, u32::MAX, PixelFormat::Gray8)
        };
        assert!(huge.required_len().is_err());
    }

    #[test]
    fn the_output_buffer_is_reused() {
        let src = vec![7u8; 64 * 48];
        let f = Frame::new(&src, FrameDesc::packed(64, 48, PixelFormat::Gray8)).unwrap();
        let mut out = GrayImage::default();
        f.to_luma(&mut out);
        let p = out.data().as_ptr();
        f.to_luma(&mut out);
        assert_eq!(p, out.data().as_ptr());
    }
}

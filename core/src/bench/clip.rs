//! The moving-face clip the benchmarks and the CLI's demo run on: a face picture under a smooth
//! similarity motion, rendered upright, then laid out as the camera would deliver it (format,
//! sensor orientation, mirroring), so the tracker converts real camera bytes and NCC and the flow
//! filter see motion.

use crate::error::{Error, Result};
use crate::image::{FrameDesc, GrayImage, PixelFormat};
use crate::kernels::plane::Orientation;
use crate::math::Libm;

/// Grey level of the background and of the blank frames.
pub const BACKGROUND: u8 = 96;

/// Renders frame `t` of the clip at `width`×`height` into `out`: `src` (a face picture) under a
/// smooth similarity — the centre on a Lissajous path (±90 px across, ±40 px down), scale
/// 0.88–1.12 (a face of about 100 px when the picture's is), roll ±12° — bilinear, on a mid-grey
/// background. Frame `cut` is blank (the face leaves the picture), forcing a re-detection after it.
pub fn render(
    src: &GrayImage,
    t: usize,
    cut: Option<usize>,
    width: usize,
    height: usize,
    out: &mut GrayImage,
) {
    out.resize(width, height);
    if cut == Some(t) || src.width() == 0 || src.height() == 0 {
        out.data_mut().fill(BACKGROUND);
        return;
    }
    let tf = t as f64;
    let scale = 1.0 + 0.12 * (tf * std::f64::consts::TAU / 90.0).msin();
    let angle = (12.0f64).to_radians() * (tf * std::f64::consts::TAU / 120.0).msin();
    let cx = width as f64 / 2.0 + 90.0 * (tf * std::f64::consts::TAU / 100.0).msin();
    let cy = height as f64 / 2.0 + 40.0 * (tf * std::f64::consts::TAU / 70.0).msin();
    let (sw, sh) = (src.width() as f64, src.height() as f64);
    let (ca, sa) = (angle.mcos() / scale, angle.msin() / scale);
    let data = out.data_mut();
    for y in 0..height {
        for x in 0..width {
            // Inverse map: frame pixel centre → source coordinates.
            let (dx, dy) = (x as f64 + 0.5 - cx, y as f64 + 0.5 - cy);
            let sx = ca * dx + sa * dy + sw / 2.0 - 0.5;
            let sy = -sa * dx + ca * dy + sh / 2.0 - 0.5;
            data[y * width + x] = if sx < 0.0 || sy < 0.0 || sx > sw - 1.0 || sy > sh - 1.0 {
                BACKGROUND
            } else {
                let (x0, y0) = (sx.floor() as usize, sy.floor() as usize);
                let (x1, y1) = (
                    (x0 + 1).min(src.width() - 1),
                    (y0 + 1).min(src.height() - 1),
                );
                let (fx, fy) = (sx - x0 as f64, sy - y0 as f64);
                let p = |xx: usize, yy: usize| f64::from(src.get(xx, yy));
                let v = (1.0 - fy) * ((1.0 - fx) * p(x0, y0) + fx * p(x1, y0))
                    + fy * ((1.0 - fx) * p(x0, y1) + fx * p(x1, y1));
                (v + 0.5) as u8
            };
        }
    }
}

/// Lays the upright luma image `upright` out as the camera buffer `desc` describes, into `buf`
/// (resized to [`FrameDesc::required_len`]): each buffer pixel takes the upright pixel it turns
/// into, chroma is neutral (128) and RGB pixels are grey (R = G = B, whose luma is that value), so
/// converting the buffer back gives `upright` exactly.
///
/// # Errors
/// [`Error::InvalidFrame`] when `desc` is inconsistent or `upright` is not its upright size.
pub fn encode(upright: &GrayImage, desc: &FrameDesc, buf: &mut Vec<u8>) -> Result<()> {
    let need = desc.required_len()?;
    let (ow, oh) = desc.upright_size();
    if (upright.width(), upright.height()) != (ow, oh) {
        return Err(Error::InvalidFrame(format!(
            "a {}x{} image is not the upright size {ow}x{oh} of the described frame",
            upright.width(),
            upright.height()
        )));
    }
    buf.clear();
    buf.resize(need, 128);
    let (w, h) = (desc.width as usize, desc.height as usize);
    let o = Orientation::new(desc.rotation, desc.mirrored);
    let bpp = desc.format.luma_bytes_per_pixel();
    for y in 0..h {
        for x in 0..w {
            let (ox, oy) = o.upright(x, y, w, h);
            let v = upright.get(ox, oy);
            let px = &mut buf[y * desc.row_stride + x * bpp..][..bpp];
            match desc.format {
                PixelFormat::Rgba8 | PixelFormat::Bgra8 => px.copy_from_slice(&[v, v, v, 255]),
                PixelFormat::Rgb8 => px.copy_from_slice(&[v, v, v]),
                _ => px[0] = v,
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Rotation;
    use crate::image::Frame;

    #[test]
    fn every_layout_converts_back_to_the_rendered_frame() {
        let src = GrayImage::from_vec(8, 6, (0..48).map(|i| (i * 5) as u8).collect()).unwrap();
        for format in [
            PixelFormat::Nv21,
            PixelFormat::Nv12,
            PixelFormat::I420,
            PixelFormat::Gray8,
            PixelFormat::Rgba8,
            PixelFormat::Bgra8,
            PixelFormat::Rgb8,
        ] {
            for rotation in [Rotation::R0, Rotation::R90, Rotation::R180, Rotation::R270] {
                for mirrored in [false, true] {
                    let desc = FrameDesc {
                        rotation,
                        mirrored,
                        ..FrameDesc::packed(37, 21, format)
                    };
                    let (ow, oh) = desc.upright_size();
                    let mut upright = GrayImage::default();
                    render(&src, 3, None, ow, oh, &mut upright);
                    let mut buf = Vec::new();
                    encode(&upright, &desc, &mut buf).unwrap();
                    let mut back = GrayImage::default();
                    Frame::new(&buf, desc).unwrap().to_luma(&mut back);
                    assert_eq!(back, upright, "{format:?} {rotation:?} {mirrored}");
                }
            }
        }
        let desc = FrameDesc::packed(37, 21, PixelFormat::Nv21);
        let wrong = GrayImage::new(37, 20);
        assert!(matches!(
            encode(&wrong, &desc, &mut Vec::new()),
            Err(Error::InvalidFrame(_))
        ));
    }

    #[test]
    fn the_face_moves_and_the_cut_is_blank() {
        let src = GrayImage::from_vec(4, 4, vec![250; 16]).unwrap();
        let (mut a, mut b) = (GrayImage::default(), GrayImage::default());
        render(&src, 0, Some(1), 64, 48, &mut a);
        render(&src, 10, Some(1), 64, 48, &mut b);
        assert_ne!(a, b);
        assert!(a.data().contains(&250));
        render(&src, 1, Some(1), 64, 48, &mut a);
        assert!(a.data().iter().all(|&v| v == BACKGROUND));
    }
}

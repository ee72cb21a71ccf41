//! Image files → upright luma, the one decoder every subcommand uses: `round(0.299 R + 0.587 G +
//! 0.114 B)` per pixel, exactly the conversion of `core/models/M3_IO.md` that the models were
//! trained with (the core's camera path uses a fixed-point form within ±1 of it, for speed).

use monotrack_core::image::{GrayImage, rgb_to_contract_luma};
use std::path::Path;

/// Converts a decoded image into `out` (resized; its allocation reused).
pub fn to_luma(img: &image::DynamicImage, out: &mut GrayImage) {
    // JPEG and most PNG files decode to RGB8: converted in place, without `to_rgb8`'s copy.
    let converted;
    let rgb = match img {
        image::DynamicImage::ImageRgb8(rgb) => rgb,
        _ => {
            converted = img.to_rgb8();
            &converted
        }
    };
    out.resize(rgb.width() as usize, rgb.height() as usize);
    rgb_to_contract_luma(rgb.as_raw(), out.data_mut());
}

/// Decodes the image file at `path` (PNG or JPEG) into `out`.
///
/// # Errors
/// A message naming the file when it cannot be read or decoded.
pub fn load_luma(path: &Path, out: &mut GrayImage) -> Result<(), String> {
    let img =
        image::open(path).map_err(|e| format!("cannot read image {}: {e}", path.display()))?;
    to_luma(&img, out);
    Ok(())
}

/// Decodes an encoded image held in memory into `out`.
///
/// # Errors
/// A message when the bytes are not a PNG or JPEG image.
pub fn decode_luma(bytes: &[u8], out: &mut GrayImage) -> Result<(), String> {
    let img = image::load_from_memory(bytes).map_err(|e| format!("cannot decode image: {e}"))?;
    to_luma(&img, out);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_bytes_are_an_error_not_a_panic() {
        let mut out = GrayImage::default();
        assert!(decode_luma(b"not an image", &mut out).is_err());
        assert!(load_luma(Path::new("/nonexistent/x.png"), &mut out).is_err());
    }
}

//! Pinhole camera intrinsics and the SDK's geometric conventions.
//!
//! Conventions (stated once here, referenced everywhere; they are those of `CONTRACT.md`):
//! - Image coordinates are pixels, x right, y down, origin at the top-left *corner* of the top-left
//!   pixel, so that pixel's centre is (0.5, 0.5).
//! - The camera frame is right-handed, x right, y down, z forward (OpenCV); units are millimetres.
//! - A pose (R, t) maps a model point X (model frame, mm) to camera coordinates R·X + t.
//! - The face model frame: x towards the subject's left (image right for a frontal face), y down, z away
//!   from the camera; a frontal face has R = I.
//! - Euler angles in degrees: yaw about y, pitch about x, roll about z, R = Rz(roll)·Ry(yaw)·Rx(pitch).
//! - Landmarks follow the 68-point iBUG / 300-W order.

use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};

/// Focal length, in units of the image's larger side, assumed when the caller gives no intrinsics
/// (about 58° horizontal field of view; CONTRACT.md).
pub const DEFAULT_FOCAL_PER_MAX_SIDE: f64 = 0.9;

/// Pinhole intrinsics in pixels (no distortion: phone camera frames are already undistorted).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Intrinsics {
    /// Focal length along x, pixels.
    pub fx: f64,
    /// Focal length along y, pixels.
    pub fy: f64,
    /// Principal point x, pixels (image convention above).
    pub cx: f64,
    /// Principal point y, pixels.
    pub cy: f64,
}

/// Clockwise rotation, in quarter turns, that makes a buffer upright (Android's `rotationDegrees`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub enum Rotation {
    /// Already upright.
    #[default]
    R0,
    /// Rotate 90° clockwise to make it upright.
    R90,
    /// Rotate 180°.
    R180,
    /// Rotate 270° clockwise (90° counter-clockwise).
    R270,
}

impl Rotation {
    /// From degrees (0, 90, 180, 270; negative and ≥ 360 values are wrapped).
    ///
    /// # Errors
    /// [`Error::InvalidFrame`] when the angle is not a multiple of 90°.
    pub fn from_degrees(deg: i32) -> Result<Self> {
        match deg.rem_euclid(360) {
            0 => Ok(Self::R0),
            90 => Ok(Self::R90),
            180 => Ok(Self::R180),
            270 => Ok(Self::R270),
            _ => Err(Error::InvalidFrame(format!(
                "rotation must be a multiple of 90 degrees, got {deg}"
            ))),
        }
    }

    /// The angle in degrees.
    pub fn degrees(self) -> i32 {
        match self {
            Self::R0 => 0,
            Self::R90 => 90,
            Self::R180 => 180,
            Self::R270 => 270,
        }
    }

    /// Whether width and height swap.
    pub fn swaps_axes(self) -> bool {
        matches!(self, Self::R90 | Self::R270)
    }
}

impl Intrinsics {
    /// Checked constructor.
    ///
    /// # Errors
    /// [`Error::InvalidCamera`] when a focal length is not finite and positive or the principal point
    /// is not finite.
    pub fn new(fx: f64, fy: f64, cx: f64, cy: f64) -> Result<Self> {
        let k = Self { fx, fy, cx, cy };
        k.validate()?;
        Ok(k)
    }

    /// The CONTRACT.md default for a `width`×`height` image: fx = fy = 0.9·max(w, h), centred
    /// principal point.
    ///
    /// # Errors
    /// [`Error::InvalidCamera`] for a zero-size image.
    pub fn default_for(width: u32, height: u32) -> Result<Self> {
        if width == 0 || height == 0 {
            return Err(Error::InvalidCamera(format!(
                "cannot derive intrinsics for a {width}x{height} image"
            )));
        }
        let f = DEFAULT_FOCAL_PER_MAX_SIDE * f64::from(width.max(height));
        Ok(Self {
            fx: f,
            fy: f,
            cx: f64::from(width) / 2.0,
            cy: f64::from(height) / 2.0,
        })
    }

    /// Check the values are usable.
    ///
    /// # Errors
    /// [`Error::InvalidCamera`] with the offending values.
    pub fn validate(&self) -> Result<()> {
        let ok = self.fx.is_finite()
            && self.fy.is_finite()
            && self.fx > 0.0
            && self.fy > 0.0
            && self.cx.is_finite()
            && self.cy.is_finite();
        if ok {
            Ok(())
        } else {
            Err(Error::InvalidCamera(format!(
                "fx, fy must be finite and > 0, cx, cy finite; got fx={}, fy={}, cx={}, cy={}",
                self.fx, self.fy, self.cx, self.cy
            )))
        }
    }

    /// Intrinsics of the upright image, given intrinsics of the `width`×`height` sensor buffer and the
    /// clockwise rotation that makes the buffer upright.
    pub fn rotated(&self, width: u32, height: u32, rotation: Rotation) -> Self {
        let (w, h) = (f64::from(width), f64::from(height));
        match rotation {
            Rotation::R0 => *self,
            // Sensor (x, y) lands at upright (h - y, x).
            Rotation::R90 => Self {
                fx: self.fy,
                fy: self.fx,
                cx: h - self.cy,
                cy: self.cx,
            },
            // (x, y) → (w - x, h - y).
            Rotation::R180 => Self {
                fx: self.fx,
                fy: self.fy,
                cx: w - self.cx,
                cy: h - self.cy,
            },
            // (x, y) → (y, w - x).
            Rotation::R270 => Self {
                fx: self.fy,
                fy: self.fx,
                cx: self.cy,
                cy: w - self.cx,
            },
        }
    }

    /// Intrinsics of the image mirrored left–right: a `width`-wide image's pixel x lands at
    /// `width − x` (corner-origin convention above), so the principal point does too.
    pub fn mirrored(&self, width: u32) -> Self {
        Self {
            cx: f64::from(width) - self.cx,
            ..*self
        }
    }

    /// Intrinsics of the upright image a `width`×`height` buffer becomes, given this buffer's
    /// (the sensor's, for the buffer as delivered): turned by `rotation`, then mirrored when
    /// `mirrored` — the order in which [`crate::image::Frame`] turns the pixels.
    pub fn for_upright(&self, width: u32, height: u32, rotation: Rotation, mirrored: bool) -> Self {
        let k = self.rotated(width, height, rotation);
        if mirrored {
            let upright_w = if rotation.swaps_axes() { height } else { width };
            k.mirrored(upright_w)
        } else {
            k
        }
    }

    /// Project a camera-frame point (mm) to pixels. Points at or behind the camera give non-finite
    /// values; callers that care check `z > 0` first.
    #[inline]
    pub fn project(&self, x: f64, y: f64, z: f64) -> (f64, f64) {
        (self.fx * x / z + self.cx, self.fy * y / z + self.cy)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_matches_contract() {
        let k = Intrinsics::default_for(640, 480).unwrap();
        assert_eq!((k.fx, k.fy, k.cx, k.cy), (576.0, 576.0, 320.0, 240.0));
        assert!(Intrinsics::default_for(0, 480).is_err());
    }

    #[test]
    fn rejects_nan_and_negative() {
        assert!(Intrinsics::new(f64::NAN, 1.0, 0.0, 0.0).is_err());
        assert!(Intrinsics::new(1.0, -1.0, 0.0, 0.0).is_err());
        assert!(Intrinsics::new(1.0, 1.0, f64::INFINITY, 0.0).is_err());
        assert!(Intrinsics::new(500.0, 500.0, 320.0, 240.0).is_ok());
    }

    /// Rotating the intrinsics must agree with rotating the projected pixel.
    #[test]
    fn rotated_intrinsics_follow_the_pixels() {
        let (w, h) = (640u32, 480u32);
        let k = Intrinsics::new(500.0, 520.0, 300.0, 250.0).unwrap();
        let p = (30.0, -20.0, 400.0);
        let (u, v) = k.project(p.0, p.1, p.2);
        let (wf, hf) = (f64::from(w), f64::from(h));
        for (rot, expect, cam) in [
            // The camera-frame point rotates with the image about the optical axis.
            (Rotation::R90, (hf - v, u), (-p.1, p.0)),
            (Rotation::R180, (wf - u, hf - v), (-p.0, -p.1)),
            (Rotation::R270, (v, wf - u), (p.1, -p.0)),
        ] {
            let kr = k.rotated(w, h, rot);
            let (ur, vr) = kr.project(cam.0, cam.1, p.2);
            assert!(
                (ur - expect.0).abs() < 1e-9 && (vr - expect.1).abs() < 1e-9,
                "{rot:?}"
            );
        }
        assert_eq!(Rotation::from_degrees(-90).unwrap(), Rotation::R270);
        // Mirrored after the turn: the upright pixel (h − v, u) reflected about the upright width
        // h, which is where the mirrored camera-frame point (x → −x) projects.
        let km = k.for_upright(w, h, Rotation::R90, true);
        let (um, vm) = km.project(p.1, p.0, p.2);
        assert!((um - (hf - (hf - v))).abs() < 1e-9 && (vm - u).abs() < 1e-9);
        assert!(Rotation::from_degrees(45).is_err());
    }
}

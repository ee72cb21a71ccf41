//! The records and enums Kotlin and Swift see, and their conversions to and from core types.
//! Conversions live here only; the core knows nothing of them.

use crate::MonotrackError;
use monotrack_core::camera::{Intrinsics, Rotation};
use monotrack_core::fit::{FaceFit, Pose, PoseUncertainty as CorePoseUncertainty};
use monotrack_core::image::{FrameDesc as CoreFrameDesc, PixelFormat as CorePixelFormat};
use monotrack_core::track::quality::{
    FaceQuality as CoreFaceQuality, QualityReason as CoreQualityReason, QualityReasons,
};

/// Pixel formats a frame may arrive in (see `FrameDesc`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, uniffi::Enum)]
pub enum PixelFormat {
    /// 8-bit R, G, B, A.
    Rgba8,
    /// 8-bit B, G, R, A (iOS 32BGRA).
    Bgra8,
    /// 8-bit R, G, B.
    Rgb8,
    /// 8-bit luma, or a YUV frame's Y plane alone (zero copy from CameraX / CVPixelBuffer plane 0).
    Gray8,
    /// Y plane then interleaved V/U in one buffer.
    Nv21,
    /// Y plane then interleaved U/V in one buffer.
    Nv12,
    /// Y plane, U plane, V plane in one buffer.
    I420,
}

/// Describes a frame's bytes. Packed formats: `row_stride` bytes per row (the last row may be
/// short). YUV in one buffer: Y rows of `row_stride`, then chroma rows of `uv_row_stride` with
/// samples `uv_pixel_stride` apart. `rotation_degrees`: clockwise rotation that makes the buffer
/// upright (CameraX `rotationDegrees`); `mirrored`: mirror the upright image (front camera).
#[derive(Debug, Clone, Copy, PartialEq, Eq, uniffi::Record)]
pub struct FrameDesc {
    /// Buffer width, pixels.
    pub width: u32,
    /// Buffer height, pixels.
    pub height: u32,
    /// Pixel format.
    pub format: PixelFormat,
    /// Bytes per row of the first plane.
    pub row_stride: u32,
    /// Bytes per chroma row (YUV only, else 0).
    pub uv_row_stride: u32,
    /// Bytes between chroma samples (2 interleaved, 1 planar; YUV only, else 0).
    pub uv_pixel_stride: u32,
    /// 0, 90, 180 or 270.
    pub rotation_degrees: u32,
    /// Mirror the upright image left–right.
    pub mirrored: bool,
}

impl TryFrom<FrameDesc> for CoreFrameDesc {
    type Error = MonotrackError;
    fn try_from(d: FrameDesc) -> Result<Self, MonotrackError> {
        let rotation = i32::try_from(d.rotation_degrees)
            .ok()
            .filter(|r| r % 90 == 0 && *r < 360)
            .ok_or_else(|| MonotrackError::InvalidFrame {
                msg: format!(
                    "rotation_degrees must be 0, 90, 180 or 270, got {}",
                    d.rotation_degrees
                ),
            })?;
        Ok(CoreFrameDesc {
            width: d.width,
            height: d.height,
            format: match d.format {
                PixelFormat::Rgba8 => CorePixelFormat::Rgba8,
                PixelFormat::Bgra8 => CorePixelFormat::Bgra8,
                PixelFormat::Rgb8 => CorePixelFormat::Rgb8,
                PixelFormat::Gray8 => CorePixelFormat::Gray8,
                PixelFormat::Nv21 => CorePixelFormat::Nv21,
                PixelFormat::Nv12 => CorePixelFormat::Nv12,
                PixelFormat::I420 => CorePixelFormat::I420,
            },
            row_stride: d.row_stride as usize,
            chroma_row_stride: d.uv_row_stride as usize,
            chroma_pixel_stride: d.uv_pixel_stride as usize,
            rotation: Rotation::from_degrees(rotation)?,
            mirrored: d.mirrored,
        })
    }
}

/// Pinhole intrinsics in pixels of the buffer as delivered: the sensor's (Camera2's
/// `LENS_INTRINSIC_CALIBRATION`, iOS's camera intrinsic matrix), scaled to the buffer's size, before
/// any rotation or mirroring. The SDK turns and mirrors them with the frame (`FrameDesc`), so the
/// pose comes out in the upright image's camera frame.
#[derive(Debug, Clone, Copy, PartialEq, uniffi::Record)]
pub struct CameraIntrinsics {
    /// Focal length x.
    pub fx: f64,
    /// Focal length y.
    pub fy: f64,
    /// Principal point x.
    pub cx: f64,
    /// Principal point y.
    pub cy: f64,
}

impl From<CameraIntrinsics> for Intrinsics {
    fn from(c: CameraIntrinsics) -> Self {
        Intrinsics {
            fx: c.fx,
            fy: c.fy,
            cx: c.cx,
            cy: c.cy,
        }
    }
}

impl From<Intrinsics> for CameraIntrinsics {
    fn from(c: Intrinsics) -> Self {
        Self {
            fx: c.fx,
            fy: c.fy,
            cx: c.cx,
            cy: c.cy,
        }
    }
}

/// A 2D point, pixels.
#[derive(Debug, Clone, Copy, PartialEq, uniffi::Record)]
pub struct Point2 {
    /// x, right.
    pub x: f32,
    /// y, down.
    pub y: f32,
}

/// A 3D vector.
#[derive(Debug, Clone, Copy, PartialEq, uniffi::Record)]
pub struct Vec3 {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
}

/// Head pose: X_cam = R·X_head + t (mm), the head frame's axes x towards the subject's left, y down
/// the face, z into the head; Euler angles per CONTRACT (R = Rz(roll)·Ry(yaw)·Rx(pitch)), all zero
/// for a face looking straight into the camera, upright (`monotrack_core::fit::pose`, "head
/// frame").
#[derive(Debug, Clone, PartialEq, uniffi::Record)]
pub struct HeadPose {
    /// R, 9 values row-major.
    pub rotation: Vec<f64>,
    /// t, millimetres.
    pub translation_mm: Vec3,
    /// Yaw, degrees.
    pub yaw_deg: f64,
    /// Pitch, degrees.
    pub pitch_deg: f64,
    /// Roll, degrees.
    pub roll_deg: f64,
}

impl From<&Pose> for HeadPose {
    fn from(p: &Pose) -> Self {
        let (yaw, pitch, roll) = p.euler_deg();
        let r = p.head_rotation();
        Self {
            rotation: (0..9).map(|k| r[(k / 3, k % 3)]).collect(),
            translation_mm: Vec3 {
                x: p.translation.x,
                y: p.translation.y,
                z: p.translation.z,
            },
            yaw_deg: yaw,
            pitch_deg: pitch,
            roll_deg: roll,
        }
    }
}

/// A named unit value (shape or action unit).
#[derive(Debug, Clone, PartialEq, uniffi::Record)]
pub struct NamedValue {
    /// snake_case name, as in the CLI's JSON.
    pub name: String,
    /// Value; ±1 spans the plausible range.
    pub value: f64,
}

/// The user's face shape: the 11 shape units (±1 spans the plausible range; 0 is the mean face).
#[derive(Debug, Clone, Copy, PartialEq, uniffi::Record)]
pub struct ShapeUnits {
    /// `eyes_height` (`SHAPE_UNIT_NAMES`).
    pub eyes_height: f64,
    /// `eyes_separation_distance` (`SHAPE_UNIT_NAMES`).
    pub eyes_separation_distance: f64,
    /// `eyes_vertical_position` (`SHAPE_UNIT_NAMES`).
    pub eyes_vertical_position: f64,
    /// `eyes_width` (`SHAPE_UNIT_NAMES`).
    pub eyes_width: f64,
    /// `face_length` (`SHAPE_UNIT_NAMES`).
    pub face_length: f64,
    /// `face_roundness` (`SHAPE_UNIT_NAMES`).
    pub face_roundness: f64,
    /// `lip_thickness` (`SHAPE_UNIT_NAMES`).
    pub lip_thickness: f64,
    /// `mouth_vertical_position` (`SHAPE_UNIT_NAMES`).
    pub mouth_vertical_position: f64,
    /// `mouth_width` (`SHAPE_UNIT_NAMES`).
    pub mouth_width: f64,
    /// `nose_width` (`SHAPE_UNIT_NAMES`).
    pub nose_width: f64,
    /// `nose_z_extension` (`SHAPE_UNIT_NAMES`).
    pub nose_z_extension: f64,
}

impl From<&[f64]> for ShapeUnits {
    fn from(v: &[f64]) -> Self {
        // The model's order (`SHAPE_UNIT_NAMES`); a shorter slice cannot occur (fixed-size arrays upstream).
        let at = |i: usize| v.get(i).copied().unwrap_or(0.0);
        Self {
            eyes_height: at(0),
            eyes_separation_distance: at(1),
            eyes_vertical_position: at(2),
            eyes_width: at(3),
            face_length: at(4),
            face_roundness: at(5),
            lip_thickness: at(6),
            mouth_vertical_position: at(7),
            mouth_width: at(8),
            nose_width: at(9),
            nose_z_extension: at(10),
        }
    }
}

/// The expression: the 6 animation units (0 neutral, 1 the unit's full extent).
#[derive(Debug, Clone, Copy, PartialEq, uniffi::Record)]
pub struct ActionUnits {
    /// `open_mouth` (`ANIM_UNIT_NAMES`).
    pub open_mouth: f64,
    /// `raise_left_outer_eyebrow` (`ANIM_UNIT_NAMES`).
    pub raise_left_outer_eyebrow: f64,
    /// `raise_nose_bridge` (`ANIM_UNIT_NAMES`).
    pub raise_nose_bridge: f64,
    /// `raise_right_outer_eyebrow` (`ANIM_UNIT_NAMES`).
    pub raise_right_outer_eyebrow: f64,
    /// `smile` (`ANIM_UNIT_NAMES`).
    pub smile: f64,
    /// `stretch_lips` (`ANIM_UNIT_NAMES`).
    pub stretch_lips: f64,
}

impl From<&[f64]> for ActionUnits {
    fn from(v: &[f64]) -> Self {
        // The model's order (`ANIM_UNIT_NAMES`); a shorter slice cannot occur (fixed-size arrays upstream).
        let at = |i: usize| v.get(i).copied().unwrap_or(0.0);
        Self {
            open_mouth: at(0),
            raise_left_outer_eyebrow: at(1),
            raise_nose_bridge: at(2),
            raise_right_outer_eyebrow: at(3),
            smile: at(4),
            stretch_lips: at(5),
        }
    }
}

/// Which 3D fit to run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, uniffi::Enum)]
pub enum FitMethod {
    /// Full perspective multi-step fit.
    Msbp,
    /// Weak perspective, ultra-light.
    Ffbp,
}

/// A fitted face model.
#[derive(Debug, Clone, PartialEq, uniffi::Record)]
pub struct FitResult {
    /// Head pose.
    pub pose: HeadPose,
    /// The 11 shape units.
    pub shape_units: ShapeUnits,
    /// The 6 animation (action) units.
    pub action_units: ActionUnits,
    /// RMS reprojection error, pixels.
    pub fit_rms_px: f64,
    /// Solver iterations.
    pub iterations: u32,
    /// Whether the solver ended at a minimum.
    pub converged: bool,
    /// How far to trust `pose`: standard deviations of its angles and translation.
    pub uncertainty: PoseUncertainty,
}

/// Standard deviations of a fitted head pose, from the fit's covariance, calibrated so that
/// about 68 % of the pose errors fall within one (`monotrack_core::fit::uncertainty`).
#[derive(Debug, Clone, Copy, PartialEq, uniffi::Record)]
pub struct PoseUncertainty {
    /// Of `HeadPose.yaw_deg`, degrees.
    pub yaw_deg: f64,
    /// Of `HeadPose.pitch_deg`, degrees.
    pub pitch_deg: f64,
    /// Of `HeadPose.roll_deg`, degrees.
    pub roll_deg: f64,
    /// Of `HeadPose.translation_mm`, per axis, millimetres.
    pub translation_mm: Vec3,
}

impl From<&CorePoseUncertainty> for PoseUncertainty {
    fn from(u: &CorePoseUncertainty) -> Self {
        let [yaw_deg, pitch_deg, roll_deg] = u.rotation_deg;
        let [x, y, z] = u.translation_mm;
        Self {
            yaw_deg,
            pitch_deg,
            roll_deg,
            translation_mm: Vec3 { x, y, z },
        }
    }
}

/// Why a face or a frame is poor (`monotrack_core::track::quality` documents each measurement;
/// `TrackerTuning.quality` holds the thresholds).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, uniffi::Enum)]
pub enum QualityReason {
    /// Too little light.
    Dark,
    /// Too much light: much of the face (or frame) saturated.
    Overexposed,
    /// Motion or focus blur, or sharpness well below the recent frames'.
    Blurred,
    /// The face is too small in the frame: come closer.
    Small,
    /// Part of the face is outside the frame.
    PartlyOutside,
    /// The head is turned further than the landmarks hold.
    Turned,
    /// The landmarks are unsure (a hand, a mask, hair over the face).
    Occluded,
    /// No face in the frame (frame reasons only).
    NoFace,
    /// A face tracked on the previous frame is gone (frame reasons only).
    Lost,
}

impl From<CoreQualityReason> for QualityReason {
    fn from(r: CoreQualityReason) -> Self {
        match r {
            CoreQualityReason::Dark => Self::Dark,
            CoreQualityReason::Overexposed => Self::Overexposed,
            CoreQualityReason::Blurred => Self::Blurred,
            CoreQualityReason::Small => Self::Small,
            CoreQualityReason::PartlyOutside => Self::PartlyOutside,
            CoreQualityReason::Turned => Self::Turned,
            CoreQualityReason::Occluded => Self::Occluded,
            CoreQualityReason::NoFace => Self::NoFace,
            CoreQualityReason::Lost => Self::Lost,
        }
    }
}

/// The reasons of a set, in their fixed order.
pub(crate) fn reasons(r: QualityReasons) -> Vec<QualityReason> {
    r.iter().map(QualityReason::from).collect()
}

/// A face's quality: a score and the reasons that lower it.
#[derive(Debug, Clone, PartialEq, uniffi::Record)]
pub struct FaceQuality {
    /// 0..1, the product of every measurement's factor (each 0.5 at its threshold).
    pub score: f32,
    /// The measurements past their thresholds (empty for a good face).
    pub reasons: Vec<QualityReason>,
}

impl From<&CoreFaceQuality> for FaceQuality {
    fn from(q: &CoreFaceQuality) -> Self {
        Self {
            score: q.score,
            reasons: reasons(q.reasons),
        }
    }
}

/// Unit values paired with their names (shared by every record that lists units).
pub(crate) fn named(names: &[&str], values: &[f64]) -> Vec<NamedValue> {
    names
        .iter()
        .zip(values)
        .map(|(n, v)| NamedValue {
            name: (*n).to_string(),
            value: *v,
        })
        .collect()
}

impl From<&FaceFit> for FitResult {
    fn from(f: &FaceFit) -> Self {
        Self {
            pose: HeadPose::from(&f.pose),
            shape_units: ShapeUnits::from(&f.shape[..]),
            action_units: ActionUnits::from(&f.animation[..]),
            fit_rms_px: f.report.rms_px,
            iterations: f.report.iterations,
            converged: f.report.converged,
            uncertainty: PoseUncertainty::from(&f.uncertainty),
        }
    }
}

/// An upright 8-bit luma image (what the pipeline sees of a frame).
#[derive(Debug, Clone, PartialEq, Eq, uniffi::Record)]
pub struct LumaImage {
    /// Width after rotation.
    pub width: u32,
    /// Height after rotation.
    pub height: u32,
    /// Row-major pixels, `width * height` bytes.
    pub pixels: Vec<u8>,
}

#[cfg(test)]
mod unit_tests {
    use super::*;
    use monotrack_core::model::{ANIM_UNIT_NAMES, SHAPE_UNIT_NAMES};

    /// The records' fields are the model's units, by name and in order.
    #[test]
    fn unit_records_follow_the_model_order() {
        assert_eq!(
            SHAPE_UNIT_NAMES,
            [
                "eyes_height",
                "eyes_separation_distance",
                "eyes_vertical_position",
                "eyes_width",
                "face_length",
                "face_roundness",
                "lip_thickness",
                "mouth_vertical_position",
                "mouth_width",
                "nose_width",
                "nose_z_extension",
            ]
        );
        assert_eq!(
            ANIM_UNIT_NAMES,
            [
                "open_mouth",
                "raise_left_outer_eyebrow",
                "raise_nose_bridge",
                "raise_right_outer_eyebrow",
                "smile",
                "stretch_lips",
            ]
        );
        let v: Vec<f64> = (0..11).map(f64::from).collect();
        let s = ShapeUnits::from(&v[..]);
        assert_eq!(
            (s.eyes_height, s.face_roundness, s.nose_z_extension),
            (0.0, 5.0, 10.0)
        );
        let a = ActionUnits::from(&v[..6]);
        assert_eq!((a.open_mouth, a.smile, a.stretch_lips), (0.0, 4.0, 5.0));
    }
}

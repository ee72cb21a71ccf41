//! The rules an app's frame plumbing and overlay need, computed in Rust so that Kotlin and Swift
//! keep no copies (`bindings/API.md`, "Frames and overlays"): the upright size and the bytes a
//! frame needs, default intrinsics (`default_camera` in `lib.rs`), point projection, the head's
//! axes, the gaze arrows and the transform's OpenGL / ARKit axes.

use crate::MonotrackError;
use crate::error::guard;
use crate::tracker::Gaze;
use crate::types::{CameraIntrinsics, FrameDesc, HeadPose, Point2, Vec3};
use monotrack_core::camera::Intrinsics;
use monotrack_core::image::FrameDesc as CoreFrameDesc;
use monotrack_core::model::N_LANDMARKS;
use monotrack_core::overlay;
use nalgebra::{Matrix3, Vector3};

/// A width and height, pixels.
#[derive(Debug, Clone, Copy, PartialEq, Eq, uniffi::Record)]
pub struct FrameSize {
    /// Width.
    pub width: u32,
    /// Height.
    pub height: u32,
}

/// The size of the upright image a frame's results refer to (width and height swap for 90° and
/// 270°).
///
/// # Errors
/// `InvalidFrame` for a rotation that is not 0, 90, 180 or 270.
#[uniffi::export]
pub fn upright_size(desc: FrameDesc) -> Result<FrameSize, MonotrackError> {
    guard(|| {
        let d = CoreFrameDesc::try_from(desc)?;
        let (width, height) = d.upright_size();
        Ok(FrameSize {
            width: width as u32,
            height: height as u32,
        })
    })
}

/// The bytes a buffer must hold for `desc` (the last row may stop after its pixels, as camera
/// HALs end planes): what `detect*` checks a frame's bytes against.
///
/// # Errors
/// `InvalidFrame` for a zero size, a row stride shorter than a row, a chroma layout the format
/// cannot have, or a rotation that is not a quarter turn.
#[uniffi::export]
pub fn frame_byte_count(desc: FrameDesc) -> Result<u64, MonotrackError> {
    guard(|| Ok(CoreFrameDesc::try_from(desc)?.required_len()? as u64))
}

fn vector(v: &Vec3) -> Vector3<f64> {
    Vector3::new(v.x, v.y, v.z)
}

fn point(p: [f64; 2]) -> Point2 {
    Point2 {
        x: p[0] as f32,
        y: p[1] as f32,
    }
}

/// A camera-frame point (mm) in pixels of the image `camera` describes (a result's `camera`);
/// `None` on or behind the camera plane.
#[uniffi::export]
pub fn project_point(camera: CameraIntrinsics, point_mm: Vec3) -> Option<Point2> {
    overlay::project(&Intrinsics::from(camera), &vector(&point_mm)).map(point)
}

/// The head's axes in pixels, for drawing a pose gizmo.
#[derive(Debug, Clone, Copy, PartialEq, uniffi::Record)]
pub struct HeadAxes {
    /// The head frame's origin.
    pub origin: Point2,
    /// Tip of the x axis (towards the subject's left).
    pub x: Point2,
    /// Tip of the y axis (down the face).
    pub y: Point2,
    /// Tip of the z axis (into the head, away from a frontal camera).
    pub z: Point2,
}

/// The head frame's axes, `length_mm` long (a face is about 140 mm wide), projected through
/// `camera` (the result's `camera`); `None` when an end lies behind the camera.
///
/// # Errors
/// `InvalidConfig` for a rotation without 9 finite values.
#[uniffi::export]
pub fn head_axes(
    pose: HeadPose,
    camera: CameraIntrinsics,
    length_mm: f64,
) -> Result<Option<HeadAxes>, MonotrackError> {
    guard(|| {
        if pose.rotation.len() != 9 || pose.rotation.iter().any(|v| !v.is_finite()) {
            return Err(MonotrackError::InvalidConfig {
                msg: format!(
                    "a pose rotation has 9 finite values, got {:?}",
                    pose.rotation
                ),
            });
        }
        let r = Matrix3::from_row_slice(&pose.rotation);
        let t = vector(&pose.translation_mm);
        Ok(
            overlay::head_axes(&r, &t, &Intrinsics::from(camera), length_mm).map(|a| HeadAxes {
                origin: point(a.origin),
                x: point(a.x),
                y: point(a.y),
                z: point(a.z),
            }),
        )
    })
}

/// A 2D arrow, pixels.
#[derive(Debug, Clone, Copy, PartialEq, uniffi::Record)]
pub struct Arrow {
    /// The tail (an eye's centre).
    pub from: Point2,
    /// The head.
    pub to: Point2,
}

/// One arrow per eye.
#[derive(Debug, Clone, Copy, PartialEq, uniffi::Record)]
pub struct GazeArrows {
    /// The subject's right eye.
    pub right: Arrow,
    /// The subject's left eye.
    pub left: Arrow,
}

/// Gaze arrows for drawing: from each eye's landmark centroid along its gaze direction's
/// image-plane part, `length_px` long for a gaze across the optical axis (a sketch for an overlay,
/// not a measurement).
///
/// # Errors
/// `InvalidConfig` for other than 68 landmarks.
#[uniffi::export]
pub fn gaze_arrows(
    landmarks: Vec<Point2>,
    gaze: Gaze,
    length_px: f32,
) -> Result<GazeArrows, MonotrackError> {
    guard(|| {
        let mut pts = [[0.0f32; 2]; N_LANDMARKS];
        if landmarks.len() != N_LANDMARKS {
            return Err(MonotrackError::InvalidConfig {
                msg: format!("expected {N_LANDMARKS} landmarks, got {}", landmarks.len()),
            });
        }
        for (o, p) in pts.iter_mut().zip(&landmarks) {
            *o = [p.x, p.y];
        }
        let f = |v: &Vec3| [v.x as f32, v.y as f32, v.z as f32];
        let [r, l] = overlay::gaze_arrows(&pts, &f(&gaze.right), &f(&gaze.left), length_px);
        let arrow = |a: [[f32; 2]; 2]| Arrow {
            from: Point2 {
                x: a[0][0],
                y: a[0][1],
            },
            to: Point2 {
                x: a[1][0],
                y: a[1][1],
            },
        };
        Ok(GazeArrows {
            right: arrow(r),
            left: arrow(l),
        })
    })
}

/// A face's `transform` (OpenCV camera axes: x right, y down, z forward) in OpenGL / ARKit /
/// SceneKit axes (x right, y up, z towards the viewer), head frame turned alike: F·M·F with
/// F = diag(1, −1, −1, 1). Still millimetres: scale the translation by 0.001 for ARKit's metres.
///
/// # Errors
/// `InvalidConfig` for other than 16 values.
#[uniffi::export]
pub fn opengl_transform(transform: Vec<f64>) -> Result<Vec<f64>, MonotrackError> {
    guard(|| {
        let m: [f64; 16] =
            transform
                .as_slice()
                .try_into()
                .map_err(|_| MonotrackError::InvalidConfig {
                    msg: format!("a transform has 16 values, got {}", transform.len()),
                })?;
        Ok(monotrack_core::fit::pose::opengl_transform(&m).to_vec())
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::types::PixelFormat;

    #[test]
    fn frame_rules_are_the_cores() {
        let desc = FrameDesc {
            width: 640,
            height: 480,
            format: PixelFormat::Nv21,
            row_stride: 704,
            uv_row_stride: 704,
            uv_pixel_stride: 2,
            rotation_degrees: 90,
            mirrored: true,
        };
        assert_eq!(
            upright_size(desc).unwrap(),
            FrameSize {
                width: 480,
                height: 640
            }
        );
        // 480 Y rows of 704 (the chroma plane follows them), 240 chroma rows of 704 (the last
        // one ends after its 640 bytes).
        assert_eq!(frame_byte_count(desc).unwrap(), 704 * 480 + 704 * 239 + 640);
        let bad = FrameDesc {
            row_stride: 600,
            ..desc
        };
        assert!(matches!(
            frame_byte_count(bad),
            Err(MonotrackError::InvalidFrame { .. })
        ));
        assert!(matches!(
            upright_size(FrameDesc {
                rotation_degrees: 45,
                ..desc
            }),
            Err(MonotrackError::InvalidFrame { .. })
        ));
    }

    #[test]
    fn overlay_inputs_are_checked() {
        let k = CameraIntrinsics {
            fx: 500.0,
            fy: 500.0,
            cx: 320.0,
            cy: 240.0,
        };
        let pose = HeadPose {
            rotation: vec![1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
            translation_mm: Vec3 {
                x: 0.0,
                y: 0.0,
                z: 500.0,
            },
            yaw_deg: 0.0,
            pitch_deg: 0.0,
            roll_deg: 0.0,
        };
        let a = head_axes(pose.clone(), k, 50.0).unwrap().unwrap();
        assert_eq!((a.origin.x, a.origin.y), (320.0, 240.0));
        assert_eq!((a.x.x, a.y.y), (370.0, 290.0));
        let short = HeadPose {
            rotation: vec![1.0; 4],
            ..pose
        };
        assert!(head_axes(short, k, 50.0).is_err());
        let p = project_point(
            k,
            Vec3 {
                x: 10.0,
                y: 0.0,
                z: 100.0,
            },
        );
        assert_eq!(p, Some(Point2 { x: 370.0, y: 240.0 }));
        let z = Vec3 {
            x: 0.0,
            y: 0.0,
            z: -1.0,
        };
        let gaze = Gaze {
            left: z,
            right: z,
            combined: z,
        };
        assert!(gaze_arrows(vec![Point2 { x: 0.0, y: 0.0 }; 5], gaze, 10.0).is_err());
        assert!(opengl_transform(vec![0.0; 15]).is_err());
        let mut m = vec![0.0; 16];
        for i in 0..4 {
            m[i * 5] = 1.0;
        }
        m[3] = 7.0;
        m[7] = 8.0;
        m[11] = 9.0;
        let gl = opengl_transform(m).unwrap();
        assert_eq!((gl[3], gl[7], gl[11]), (7.0, -8.0, -9.0));
        assert_eq!((gl[0], gl[5], gl[10]), (1.0, 1.0, 1.0));
    }
}

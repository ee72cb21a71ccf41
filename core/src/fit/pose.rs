//! Head pose: rotation + translation, Euler angles per `CONTRACT.md`
//! (R = Rz(roll)·Ry(yaw)·Rx(pitch), degrees) and the rotation's partial derivatives used by the
//! analytic Jacobians.
//!
//! Two frames share the model's origin. The *model frame* is the one the face model's vertices
//! are given in and the fit solves for ([`Pose::rotation`]); the *head frame* is the model frame
//! turned by the constant [`HEAD_FRAME_PITCH_DEG`], so that zero angles mean a face looking
//! straight into the camera, upright. What the SDK reports (Euler angles, [`Pose::transform`])
//! is the head frame; everything that places model points (projection, vertices, eye centres)
//! uses the model frame.

use crate::math::Libm;
use nalgebra::{Matrix3, Vector3};

/// The head frame's pitch relative to the face model's frame, degrees: the head frame is the
/// model frame turned by Rx(this), so the reported pitch is the model frame's plus this.
///
/// Set as the mean signed difference between the MediaPipe Face Landmarker's head pitch (the
/// teacher of `../shared/data/faces68`) and the pitch fitted to the SDK's own landmarks, on the
/// faces68 training split only (`models/train/eval_head_frame.py`, which also writes the
/// resulting bias on both splits to `models/face_model/head_frame_metrics.json`). The model frame's
/// zero pitch is a convention of the mean face it was built from (`models/face_model/build.py`),
/// not a face looking into the camera. Yaw and roll get no turn: the mean face is left/right
/// symmetric, and the same measurement finds their bias within a fraction of a degree.
pub const HEAD_FRAME_PITCH_DEG: f64 = -4.48;

/// The head frame's axes in the model frame, R0 = Rx([`HEAD_FRAME_PITCH_DEG`]): a head-frame
/// point X_h is the model point R0·X_h.
pub fn head_frame_in_model() -> Matrix3<f64> {
    rx(HEAD_FRAME_PITCH_DEG.to_radians())
}

/// A rigid pose mapping model points (mm) to camera coordinates: X_cam = R·X + t.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    /// Rotation matrix R.
    pub rotation: Matrix3<f64>,
    /// Translation t, millimetres.
    pub translation: Vector3<f64>,
}

impl Default for Pose {
    fn default() -> Self {
        Self {
            rotation: Matrix3::identity(),
            translation: Vector3::new(0.0, 0.0, 600.0),
        }
    }
}

/// Rx(a), Ry(b), Rz(c) for the CONTRACT's Euler convention.
fn rx(a: f64) -> Matrix3<f64> {
    let (s, c) = a.msin_cos();
    Matrix3::new(1.0, 0.0, 0.0, 0.0, c, -s, 0.0, s, c)
}
fn ry(a: f64) -> Matrix3<f64> {
    let (s, c) = a.msin_cos();
    Matrix3::new(c, 0.0, s, 0.0, 1.0, 0.0, -s, 0.0, c)
}
fn rz(a: f64) -> Matrix3<f64> {
    let (s, c) = a.msin_cos();
    Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0)
}
fn drx(a: f64) -> Matrix3<f64> {
    let (s, c) = a.msin_cos();
    Matrix3::new(0.0, 0.0, 0.0, 0.0, -s, -c, 0.0, c, -s)
}
fn dry(a: f64) -> Matrix3<f64> {
    let (s, c) = a.msin_cos();
    Matrix3::new(-s, 0.0, c, 0.0, 0.0, 0.0, -c, 0.0, -s)
}
fn drz(a: f64) -> Matrix3<f64> {
    let (s, c) = a.msin_cos();
    Matrix3::new(-s, -c, 0.0, c, -s, 0.0, 0.0, 0.0, 0.0)
}

/// R(θ) = Rz(θz)·Ry(θy)·Rx(θx) for angles θ = (pitch θx, yaw θy, roll θz) in radians.
pub fn rotation_from_angles(th: &Vector3<f64>) -> Matrix3<f64> {
    rz(th.z) * ry(th.y) * rx(th.x)
}

/// R(θ) and its three partial derivatives ∂R/∂θx, ∂R/∂θy, ∂R/∂θz.
pub fn rotation_and_derivatives(th: &Vector3<f64>) -> (Matrix3<f64>, [Matrix3<f64>; 3]) {
    let (x, y, z) = (rx(th.x), ry(th.y), rz(th.z));
    let r = z * y * x;
    let d = [z * y * drx(th.x), z * dry(th.y) * x, drz(th.z) * y * x];
    (r, d)
}

/// Angles θ = (pitch, yaw, roll) in radians with R = Rz·Ry·Rx; yaw in [-90°, 90°].
pub fn angles_from_rotation(r: &Matrix3<f64>) -> Vector3<f64> {
    // R[2][0] = -sin(yaw); R[2][1] = cos(yaw) sin(pitch); R[1][0] = sin(roll) cos(yaw).
    let yaw = (-r[(2, 0)]).clamp(-1.0, 1.0).masin();
    if yaw.mcos().abs() > 1e-9 {
        let pitch = r[(2, 1)].matan2(r[(2, 2)]);
        let roll = r[(1, 0)].matan2(r[(0, 0)]);
        Vector3::new(pitch, yaw, roll)
    } else {
        // Gimbal lock: only pitch - roll (or pitch + roll) is defined; put it all in pitch.
        let pitch = (-r[(1, 2)]).matan2(r[(1, 1)]);
        Vector3::new(pitch, yaw, 0.0)
    }
}

impl Pose {
    /// From the *model frame's* Euler angles in degrees (CONTRACT convention; `rotation` =
    /// Rz(roll)·Ry(yaw)·Rx(pitch)) and a translation in mm: what synthetic round trips of the fit
    /// build. Its inverse is [`Pose::model_euler_deg`]; for the reported angles see
    /// [`Pose::from_head_euler_deg`].
    pub fn from_euler_deg(yaw: f64, pitch: f64, roll: f64, translation: Vector3<f64>) -> Self {
        let th = Vector3::new(pitch.to_radians(), yaw.to_radians(), roll.to_radians());
        Self {
            rotation: rotation_from_angles(&th),
            translation,
        }
    }

    /// From the head frame's Euler angles in degrees (those [`Pose::euler_deg`] reports) and a
    /// translation in mm.
    pub fn from_head_euler_deg(yaw: f64, pitch: f64, roll: f64, translation: Vector3<f64>) -> Self {
        let mut pose = Self::from_euler_deg(yaw, pitch, roll, translation);
        pose.rotation *= head_frame_in_model().transpose();
        pose
    }

    /// The head frame's rotation R·R0 ([`head_frame_in_model`]): camera coordinates of the head
    /// frame's axes, the rotation the SDK reports.
    pub fn head_rotation(&self) -> Matrix3<f64> {
        self.rotation * head_frame_in_model()
    }

    /// The reported (yaw, pitch, roll) in degrees: the Euler angles (CONTRACT convention) of
    /// [`Pose::head_rotation`]; all zero for a face looking straight into the camera, upright.
    pub fn euler_deg(&self) -> (f64, f64, f64) {
        euler_deg_of(&self.head_rotation())
    }

    /// (yaw, pitch, roll) in degrees of the model frame's rotation [`Pose::rotation`].
    pub fn model_euler_deg(&self) -> (f64, f64, f64) {
        euler_deg_of(&self.rotation)
    }

    /// The 4×4 row-major matrix [R·R0 | t; 0 0 0 1] mapping head-frame points (mm) into the
    /// camera frame (OpenCV axes: x right, y down, z forward). The head frame shares the model's
    /// origin (`models/face_model/build.py`); its axes are x towards the subject's left, y down,
    /// z into the head. [`opengl_transform`] converts it to OpenGL / ARKit axes.
    pub fn transform(&self) -> [f64; 16] {
        let r = self.head_rotation();
        let t = &self.translation;
        [
            r[(0, 0)],
            r[(0, 1)],
            r[(0, 2)],
            t.x,
            r[(1, 0)],
            r[(1, 1)],
            r[(1, 2)],
            t.y,
            r[(2, 0)],
            r[(2, 1)],
            r[(2, 2)],
            t.z,
            0.0,
            0.0,
            0.0,
            1.0,
        ]
    }

    /// Angle in degrees of the rotation taking `self` to `other` (geodesic distance on SO(3)).
    pub fn rotation_angle_to(&self, other: &Pose) -> f64 {
        rotation_angle_deg(&(self.rotation.transpose() * other.rotation))
    }
}

fn euler_deg_of(r: &Matrix3<f64>) -> (f64, f64, f64) {
    let th = angles_from_rotation(r);
    (th.y.to_degrees(), th.x.to_degrees(), th.z.to_degrees())
}

/// [`Pose::transform`] (or any 4×4 row-major rigid transform between OpenCV-axis frames) in
/// OpenGL / ARKit / SceneKit camera axes: x right, y up, z towards the viewer. Both the head
/// frame and the camera frame are turned the same way (y and z negated), so the result is
/// F·M·F with F = diag(1, −1, −1, 1): the head frame's x stays towards the subject's left, its y
/// points up and its z out of the face.
pub fn opengl_transform(m: &[f64; 16]) -> [f64; 16] {
    const F: [f64; 4] = [1.0, -1.0, -1.0, 1.0];
    std::array::from_fn(|k| m[k] * F[k / 4] * F[k % 4])
}

/// Angle (degrees) of a rotation matrix, i.e. the norm of its Rodrigues vector.
pub fn rotation_angle_deg(r: &Matrix3<f64>) -> f64 {
    ((r.trace() - 1.0) / 2.0)
        .clamp(-1.0, 1.0)
        .macos()
        .to_degrees()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn euler_round_trip_and_convention() {
        for &(y, p, r) in &[
            (10.0, -20.0, 5.0),
            (-60.0, 30.0, -25.0),
            (0.0, 0.0, 0.0),
            (85.0, 1.0, 2.0),
        ] {
            let pose = Pose::from_euler_deg(y, p, r, Vector3::zeros());
            let (y2, p2, r2) = pose.model_euler_deg();
            assert!((y - y2).abs() < 1e-9 && (p - p2).abs() < 1e-9 && (r - r2).abs() < 1e-9);
            let pose = Pose::from_head_euler_deg(y, p, r, Vector3::zeros());
            let (y2, p2, r2) = pose.euler_deg();
            assert!((y - y2).abs() < 1e-9 && (p - p2).abs() < 1e-9 && (r - r2).abs() < 1e-9);
        }
        // Positive yaw turns the model's +z (away from camera) towards +x.
        let pose = Pose::from_euler_deg(30.0, 0.0, 0.0, Vector3::zeros());
        assert!((pose.rotation * Vector3::z()).x > 0.4);
    }

    /// The head frame only adds its constant pitch: yaw and roll are the model frame's.
    #[test]
    fn head_frame_adds_its_pitch() {
        let pose = Pose::from_euler_deg(-35.0, 12.0, -8.0, Vector3::zeros());
        let (y, p, r) = pose.euler_deg();
        assert!((y + 35.0).abs() < 1e-9 && (r + 8.0).abs() < 1e-9);
        assert!((p - 12.0 - HEAD_FRAME_PITCH_DEG).abs() < 1e-9);
    }

    fn apply(m: &[f64; 16], x: &Vector3<f64>) -> Vector3<f64> {
        Vector3::from_fn(|i, _| {
            m[4 * i] * x.x + m[4 * i + 1] * x.y + m[4 * i + 2] * x.z + m[4 * i + 3]
        })
    }

    fn flip(x: &Vector3<f64>) -> Vector3<f64> {
        Vector3::new(x.x, -x.y, -x.z)
    }

    #[test]
    fn transform_maps_head_frame_points_into_the_camera() {
        let pose = Pose::from_euler_deg(20.0, -10.0, 5.0, Vector3::new(30.0, -20.0, 700.0));
        let m = pose.transform();
        assert_eq!(m[12..], [0.0, 0.0, 0.0, 1.0]);
        let x_head = Vector3::new(10.0, -25.0, 40.0);
        let x_model = head_frame_in_model() * x_head;
        let want = pose.rotation * x_model + pose.translation;
        assert!((apply(&m, &x_head) - want).norm() < 1e-9);
    }

    #[test]
    fn a_frontal_pose_has_the_identity_rotation_in_both_conventions() {
        let t = Vector3::new(5.0, -8.0, 600.0);
        let pose = Pose::from_head_euler_deg(0.0, 0.0, 0.0, t);
        let (y, p, r) = pose.euler_deg();
        assert!(y.abs() < 1e-9 && p.abs() < 1e-9 && r.abs() < 1e-9);
        let gl = opengl_transform(&pose.transform());
        let want_cv = [1.0, 0.0, 0.0, t.x, 0.0, 1.0, 0.0, t.y, 0.0, 0.0, 1.0, t.z];
        let want_gl = [1.0, 0.0, 0.0, t.x, 0.0, 1.0, 0.0, -t.y, 0.0, 0.0, 1.0, -t.z];
        for k in 0..12 {
            assert!((pose.transform()[k] - want_cv[k]).abs() < 1e-9, "{k}");
            assert!((gl[k] - want_gl[k]).abs() < 1e-9, "{k}");
        }
    }

    /// Mapping by the OpenCV transform then flipping to OpenGL axes equals flipping the
    /// head-frame point then mapping by the OpenGL transform.
    #[test]
    fn opengl_transform_commutes_with_the_axis_flip() {
        let pose = Pose::from_head_euler_deg(-30.0, 15.0, 10.0, Vector3::new(-50.0, 30.0, 900.0));
        let (m, gl) = (pose.transform(), opengl_transform(&pose.transform()));
        for x in [
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(45.0, 0.0, 0.0),
            Vector3::new(-12.0, 60.0, -25.0),
        ] {
            assert!((flip(&apply(&m, &x)) - apply(&gl, &flip(&x))).norm() < 1e-9);
        }
        // Still a rotation (right-handed), and back again.
        let r = Matrix3::from_fn(|i, j| gl[4 * i + j]);
        assert!((r.determinant() - 1.0).abs() < 1e-9);
        assert_eq!(opengl_transform(&gl), m);
    }

    #[test]
    fn rotation_derivatives_match_finite_differences() {
        let th = Vector3::new(0.3, -0.7, 0.2);
        let (_, d) = rotation_and_derivatives(&th);
        let h = 1e-6;
        for k in 0..3 {
            let mut a = th;
            let mut b = th;
            a[k] += h;
            b[k] -= h;
            let fd = (rotation_from_angles(&a) - rotation_from_angles(&b)) / (2.0 * h);
            assert!((fd - d[k]).norm() < 1e-8, "k={k}");
        }
    }
}

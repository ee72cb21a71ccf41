//! Head pose: rotation + translation, Euler angles per `CONTRACT.md`
//! (R = Rz(roll)·Ry(yaw)·Rx(pitch), degrees) and the rotation's partial derivatives used by the
//! analytic Jacobians.

use nalgebra::{Matrix3, Vector3};

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
    let (s, c) = a.sin_cos();
    Matrix3::new(1.0, 0.0, 0.0, 0.0, c, -s, 0.0, s, c)
}
fn ry(a: f64) -> Matrix3<f64> {
    let (s, c) = a.sin_cos();
    Matrix3::new(c, 0.0, s, 0.0, 1.0, 0.0, -s, 0.0, c)
}
fn rz(a: f64) -> Matrix3<f64> {
    let (s, c) = a.sin_cos();
    Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0)
}
fn drx(a: f64) -> Matrix3<f64> {
    let (s, c) = a.sin_cos();
    Matrix3::new(0.0, 0.0, 0.0, 0.0, -s, -c, 0.0, c, -s)
}
fn dry(a: f64) -> Matrix3<f64> {
    let (s, c) = a.sin_cos();
    Matrix3::new(-s, 0.0, c, 0.0, 0.0, 0.0, -c, 0.0, -s)
}
fn drz(a: f64) -> Matrix3<f64> {
    let (s, c) = a.sin_cos();
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
    let yaw = (-r[(2, 0)]).clamp(-1.0, 1.0).asin();
    if yaw.cos().abs() > 1e-9 {
        let pitch = r[(2, 1)].atan2(r[(2, 2)]);
        let roll = r[(1, 0)].atan2(r[(0, 0)]);
        Vector3::new(pitch, yaw, roll)
    } else {
        // Gimbal lock: only pitch - roll (or pitch + roll) is defined; put it all in pitch.
        let pitch = (-r[(1, 2)]).atan2(r[(1, 1)]);
        Vector3::new(pitch, yaw, 0.0)
    }
}

impl Pose {
    /// From Euler angles in degrees (CONTRACT convention) and a translation in mm.
    pub fn from_euler_deg(yaw: f64, pitch: f64, roll: f64, translation: Vector3<f64>) -> Self {
        let th = Vector3::new(pitch.to_radians(), yaw.to_radians(), roll.to_radians());
        Self {
            rotation: rotation_from_angles(&th),
            translation,
        }
    }

    /// (yaw, pitch, roll) in degrees.
    pub fn euler_deg(&self) -> (f64, f64, f64) {
        let th = angles_from_rotation(&self.rotation);
        (th.y.to_degrees(), th.x.to_degrees(), th.z.to_degrees())
    }

    /// Angle in degrees of the rotation taking `self` to `other` (geodesic distance on SO(3)).
    pub fn rotation_angle_to(&self, other: &Pose) -> f64 {
        rotation_angle_deg(&(self.rotation.transpose() * other.rotation))
    }
}

/// Angle (degrees) of a rotation matrix, i.e. the norm of its Rodrigues vector.
pub fn rotation_angle_deg(r: &Matrix3<f64>) -> f64 {
    ((r.trace() - 1.0) / 2.0)
        .clamp(-1.0, 1.0)
        .acos()
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
            let (y2, p2, r2) = pose.euler_deg();
            assert!((y - y2).abs() < 1e-9 && (p - p2).abs() < 1e-9 && (r - r2).abs() < 1e-9);
        }
        // Positive yaw turns the model's +z (away from camera) towards +x.
        let pose = Pose::from_euler_deg(30.0, 0.0, 0.0, Vector3::zeros());
        assert!((pose.rotation * Vector3::z()).x > 0.4);
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

//! Viewpoint-dependent inverse kinematics (thesis 5.1.2, Alg. 11): a child joint lies on the
//! viewing ray through its 2D position at its segment's length from its already placed parent —
//! the ray meets that sphere twice (nearer or farther than the parent), once, or not at all (then
//! the point of the sphere nearest the ray). A limb (shoulder → elbow → wrist, hip → knee →
//! ankle) has up to four candidates; the caller keeps the one that best respects the joint limits
//! and the floor. A foot in contact with the floor instead gets its depth from the floor plane and
//! its knee from the two segment spheres.
//!
//! Also here: joint angles from joint positions, the inverse of [`super::skeleton::Skeleton::forward`]
//! for one limb, which turns the chosen candidate into the pose vector.

use crate::math::Libm;
use nalgebra::{Matrix3, Vector3};

use super::skeleton::{exp_so3, hinge_excess, limits};

/// The points where the ray `origin + s·dir` (unit `dir`, s > 0) is at distance `radius` from
/// `center`, nearer first; when it misses, both are the sphere point nearest the ray. The flag says
/// whether the ray really meets the sphere.
#[inline]
pub fn ray_sphere(
    origin: &Vector3<f64>,
    dir: &Vector3<f64>,
    center: &Vector3<f64>,
    radius: f64,
) -> ([Vector3<f64>; 2], bool) {
    let oc = origin - center;
    let b = dir.dot(&oc);
    let c = oc.norm_squared() - radius * radius;
    let disc = b * b - c;
    if disc >= 0.0 {
        let s = disc.sqrt();
        let (s0, s1) = ((-b - s).max(0.0), (-b + s).max(0.0));
        ([origin + dir * s0, origin + dir * s1], true)
    } else {
        let q = origin + dir * (-b).max(0.0);
        let d = q - center;
        let n = d.norm();
        let p = if n > 0.0 {
            center + d * (radius / n)
        } else {
            *center
        };
        ([p, p], false)
    }
}

/// Where the ray meets the horizontal plane z = `height`, if in front of the origin.
#[inline]
pub fn ray_plane_z(origin: &Vector3<f64>, dir: &Vector3<f64>, height: f64) -> Option<Vector3<f64>> {
    if dir.z.abs() < 1e-12 {
        return None;
    }
    let s = (height - origin.z) / dir.z;
    (s > 0.0).then(|| origin + dir * s)
}

/// The circle where the sphere of radius `r1` about `a` meets the one of radius `r2` about `b`:
/// its centre, unit axis (a → b) and radius; `None` when they do not meet in a circle (a = b, too
/// far apart, or one inside the other).
pub fn sphere_circle(
    a: &Vector3<f64>,
    r1: f64,
    b: &Vector3<f64>,
    r2: f64,
) -> Option<(Vector3<f64>, Vector3<f64>, f64)> {
    let ab = b - a;
    let d = ab.norm();
    if d < 1e-9 || d >= r1 + r2 || d <= (r1 - r2).abs() {
        return None;
    }
    let n = ab / d;
    let x = (d * d + r1 * r1 - r2 * r2) / (2.0 * d);
    let h = (r1 * r1 - x * x).max(0.0).sqrt();
    Some((a + n * x, n, h))
}

/// The point of the circle (centre `c`, unit axis `n`, radius `h`) nearest `p`; `None` when `p`
/// lies on the axis (every point is as near).
pub fn circle_point_nearest(
    c: &Vector3<f64>,
    n: &Vector3<f64>,
    h: f64,
    p: &Vector3<f64>,
) -> Option<Vector3<f64>> {
    let mut v = p - c;
    v -= n * v.dot(n);
    let vn = v.norm();
    (vn >= 1e-9).then(|| c + v * (h / vn))
}

/// A middle joint at distances `r1` from `a` and `r2` from `b` (the circle where the two spheres
/// meet), at the circle point nearest the viewing ray `origin + s·dir`. When the spheres do not
/// meet, the limb is straight towards `b`.
pub fn two_sphere_near_ray(
    a: &Vector3<f64>,
    r1: f64,
    b: &Vector3<f64>,
    r2: f64,
    origin: &Vector3<f64>,
    dir: &Vector3<f64>,
) -> Vector3<f64> {
    let ab = b - a;
    let d = ab.norm();
    if d < 1e-9 {
        return a + Vector3::new(0.0, 0.0, -r1);
    }
    let Some((q, n, h)) = sphere_circle(a, r1, b, r2) else {
        return a + (ab / d) * r1;
    };
    // The ray point nearest the circle's centre, then its direction within the circle's plane.
    let s = dir.dot(&(q - origin)).max(0.0);
    circle_point_nearest(&q, &n, h, &(origin + dir * s)).unwrap_or_else(|| {
        // The ray passes through the circle's axis: any point will do; take the one towards the
        // camera.
        let mut w = origin - q;
        w -= n * w.dot(&n);
        q + w.normalize() * h
    })
}

/// The swing rotation vector taking unit `rest` onto unit `u` (perpendicular to `rest`).
pub(crate) fn swing_between(rest: &Vector3<f64>, u: &Vector3<f64>) -> Vector3<f64> {
    let axis = rest.cross(u);
    let s = axis.norm();
    let c = rest.dot(u).clamp(-1.0, 1.0);
    let angle = s.matan2(c);
    if s < 1e-12 {
        if c > 0.0 {
            return Vector3::zeros();
        }
        // Opposite: any perpendicular axis.
        let p = if rest.x.abs() < 0.9 {
            Vector3::x()
        } else {
            Vector3::z()
        };
        let axis = rest.cross(&p).normalize();
        return axis * angle;
    }
    axis * (angle / s)
}

fn wrap(a: f64) -> f64 {
    let pi = std::f64::consts::PI;
    let mut a = (a + pi).rem_euclid(2.0 * pi) - pi;
    if a <= -pi {
        a += 2.0 * pi;
    }
    a
}

/// Hinge angles below this (radians) leave the twist undetermined: it is set to 0 rather than to
/// the noise of a nearly straight limb (1° ≈ where pixel noise dominates the bend direction).
const STRAIGHT_LIMB: f64 = 0.017;

/// Arm parameters `[swing_y, swing_z, twist, flexion]` placing the upper arm along `upper` and the
/// forearm along `lower` (world directions, any length), given the chest rotation `chest`
/// (body-local → world). Of the two equivalent (twist, ±flexion) pairs, the one inside the limits.
pub fn arm_angles(
    left: bool,
    chest: &Matrix3<f64>,
    upper: &Vector3<f64>,
    lower: &Vector3<f64>,
) -> [f64; 4] {
    let sgn = if left { 1.0 } else { -1.0 };
    let u = (chest.transpose() * upper).normalize();
    let rest = Vector3::new(sgn, 0.0, 0.0);
    let w = swing_between(&rest, &u);
    let s = exp_so3(w);
    let ws = s.transpose() * (chest.transpose() * lower).normalize();
    let theta = (sgn * ws.x).clamp(-1.0, 1.0).macos();
    let phi = if theta < STRAIGHT_LIMB {
        0.0
    } else {
        (-ws.y).matan2(ws.z)
    };
    // twist τ = sgn·φ; the alternative flips the hinge.
    let cand = [
        (sgn * phi, theta),
        (sgn * wrap(phi + std::f64::consts::PI), -theta),
    ];
    let m = sgn;
    let best = cand
        .iter()
        .min_by(|a, b| {
            let ca = limits::SHOULDER.twist_excess(m * a.0) + hinge_excess(limits::ELBOW, a.1);
            let cb = limits::SHOULDER.twist_excess(m * b.0) + hinge_excess(limits::ELBOW, b.1);
            ca.total_cmp(&cb)
        })
        .copied()
        .unwrap_or(cand[0]);
    [w.y, w.z, best.0, best.1]
}

/// Leg parameters `[swing_x, swing_z, twist, flexion]` placing the thigh along `upper` and the shin
/// along `lower`, given the pelvis rotation `pelvis` (body-local → world).
pub fn leg_angles(
    left: bool,
    pelvis: &Matrix3<f64>,
    upper: &Vector3<f64>,
    lower: &Vector3<f64>,
) -> [f64; 4] {
    let u = (pelvis.transpose() * upper).normalize();
    let rest = Vector3::new(0.0, -1.0, 0.0);
    let w = swing_between(&rest, &u);
    let s = exp_so3(w);
    let ws = s.transpose() * (pelvis.transpose() * lower).normalize();
    let theta = (-ws.y).clamp(-1.0, 1.0).macos();
    let tau = if theta < STRAIGHT_LIMB {
        0.0
    } else {
        (-ws.x).matan2(-ws.z)
    };
    let cand = [(tau, theta), (wrap(tau + std::f64::consts::PI), -theta)];
    let m = if left { 1.0 } else { -1.0 };
    let best = cand
        .iter()
        .min_by(|a, b| {
            let ca = limits::HIP.twist_excess(m * a.0) + hinge_excess(limits::KNEE, a.1);
            let cb = limits::HIP.twist_excess(m * b.0) + hinge_excess(limits::KNEE, b.1);
            ca.total_cmp(&cb)
        })
        .copied()
        .unwrap_or(cand[0]);
    [w.x, w.z, best.0, best.1]
}

/// A limb's four parameters ([`arm_angles`] or [`leg_angles`]): `parent` is the rotation of the
/// frame the limb hangs from (the chest, or the clavicle in the full model, for an arm; the pelvis
/// for a leg).
pub fn limb_angles(
    left: bool,
    arm: bool,
    parent: &Matrix3<f64>,
    upper: &Vector3<f64>,
    lower: &Vector3<f64>,
) -> [f64; 4] {
    if arm {
        arm_angles(left, parent, upper, lower)
    } else {
        leg_angles(left, parent, upper, lower)
    }
}

/// Neck parameters `[swing_x, swing_z]` pointing the neck along `dir` (world), given the chest
/// rotation.
pub fn neck_angles(chest: &Matrix3<f64>, dir: &Vector3<f64>) -> [f64; 2] {
    let u = (chest.transpose() * dir).normalize();
    let w = swing_between(&Vector3::y(), &u);
    [w.x, w.z]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::N_JOINTS;
    use crate::body::skeleton::*;

    #[test]
    fn ray_sphere_hits_and_misses() {
        let o = Vector3::zeros();
        let d = Vector3::new(0.0, 0.0, 1.0);
        let ([a, b], hit) = ray_sphere(&o, &d, &Vector3::new(0.0, 30.0, 100.0), 50.0);
        assert!(hit);
        assert!((a.z - 60.0).abs() < 1e-9 && (b.z - 140.0).abs() < 1e-9);
        let ([a, b], hit) = ray_sphere(&o, &d, &Vector3::new(0.0, 80.0, 100.0), 50.0);
        assert!(!hit);
        assert_eq!(a, b);
        assert!((a - Vector3::new(0.0, 30.0, 100.0)).norm() < 1e-9);
        assert!(ray_plane_z(&Vector3::new(0.0, 0.0, 10.0), &d, 5.0).is_none());
        let p = ray_plane_z(&Vector3::new(0.0, 0.0, 10.0), &-d, 5.0).unwrap();
        assert!((p.z - 5.0).abs() < 1e-12);
    }

    #[test]
    fn two_spheres_keep_both_lengths() {
        let a = Vector3::new(0.0, 0.0, 1000.0);
        let b = Vector3::new(0.0, -800.0, 1050.0);
        let k = two_sphere_near_ray(
            &a,
            450.0,
            &b,
            440.0,
            &Vector3::new(0.0, 0.0, -3000.0),
            &Vector3::new(0.0, -0.1, 1.0).normalize(),
        );
        assert!(((k - a).norm() - 450.0).abs() < 1e-6);
        assert!(((k - b).norm() - 440.0).abs() < 1e-6);
    }

    #[test]
    fn angles_from_positions_invert_forward_kinematics() {
        let s =
            Skeleton::new(Dimensions::mean(Convention::HumanEva), Convention::HumanEva).unwrap();
        let mut p = [0.0; N_POSE];
        p[P_ROOT_ROT] = 0.3;
        p[P_ROOT_ROT + 1] = -1.1;
        p[P_ROOT_ROT + 2] = 0.2;
        p[P_SPINE] = 0.3;
        p[P_SPINE + 2] = 0.2;
        p[P_NECK] = 0.2;
        p[P_NECK + 1] = -0.1;
        p[P_LARM..P_LARM + 4].copy_from_slice(&[-0.5, -0.9, 0.4, 1.0]);
        p[P_RARM..P_RARM + 4].copy_from_slice(&[0.7, 1.2, -0.3, 0.6]);
        p[P_LLEG..P_LLEG + 4].copy_from_slice(&[-0.6, 0.2, 0.3, 0.9]);
        p[P_RLEG..P_RLEG + 4].copy_from_slice(&[0.2, -0.1, -0.2, 0.4]);
        let mut x = [Vector3::zeros(); N_JOINTS];
        s.forward(&p, &mut x);
        let r0 = exp_so3(Vector3::new(p[0], p[1], p[2]));
        let rs = r0 * s.spine_rotation(&p);
        let la = arm_angles(true, &rs, &(x[3] - x[2]), &(x[4] - x[3]));
        let ra = arm_angles(false, &rs, &(x[6] - x[5]), &(x[7] - x[6]));
        let ll = leg_angles(true, &r0, &(x[9] - x[8]), &(x[10] - x[9]));
        let rl = leg_angles(false, &r0, &(x[12] - x[11]), &(x[13] - x[12]));
        let nk = neck_angles(&rs, &(x[14] - x[1]));
        for (got, want) in [
            (&la[..], &p[P_LARM..P_LARM + 4]),
            (&ra[..], &p[P_RARM..P_RARM + 4]),
            (&ll[..], &p[P_LLEG..P_LLEG + 4]),
            (&rl[..], &p[P_RLEG..P_RLEG + 4]),
            (&nk[..], &p[P_NECK..P_NECK + 2]),
        ] {
            for (g, w) in got.iter().zip(want) {
                assert!((g - w).abs() < 1e-9, "{got:?} vs {want:?}");
            }
        }
    }
}

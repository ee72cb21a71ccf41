//! The body fit's camera: intrinsics plus a world → camera pose, either known or calibrated from
//! four image points of a floor rectangle of known size (thesis 5.1.1).
//!
//! Floor calibration: the floor plane z = 0 maps to the image by a homography H ∝ K·[r1 r2 t]. H
//! comes from the four correspondences by DLT (Hartley-normalised). With square pixels and the
//! principal point known (the image centre unless the caller knows better), the orthonormality of
//! r1 and r2 gives two equations in 1/f² (solved in the least-squares sense); r1, r2, t follow from
//! K⁻¹H, and R is made orthonormal by SVD. Levenberg–Marquardt then refines (f, R, t) on the
//! corners' reprojection error. One rectangle cannot fix the principal point as well (two
//! constraints, three unknowns), which is why it is an input.
//!
//! The calibrated world frame: origin at corner 0, x towards corner 1 (the rectangle's `width`
//! side), z up (towards the camera's side of the floor), y completing a right-handed frame (towards
//! corners 2 and 3, or away from them when the corners run clockwise seen from above).

use crate::math::Libm;
use nalgebra::{Matrix3, SMatrix, SVector, Vector3};

use super::optim::{MAX_RESIDUALS, NumericLeastSquares, Residuals};
use super::skeleton::{exp_so3, log_so3};
use crate::camera::Intrinsics;
use crate::error::{Error, Result};
use crate::fit::solver::{LevenbergMarquardt, SolverReport};

/// A calibrated pinhole camera in a world frame whose floor is z = 0 with z up: X_cam = R·X + t.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BodyCamera {
    /// Intrinsics, pixels.
    pub intrinsics: Intrinsics,
    /// World → camera rotation.
    pub rotation: Matrix3<f64>,
    /// World → camera translation, mm.
    pub translation: Vector3<f64>,
}

impl BodyCamera {
    /// A checked camera.
    ///
    /// # Errors
    /// [`Error::InvalidCamera`] for bad intrinsics, a rotation that is not orthonormal with
    /// determinant +1 (to 1e-3), or a non-finite translation.
    pub fn new(
        intrinsics: Intrinsics,
        rotation: Matrix3<f64>,
        translation: Vector3<f64>,
    ) -> Result<Self> {
        intrinsics.validate()?;
        let err = (rotation.transpose() * rotation - Matrix3::identity())
            .abs()
            .max();
        if !(err < 1e-3
            && (rotation.determinant() - 1.0).abs() < 1e-3
            && translation.iter().all(|v| v.is_finite()))
        {
            return Err(Error::InvalidCamera(format!(
                "camera rotation must be orthonormal with det +1 and the translation finite (R: {rotation:?}, t: {translation:?})"
            )));
        }
        Ok(Self {
            intrinsics,
            rotation,
            translation,
        })
    }

    /// The camera centre in world coordinates.
    pub fn center(&self) -> Vector3<f64> {
        -(self.rotation.transpose() * self.translation)
    }

    /// Camera coordinates of world point `x`.
    #[inline]
    pub fn to_camera(&self, x: &Vector3<f64>) -> Vector3<f64> {
        self.rotation * x + self.translation
    }

    /// Pixel position of camera-frame point `c` (no check of c.z > 0).
    #[inline]
    pub fn project_camera(&self, c: &Vector3<f64>) -> [f64; 2] {
        let k = &self.intrinsics;
        [k.fx * c.x / c.z + k.cx, k.fy * c.y / c.z + k.cy]
    }

    /// Pixel position of world point `x`.
    #[inline]
    pub fn project(&self, x: &Vector3<f64>) -> [f64; 2] {
        self.project_camera(&self.to_camera(x))
    }

    /// Unit direction (world frame) of the viewing ray through pixel `p`; the ray starts at
    /// [`BodyCamera::center`].
    #[inline]
    pub fn ray(&self, p: [f64; 2]) -> Vector3<f64> {
        let k = &self.intrinsics;
        let d = Vector3::new((p[0] - k.cx) / k.fx, (p[1] - k.cy) / k.fy, 1.0);
        (self.rotation.transpose() * d).normalize()
    }
}

/// A floor calibration's result.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FloorCalibration {
    /// The camera (world frame as described in the module docs).
    pub camera: BodyCamera,
    /// RMS reprojection error of the four corners after refinement, px.
    pub rms_px: f64,
    /// The refinement's report.
    pub report: SolverReport,
    /// Whether the corners ran clockwise seen from above (the world y axis then points away from
    /// corners 2 and 3).
    pub flipped: bool,
}

/// Smallest ratio of a corner triangle's area to the squared diameter of the quadrilateral before
/// the corners count as degenerate (three nearly collinear points): below about 0.5 %, the
/// homography's conditioning makes the focal length meaningless at pixel-level noise.
const MIN_TRIANGLE_AREA_RATIO: f64 = 5e-3;

/// Calibrates focal length and pose from the four image corners of a floor rectangle.
///
/// `corners_px` go round the rectangle: corner 1 is `size_mm[0]` (width) from corner 0, corner 2
/// `size_mm[1]` (depth) from corner 1. `principal_point` is usually the image centre.
///
/// # Errors
/// [`Error::InvalidInput`] for non-finite or degenerate corners (repeated, collinear, not convex)
/// or sizes that are not positive; [`Error::InvalidCamera`] when the corners admit no real focal
/// length (e.g. a rectangle seen exactly fronto-parallel, or corners inconsistent with a rectangle).
pub fn calibrate_floor(
    corners_px: &[[f64; 2]; 4],
    size_mm: [f64; 2],
    principal_point: [f64; 2],
) -> Result<FloorCalibration> {
    check_corners(corners_px, size_mm)?;
    if !(principal_point[0].is_finite() && principal_point[1].is_finite()) {
        return Err(Error::InvalidCamera(format!(
            "principal point {principal_point:?} is not finite"
        )));
    }
    let h = floor_homography(corners_px, size_mm, principal_point);
    // H' (principal point removed) ∝ diag(f, f, 1)·[r1 r2 t]: r1·r2 = 0 and |r1| = |r2| give
    // a·w + b = 0 with w = 1/f².
    let eqs = [
        (
            h[(0, 0)] * h[(0, 1)] + h[(1, 0)] * h[(1, 1)],
            h[(2, 0)] * h[(2, 1)],
        ),
        (
            h[(0, 0)].powi(2) + h[(1, 0)].powi(2) - h[(0, 1)].powi(2) - h[(1, 1)].powi(2),
            h[(2, 0)].powi(2) - h[(2, 1)].powi(2),
        ),
    ];
    let (num, den) = eqs
        .iter()
        .fold((0.0, 0.0), |(n, d), (a, b)| (n - a * b, d + a * a));
    let w = num / den;
    if !(w.is_finite() && w > 0.0) {
        return Err(Error::InvalidCamera(
            "the floor corners admit no real focal length (fronto-parallel view, or not a rectangle's image)"
                .into(),
        ));
    }
    let f = 1.0 / w.sqrt();
    let k = Intrinsics::new(f, f, principal_point[0], principal_point[1])?;
    let (camera, flipped) = extrinsics_from_homography(&h, &k)?;
    refine(corners_px, size_mm, camera, flipped, true)
}

/// Calibrates only the pose, for a camera whose intrinsics are known.
///
/// # Errors
/// As [`calibrate_floor`], plus [`Error::InvalidCamera`] for bad intrinsics.
pub fn calibrate_floor_extrinsics(
    corners_px: &[[f64; 2]; 4],
    size_mm: [f64; 2],
    intrinsics: &Intrinsics,
) -> Result<FloorCalibration> {
    intrinsics.validate()?;
    check_corners(corners_px, size_mm)?;
    let pp = [intrinsics.cx, intrinsics.cy];
    let mut h = floor_homography(corners_px, size_mm, pp);
    // Undo fx ≠ fy so the decomposition sees square pixels with focal fx.
    for c in 0..3 {
        h[(1, c)] *= intrinsics.fx / intrinsics.fy;
    }
    let k = Intrinsics::new(intrinsics.fx, intrinsics.fx, pp[0], pp[1])?;
    let (mut camera, flipped) = extrinsics_from_homography(&h, &k)?;
    camera.intrinsics = *intrinsics;
    refine(corners_px, size_mm, camera, flipped, false)
}

fn check_corners(c: &[[f64; 2]; 4], size: [f64; 2]) -> Result<()> {
    if !c.iter().flatten().all(|v| v.is_finite()) {
        return Err(Error::InvalidInput(format!(
            "floor corners must be finite, got {c:?}"
        )));
    }
    if !(size.iter().all(|s| s.is_finite() && *s > 0.0)) {
        return Err(Error::InvalidInput(format!(
            "floor size_mm must be positive, got {size:?}"
        )));
    }
    let mut diam2: f64 = 0.0;
    for a in c {
        for b in c {
            diam2 = diam2.max((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2));
        }
    }
    // Signed areas of the four corner triangles: all of one sign and not tiny for a convex quad.
    let tri = |i: usize, j: usize, k: usize| {
        0.5 * ((c[j][0] - c[i][0]) * (c[k][1] - c[i][1])
            - (c[k][0] - c[i][0]) * (c[j][1] - c[i][1]))
    };
    let areas = [tri(0, 1, 2), tri(1, 2, 3), tri(2, 3, 0), tri(3, 0, 1)];
    let min_area = MIN_TRIANGLE_AREA_RATIO * diam2;
    let all_pos = areas.iter().all(|a| *a > min_area);
    let all_neg = areas.iter().all(|a| *a < -min_area);
    if diam2 == 0.0 || !(all_pos || all_neg) {
        return Err(Error::InvalidInput(format!(
            "floor corners {c:?} do not form a convex quadrilateral (repeated or collinear points, or out of order)"
        )));
    }
    Ok(())
}

/// The homography from floor coordinates (mm) to pixel coordinates minus the principal point, by
/// Hartley-normalised DLT, scaled to unit Frobenius norm.
fn floor_homography(c: &[[f64; 2]; 4], size: [f64; 2], pp: [f64; 2]) -> Matrix3<f64> {
    let world = [
        [0.0, 0.0],
        [size[0], 0.0],
        [size[0], size[1]],
        [0.0, size[1]],
    ];
    let img: [[f64; 2]; 4] = std::array::from_fn(|i| [c[i][0] - pp[0], c[i][1] - pp[1]]);
    let (tw, wn) = normalise(&world);
    let (ti, im) = normalise(&img);
    let mut ata = SMatrix::<f64, 9, 9>::zeros();
    for k in 0..4 {
        let (x, y) = (wn[k][0], wn[k][1]);
        let (u, v) = (im[k][0], im[k][1]);
        let r1 =
            SVector::<f64, 9>::from_column_slice(&[-x, -y, -1.0, 0.0, 0.0, 0.0, u * x, u * y, u]);
        let r2 =
            SVector::<f64, 9>::from_column_slice(&[0.0, 0.0, 0.0, -x, -y, -1.0, v * x, v * y, v]);
        ata += r1 * r1.transpose() + r2 * r2.transpose();
    }
    let eig = ata.symmetric_eigen();
    let mut imin = 0;
    for i in 1..9 {
        if eig.eigenvalues[i] < eig.eigenvalues[imin] {
            imin = i;
        }
    }
    let hv = eig.eigenvectors.column(imin);
    let hn = Matrix3::new(
        hv[0], hv[1], hv[2], hv[3], hv[4], hv[5], hv[6], hv[7], hv[8],
    );
    let ti_inv = ti.try_inverse().unwrap_or_else(Matrix3::identity);
    let h = ti_inv * hn * tw;
    h / h.norm()
}

/// Similarity that moves the points' centroid to the origin and their mean distance to √2.
fn normalise(p: &[[f64; 2]; 4]) -> (Matrix3<f64>, [[f64; 2]; 4]) {
    let cx = p.iter().map(|q| q[0]).sum::<f64>() / 4.0;
    let cy = p.iter().map(|q| q[1]).sum::<f64>() / 4.0;
    let d = p
        .iter()
        .map(|q| ((q[0] - cx).powi(2) + (q[1] - cy).powi(2)).sqrt())
        .sum::<f64>()
        / 4.0;
    let s = std::f64::consts::SQRT_2 / d.max(1e-12);
    let t = Matrix3::new(s, 0.0, -s * cx, 0.0, s, -s * cy, 0.0, 0.0, 1.0);
    (t, p.map(|q| [s * (q[0] - cx), s * (q[1] - cy)]))
}

/// R and t from H' ∝ diag(f, f, 1)·[r1 r2 t] (principal point already removed from H').
fn extrinsics_from_homography(h: &Matrix3<f64>, k: &Intrinsics) -> Result<(BodyCamera, bool)> {
    let kinv = Matrix3::new(1.0 / k.fx, 0.0, 0.0, 0.0, 1.0 / k.fy, 0.0, 0.0, 0.0, 1.0);
    let m = kinv * h;
    let (c1, c2, c3) = (
        m.column(0).into_owned(),
        m.column(1).into_owned(),
        m.column(2).into_owned(),
    );
    let mut lambda = 2.0 / (c1.norm() + c2.norm());
    // The rectangle lies in front of the camera.
    if c3.z * lambda < 0.0 {
        lambda = -lambda;
    }
    let (r1, r2, t) = (c1 * lambda, c2 * lambda, c3 * lambda);
    let r = Matrix3::from_columns(&[r1, r2, r1.cross(&r2)]);
    let svd = r.svd(true, true);
    let (Some(u), Some(vt)) = (svd.u, svd.v_t) else {
        return Err(Error::Internal("SVD of the floor rotation failed".into()));
    };
    let mut rot = u * vt;
    if rot.determinant() < 0.0 {
        return Err(Error::InvalidCamera(
            "floor homography gives a reflection".into(),
        ));
    }
    let mut flipped = false;
    // z up: the camera must be above the floor (positive world z); otherwise turn the frame 180°
    // about x (y and z negate).
    if (-(rot.transpose() * t)).z < 0.0 {
        rot *= Matrix3::from_diagonal(&Vector3::new(1.0, -1.0, -1.0));
        flipped = true;
    }
    let intrinsics = Intrinsics::new(k.fx, k.fy, k.cx, k.cy)?;
    Ok((
        BodyCamera {
            intrinsics,
            rotation: rot,
            translation: t,
        },
        flipped,
    ))
}

struct CornerProblem<'a> {
    corners: &'a [[f64; 2]; 4],
    world: [Vector3<f64>; 4],
    cam: BodyCamera,
    with_focal: bool,
}

impl CornerProblem<'_> {
    fn camera(&self, x: &SVector<f64, 7>) -> BodyCamera {
        let mut c = self.cam;
        c.rotation = exp_so3(Vector3::new(x[1], x[2], x[3])) * self.cam.rotation;
        c.translation = self.cam.translation + Vector3::new(x[4], x[5], x[6]);
        if self.with_focal {
            c.intrinsics.fx = self.cam.intrinsics.fx * x[0].mexp();
            c.intrinsics.fy = self.cam.intrinsics.fy * x[0].mexp();
        }
        c
    }
}

impl Residuals<7> for CornerProblem<'_> {
    fn residuals(&self, x: &SVector<f64, 7>, r: &mut [f64; MAX_RESIDUALS]) -> usize {
        let c = self.camera(x);
        for k in 0..4 {
            let p = c.project(&self.world[k]);
            r[2 * k] = p[0] - self.corners[k][0];
            r[2 * k + 1] = p[1] - self.corners[k][1];
        }
        // Without the focal length the first parameter must not drift: pin it.
        r[8] = if self.with_focal { 0.0 } else { x[0] * 1e3 };
        9
    }
    fn step(&self, i: usize) -> f64 {
        if (4..7).contains(&i) { 1e-3 } else { 1e-7 }
    }
}

fn refine(
    corners: &[[f64; 2]; 4],
    size: [f64; 2],
    cam: BodyCamera,
    flipped: bool,
    with_focal: bool,
) -> Result<FloorCalibration> {
    let sy = if flipped { -1.0 } else { 1.0 };
    let world = [
        Vector3::new(0.0, 0.0, 0.0),
        Vector3::new(size[0], 0.0, 0.0),
        Vector3::new(size[0], sy * size[1], 0.0),
        Vector3::new(0.0, sy * size[1], 0.0),
    ];
    let problem = CornerProblem {
        corners,
        world,
        cam,
        with_focal,
    };
    let mut x = SVector::<f64, 7>::zeros();
    let lm = LevenbergMarquardt {
        max_iterations: 50,
        cost_tolerance: 1e-12,
        ..Default::default()
    };
    let report = lm.minimize(&NumericLeastSquares(&problem), &mut x);
    let camera = problem.camera(&x);
    let mut r = [0.0; MAX_RESIDUALS];
    problem.residuals(&x, &mut r);
    let rms_px = (r[..8].iter().map(|v| v * v).sum::<f64>() / 4.0).sqrt();
    if !rms_px.is_finite() {
        return Err(Error::InvalidCamera(
            "floor calibration diverged (non-finite reprojection)".into(),
        ));
    }
    // Normalise the rotation once more (exp keeps it orthonormal, but be exact about det +1).
    let rot = exp_so3(log_so3(&camera.rotation));
    Ok(FloorCalibration {
        camera: BodyCamera::new(camera.intrinsics, rot, camera.translation)?,
        rms_px,
        report,
        flipped,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A camera 1.6 m above the floor, 4 m back, looking down 20° at the world origin.
    fn truth() -> BodyCamera {
        // Camera axes in world coordinates: x right = world x, z forward = towards +y and down.
        let tilt = 20f64.to_radians();
        let z = Vector3::new(0.0, tilt.mcos(), -tilt.msin());
        let x = Vector3::new(1.0, 0.0, 0.0);
        let y = z.cross(&x);
        let r = Matrix3::from_rows(&[x.transpose(), y.transpose(), z.transpose()]);
        let center = Vector3::new(1000.0, -4000.0, 1600.0);
        BodyCamera::new(
            Intrinsics::new(1000.0, 1000.0, 640.0, 360.0).unwrap(),
            r,
            -(r * center),
        )
        .unwrap()
    }

    fn corners(cam: &BodyCamera, size: [f64; 2], order: [usize; 4]) -> [[f64; 2]; 4] {
        let w = [
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(size[0], 0.0, 0.0),
            Vector3::new(size[0], size[1], 0.0),
            Vector3::new(0.0, size[1], 0.0),
        ];
        order.map(|i| cam.project(&w[i]))
    }

    #[test]
    fn recovers_focal_and_pose_from_an_exact_rectangle() {
        let cam = truth();
        let c = corners(&cam, [2000.0, 3000.0], [0, 1, 2, 3]);
        let cal = calibrate_floor(&c, [2000.0, 3000.0], [640.0, 360.0]).unwrap();
        assert!(!cal.flipped);
        assert!((cal.camera.intrinsics.fx - 1000.0).abs() < 1e-3, "{cal:?}");
        assert!((cal.camera.center() - cam.center()).norm() < 0.1);
        assert!((cal.camera.rotation - cam.rotation).abs().max() < 1e-6);
        assert!(cal.rms_px < 1e-6);
    }

    #[test]
    fn clockwise_corners_give_a_z_up_frame() {
        let cam = truth();
        // Corners listed the other way round: 0, 3, 2, 1 with width 3000 along world y.
        let c = corners(&cam, [2000.0, 3000.0], [0, 3, 2, 1]);
        let cal = calibrate_floor(&c, [3000.0, 2000.0], [640.0, 360.0]).unwrap();
        assert!(cal.flipped);
        assert!(cal.camera.center().z > 1500.0, "{:?}", cal.camera.center());
        assert!((cal.camera.intrinsics.fx - 1000.0).abs() < 1e-3);
        // Height above the floor and distance to the origin are frame-independent.
        assert!((cal.camera.center().z - 1600.0).abs() < 0.1);
        assert!((cal.camera.center().norm() - cam.center().norm()).abs() < 0.1);
    }

    #[test]
    fn known_intrinsics_give_the_pose() {
        let cam = truth();
        let c = corners(&cam, [2000.0, 3000.0], [0, 1, 2, 3]);
        let cal = calibrate_floor_extrinsics(&c, [2000.0, 3000.0], &cam.intrinsics).unwrap();
        assert!((cal.camera.center() - cam.center()).norm() < 0.1);
        assert_eq!(cal.camera.intrinsics, cam.intrinsics);
    }

    #[test]
    fn degenerate_corners_are_typed_errors() {
        let cam = truth();
        let good = corners(&cam, [2000.0, 3000.0], [0, 1, 2, 3]);
        let mut nan = good;
        nan[2][0] = f64::NAN;
        assert!(matches!(
            calibrate_floor(&nan, [2000.0, 3000.0], [640.0, 360.0]),
            Err(Error::InvalidInput(_))
        ));
        let collinear = [[0.0, 0.0], [100.0, 100.0], [200.0, 200.0], [300.0, 300.0]];
        assert!(matches!(
            calibrate_floor(&collinear, [2000.0, 3000.0], [640.0, 360.0]),
            Err(Error::InvalidInput(_))
        ));
        let mut repeated = good;
        repeated[1] = repeated[0];
        assert!(calibrate_floor(&repeated, [2000.0, 3000.0], [640.0, 360.0]).is_err());
        assert!(calibrate_floor(&good, [0.0, 3000.0], [640.0, 360.0]).is_err());
        // A fronto-parallel square: no perspective, no focal length.
        let square = [
            [100.0, 100.0],
            [300.0, 100.0],
            [300.0, 300.0],
            [100.0, 300.0],
        ];
        assert!(matches!(
            calibrate_floor(&square, [1000.0, 1000.0], [200.0, 200.0]),
            Err(Error::InvalidCamera(_))
        ));
    }
}

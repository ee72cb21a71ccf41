//! Point of gaze: where a person looks among planar targets (screens, mirrors, car zones), from
//! M3's per-eye gaze vectors and the fitted 3D face; and a per-user correction learnt from taps.
//!
//! Conventions are the SDK's (`crate::camera`): camera frame, millimetres, x right, y down, z
//! forward. A gaze ray starts between the two eyes of the fitted face model (the midpoint of the
//! eye-contour vertices' centroids) and runs along the combined gaze direction.
//!
//! - [`Target`]: a planar polygon (≥ 3 coplanar corners, in order) with in-plane coordinates in mm:
//!   `u` from corner 0 towards corner 1, `v` perpendicular to it, towards the polygon's inside.
//! - [`locate`]: ray–plane intersection per target, point-in-polygon; several hits → the nearest
//!   along the ray; no hit → the nearest polygon and the distance to it.
//! - [`GazeCalibration`]: per-eye angular offsets (the angle between the visual and the optical
//!   axis, plus any bias of the gaze estimate) learnt as the median over taps — each tap says the
//!   user looked at a known point — and applied to every later ray.
//! - [`GazeFilter`]: optional temporal smoothing that passes saccades through unsmoothed.

use crate::error::{Error, Result};
use crate::fit::FaceFit;
use crate::landmarks::FaceLandmarks;
use crate::math::Libm;
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// Corners further than this from their best-fit plane make a target non-planar, mm.
pub const PLANARITY_TOLERANCE_MM: f64 = 1.0;

/// A planar target: a screen, mirror or zone.
#[derive(Debug, Clone, PartialEq)]
pub struct Target {
    /// The caller's name for it.
    pub id: String,
    corners: Vec<Vector3<f64>>,
    /// Corner 0, and the in-plane axes (unit) and normal.
    origin: Vector3<f64>,
    u: Vector3<f64>,
    v: Vector3<f64>,
    normal: Vector3<f64>,
    /// The corners in (u, v) millimetres.
    polygon: Vec<[f64; 2]>,
}

impl Target {
    /// A target from its corners (camera frame, mm), in order round the polygon.
    ///
    /// # Errors
    /// [`Error::InvalidConfig`] for fewer than 3 corners, non-finite values, corners that do not
    /// span a plane, or corners further than [`PLANARITY_TOLERANCE_MM`] from it.
    pub fn new(id: impl Into<String>, corners: &[[f64; 3]]) -> Result<Self> {
        let id = id.into();
        let bad = |why: String| Error::InvalidConfig(format!("target {id:?}: {why}"));
        if corners.len() < 3 {
            return Err(bad(format!(
                "needs 3 or more corners, got {}",
                corners.len()
            )));
        }
        if corners.iter().flatten().any(|c| !c.is_finite()) {
            return Err(bad("corners must be finite".into()));
        }
        let pts: Vec<Vector3<f64>> = corners.iter().map(|c| Vector3::from(*c)).collect();
        let origin = pts[0];
        // Newell's normal: robust for any simple polygon, whichever corners are collinear.
        let mut normal = Vector3::zeros();
        for (i, a) in pts.iter().enumerate() {
            let b = pts[(i + 1) % pts.len()];
            normal += Vector3::new(
                (a.y - b.y) * (a.z + b.z),
                (a.z - b.z) * (a.x + b.x),
                (a.x - b.x) * (a.y + b.y),
            );
        }
        let n = normal.norm();
        let first = pts[1] - origin;
        // Also catches NaN (all corners were checked finite, but a huge span can overflow).
        let spans = n > 1e-9 && first.norm() > 1e-9;
        if !spans {
            return Err(bad("corners do not span a plane".into()));
        }
        let normal = normal / n;
        for p in &pts {
            let off = (p - origin).dot(&normal);
            if off.abs() > PLANARITY_TOLERANCE_MM {
                return Err(bad(format!(
                    "corners are not coplanar ({off:.2} mm off the plane)"
                )));
            }
        }
        let u = (first - normal * first.dot(&normal)).normalize();
        // Newell's normal follows the corners' winding, so n × u points into the polygon.
        let v = normal.cross(&u);
        let polygon = pts
            .iter()
            .map(|p| [(p - origin).dot(&u), (p - origin).dot(&v)])
            .collect();
        Ok(Self {
            id,
            corners: pts,
            origin,
            u,
            v,
            normal,
            polygon,
        })
    }

    /// A phone's or tablet's own screen, `width_mm` × `height_mm` as the user sees it, with the
    /// camera in the screen's plane at `camera_mm` = (right, down) from the screen's top-left
    /// corner as the user sees it (negative `down` for a camera above the screen). For a front
    /// camera whose frames are mirrored (`FrameDesc::mirrored`, the selfie view), so that the
    /// camera's x axis points to the user's right. (u, v) on it are then the user's screen
    /// coordinates in mm from the top-left.
    ///
    /// # Errors
    /// [`Error::InvalidConfig`] for a size that is not finite and positive.
    pub fn screen(
        id: impl Into<String>,
        width_mm: f64,
        height_mm: f64,
        camera_mm: [f64; 2],
    ) -> Result<Self> {
        let id = id.into();
        let ok = width_mm.is_finite()
            && height_mm.is_finite()
            && width_mm > 0.0
            && height_mm > 0.0
            && camera_mm.iter().all(|c| c.is_finite());
        if !ok {
            return Err(Error::InvalidConfig(format!(
                "screen {id:?}: size {width_mm}x{height_mm} mm and camera offset must be finite, the size positive"
            )));
        }
        let (x0, y0) = (-camera_mm[0], -camera_mm[1]);
        Self::new(
            id,
            &[
                [x0, y0, 0.0],
                [x0 + width_mm, y0, 0.0],
                [x0 + width_mm, y0 + height_mm, 0.0],
                [x0, y0 + height_mm, 0.0],
            ],
        )
    }

    /// The corners, camera frame, mm.
    pub fn corners(&self) -> &[Vector3<f64>] {
        &self.corners
    }

    /// The point at (u, v) mm on the target's plane, camera frame.
    pub fn point_at(&self, uv: [f64; 2]) -> Vector3<f64> {
        self.origin + self.u * uv[0] + self.v * uv[1]
    }

    /// (u, v) of a point on the plane.
    fn uv_of(&self, p: &Vector3<f64>) -> [f64; 2] {
        let d = p - self.origin;
        [d.dot(&self.u), d.dot(&self.v)]
    }

    /// Distance in the plane from (u, v) to the polygon: 0 inside.
    fn distance_2d(&self, q: [f64; 2]) -> f64 {
        if point_in_polygon(&self.polygon, q) {
            return 0.0;
        }
        let n = self.polygon.len();
        (0..n)
            .map(|i| segment_distance(q, self.polygon[i], self.polygon[(i + 1) % n]))
            .fold(f64::INFINITY, f64::min)
    }

    /// The centroid of the corners.
    fn centroid(&self) -> Vector3<f64> {
        self.corners.iter().sum::<Vector3<f64>>() / self.corners.len() as f64
    }
}

/// Targets from the CLI contract's `T.json`: `{"targets": [{"id": str, "corners_mm": [[x, y, z],
/// ...]}]}` (camera frame, ≥ 3 coplanar corners in order; other fields are ignored).
///
/// # Errors
/// [`Error::InvalidConfig`] for malformed JSON, no targets, a repeated id or a bad target.
pub fn targets_from_json(bytes: &[u8]) -> Result<Vec<Target>> {
    #[derive(serde::Deserialize)]
    struct File {
        targets: Vec<Entry>,
    }
    #[derive(serde::Deserialize)]
    struct Entry {
        id: String,
        corners_mm: Vec<[f64; 3]>,
    }
    let f: File = serde_json::from_slice(bytes)
        .map_err(|e| Error::InvalidConfig(format!("targets JSON: {e}")))?;
    if f.targets.is_empty() {
        return Err(Error::InvalidConfig("targets JSON: no targets".into()));
    }
    let mut out: Vec<Target> = Vec::with_capacity(f.targets.len());
    for e in f.targets {
        if out.iter().any(|t| t.id == e.id) {
            return Err(Error::InvalidConfig(format!(
                "targets JSON: id {:?} given twice",
                e.id
            )));
        }
        out.push(Target::new(e.id, &e.corners_mm)?);
    }
    Ok(out)
}

/// Even–odd rule (boundary points count as inside up to rounding).
fn point_in_polygon(poly: &[[f64; 2]], q: [f64; 2]) -> bool {
    let mut inside = false;
    let n = poly.len();
    let mut j = n - 1;
    for i in 0..n {
        let (a, b) = (poly[i], poly[j]);
        if (a[1] > q[1]) != (b[1] > q[1]) {
            let x = a[0] + (q[1] - a[1]) * (b[0] - a[0]) / (b[1] - a[1]);
            if q[0] < x {
                inside = !inside;
            }
        }
        j = i;
    }
    inside
}

fn segment_distance(q: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let len2 = dx * dx + dy * dy;
    let t = if len2 > 0.0 {
        (((q[0] - a[0]) * dx + (q[1] - a[1]) * dy) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let (px, py) = (a[0] + t * dx - q[0], a[1] + t * dy - q[1]);
    (px * px + py * py).sqrt()
}

/// A gaze ray, camera frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GazeRay {
    /// Where it starts, mm.
    pub origin: Vector3<f64>,
    /// Unit direction.
    pub direction: Vector3<f64>,
}

/// Where a ray lands among targets.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TargetHit {
    /// Index of the target hit (in the slice given to [`locate`]), `None` when none is.
    pub target: Option<usize>,
    /// Index of the target hit, or else of the nearest one.
    pub nearest: usize,
    /// (u, v) mm on the hit target; else where the ray meets the nearest target's plane, or its
    /// centroid when the ray never meets that plane in front of the eyes.
    pub point_mm: [f64; 2],
    /// 0 on a hit; else the distance from the ray to the nearest target, mm (in its plane where
    /// the ray meets it, from its centroid to the ray otherwise).
    pub distance_mm: f64,
    /// Distance along the ray to the point, mm (`f64::INFINITY` when the plane is not met).
    pub range_mm: f64,
}

/// Ray–plane intersection for each target (thesis eq. 6.6) and point-in-polygon: where several
/// targets are hit, the nearest along the ray wins; where none is, the nearest target and the
/// distance to it (Algorithm 15). Targets behind the eyes or parallel to the ray are never hit.
/// `None` only for an empty slice.
pub fn locate(targets: &[Target], ray: &GazeRay) -> Option<TargetHit> {
    let mut best_hit: Option<TargetHit> = None;
    let mut best_miss: Option<TargetHit> = None;
    for (i, t) in targets.iter().enumerate() {
        let denom = t.normal.dot(&ray.direction);
        let along = if denom.abs() > 1e-12 {
            t.normal.dot(&(t.origin - ray.origin)) / denom
        } else {
            f64::NAN
        };
        let candidate = if along > 0.0 {
            let q = ray.origin + ray.direction * along;
            let uv = t.uv_of(&q);
            TargetHit {
                target: None,
                nearest: i,
                point_mm: uv,
                distance_mm: t.distance_2d(uv),
                range_mm: along,
            }
        } else {
            // Behind the eyes or parallel: how far the target lies from the ray (half-line).
            let c = t.centroid();
            let s = (c - ray.origin).dot(&ray.direction).max(0.0);
            TargetHit {
                target: None,
                nearest: i,
                point_mm: t.uv_of(&c),
                distance_mm: (c - (ray.origin + ray.direction * s)).norm(),
                range_mm: f64::INFINITY,
            }
        };
        if candidate.distance_mm == 0.0 && candidate.range_mm.is_finite() {
            if best_hit.is_none_or(|b| candidate.range_mm < b.range_mm) {
                best_hit = Some(TargetHit {
                    target: Some(i),
                    ..candidate
                });
            }
        } else if best_miss.is_none_or(|b| candidate.distance_mm < b.distance_mm) {
            best_miss = Some(candidate);
        }
    }
    best_hit.or(best_miss)
}

/// (yaw, pitch) of a direction, radians: yaw about y (positive towards +x), pitch about x
/// (positive towards +y), both 0 for a ray towards the camera (−z).
fn angles(d: &Vector3<f64>) -> [f64; 2] {
    [d.x.matan2(-d.z), d.y.matan2(d.x.mhypot(d.z))]
}

fn from_angles(a: [f64; 2]) -> Vector3<f64> {
    let (sy, cy) = a[0].msin_cos();
    let (sp, cp) = a[1].msin_cos();
    Vector3::new(cp * sy, sp, -cp * cy)
}

fn rotate_by(d: &Vector3<f64>, offset: [f64; 2]) -> Vector3<f64> {
    let a = angles(d);
    from_angles([a[0] + offset[0], a[1] + offset[1]])
}

/// Most taps a calibration keeps (the oldest go first): a user's offset is stable, and the
/// median over this many is robust to mis-taps.
pub const MAX_CALIBRATION_TAPS: usize = 64;

/// A per-user correction of the gaze direction, per eye, learnt from taps (see the module docs).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct GazeCalibration {
    /// Per tap: (yaw, pitch) offsets, radians, of the right eye then the left eye.
    taps: Vec<[[f64; 2]; 2]>,
    /// The current correction: the component-wise median of `taps`, per eye.
    offset: [[f64; 2]; 2],
}

impl GazeCalibration {
    /// Records that while the eyes were `eyes` (right, left: origin and measured direction, before
    /// any correction) the user looked at `point` (camera frame, mm). The correction is
    /// re-estimated at once.
    ///
    /// # Errors
    /// [`Error::InvalidInput`] for non-finite values or a point at an eye.
    pub fn add_tap(&mut self, eyes: &[GazeRay; 2], point: &Vector3<f64>) -> Result<()> {
        let mut tap = [[0.0; 2]; 2];
        for (slot, eye) in tap.iter_mut().zip(eyes) {
            let to = point - eye.origin;
            let n = to.norm();
            let usable = n > 1e-6 && n.is_finite() && eye.direction.iter().all(|v| v.is_finite());
            if !usable {
                return Err(Error::InvalidInput(
                    "a calibration tap needs finite eye rays and a point away from the eyes".into(),
                ));
            }
            let (want, got) = (angles(&(to / n)), angles(&eye.direction));
            *slot = [wrap(want[0] - got[0]), want[1] - got[1]];
        }
        if self.taps.len() == MAX_CALIBRATION_TAPS {
            self.taps.remove(0);
        }
        self.taps.push(tap);
        self.update_offset();
        Ok(())
    }

    fn update_offset(&mut self) {
        if self.taps.is_empty() {
            self.offset = [[0.0; 2]; 2];
            return;
        }
        for eye in 0..2 {
            for k in 0..2 {
                let mut v: Vec<f64> = self.taps.iter().map(|t| t[eye][k]).collect();
                self.offset[eye][k] = median(&mut v);
            }
        }
    }

    /// Every tap's (yaw, pitch) offsets, radians, right eye then left eye, oldest first: what
    /// [`Self::from_tap_offsets`] rebuilds the calibration from (a recording's start holds them).
    pub fn tap_offsets(&self) -> &[[[f64; 2]; 2]] {
        &self.taps
    }

    /// The calibration of taps with these offsets ([`Self::tap_offsets`]).
    ///
    /// # Errors
    /// [`Error::InvalidInput`] for more than [`MAX_CALIBRATION_TAPS`] taps or a non-finite offset.
    pub fn from_tap_offsets(taps: &[[[f64; 2]; 2]]) -> Result<Self> {
        if taps.len() > MAX_CALIBRATION_TAPS {
            return Err(Error::InvalidInput(format!(
                "{} calibration taps; at most {MAX_CALIBRATION_TAPS} are kept",
                taps.len()
            )));
        }
        if taps.iter().flatten().flatten().any(|v| !v.is_finite()) {
            return Err(Error::InvalidInput(
                "calibration tap offsets must be finite".into(),
            ));
        }
        let mut c = Self {
            taps: taps.to_vec(),
            offset: [[0.0; 2]; 2],
        };
        c.update_offset();
        Ok(c)
    }

    /// Taps recorded.
    pub fn taps(&self) -> usize {
        self.taps.len()
    }

    /// The correction (yaw, pitch) in degrees, right eye then left eye.
    pub fn offsets_deg(&self) -> [[f64; 2]; 2] {
        self.offset.map(|e| e.map(f64::to_degrees))
    }

    /// Applies the correction to one eye's direction (0 right, 1 left).
    pub fn correct(&self, eye: usize, direction: &Vector3<f64>) -> Vector3<f64> {
        if self.taps.is_empty() {
            *direction
        } else {
            rotate_by(direction, self.offset[eye])
        }
    }

    /// Forgets every tap.
    pub fn reset(&mut self) {
        *self = Self::default();
    }
}

fn wrap(a: f64) -> f64 {
    (a + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Optional temporal smoothing of the gaze direction: an exponential average that jumps straight
/// to the new direction when it moved more than `saccade_deg` (saccades stay sharp; fixation
/// jitter is smoothed).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct GazeFilter {
    /// Weight of the newest direction, 0 < alpha ≤ 1.
    pub alpha: f64,
    /// A change larger than this (degrees) is a saccade: taken as is.
    pub saccade_deg: f64,
}

impl Default for GazeFilter {
    fn default() -> Self {
        // A fixation's jitter is a few degrees; saccades between screen regions are larger.
        Self {
            alpha: 0.4,
            saccade_deg: 6.0,
        }
    }
}

impl GazeFilter {
    /// The filtered direction given the previous filtered one.
    pub fn apply(&self, previous: Option<&Vector3<f64>>, current: &Vector3<f64>) -> Vector3<f64> {
        match previous {
            Some(p) if crate::math::angle(p, current).to_degrees() <= self.saccade_deg => {
                (p * (1.0 - self.alpha) + current * self.alpha).normalize()
            }
            _ => *current,
        }
    }
}

/// Which rays a point of gaze came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GazeSource {
    /// The eyes' gaze vectors.
    Eyes,
    /// The head's facing direction: the eyes' estimates were not trustworthy (large head
    /// rotation, eyes that disagree).
    Head,
}

/// Point-of-gaze settings (serde: a recording's header holds them, `crate::record`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct GazeConfig {
    /// Below this confidence the head direction replaces the eyes'.
    pub min_eye_confidence: f64,
    /// Head yaw (degrees, absolute) at which the eyes' confidence reaches 0: past it one eye is
    /// hidden and the eye patches are too foreshortened for M3's eye network.
    pub max_yaw_deg: f64,
    /// The temporal filter; `None` (the default) passes every frame's direction through.
    pub filter: Option<GazeFilter>,
    /// Eye aspect ratio ([`eye_openness`]) at or below which an eye counts as closed: the eyes'
    /// confidence is 0 there, and rises to its other terms' value at [`Self::open_eye_ratio`].
    /// On faces68 the few faces with an eye at or below the default are closed eyes (most near
    /// 0), and most faces have both eyes well above it.
    pub closed_eye_ratio: f64,
    /// Eye aspect ratio from which an eye counts as fully open.
    pub open_eye_ratio: f64,
    /// The thesis' head-pose correction of each eye's gaze and the dominant eye's weight (eq.
    /// 6.4); the default applies none (see [`HeadCorrection`]).
    pub head_correction: HeadCorrection,
}

/// The thesis' correction of each eye's gaze by the head pose (eq. 6.4): the eye-in-head angles
/// shifted by `K_x (yaw − r_x0)` and `K_y (pitch − r_y0)`, and the eye nearer the camera weighted
/// more in the combined direction as the head turns. The default leaves M3's gaze as it is:
/// fitted on the faces68 training split (`core/models/train/eval_gaze.py --fit-correction`), the
/// correction made the validation error worse, with equal eye weights and with a dominant eye
/// (`core/models/m3/gaze_metrics.json`; `core/models/train/RESEARCH_LOG.md`, "Gaze against an
/// iris teacher"), as M3's eye network already sees the head's turn in its patches.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct HeadCorrection {
    /// K_x: degrees of eye-in-head yaw added per degree of head yaw away from `ref_yaw_deg`.
    pub gain_yaw: f64,
    /// K_y: likewise for pitch.
    pub gain_pitch: f64,
    /// r_x0: the head yaw (degrees) at which the yaw term is 0.
    pub ref_yaw_deg: f64,
    /// r_y0: the head pitch (degrees) at which the pitch term is 0.
    pub ref_pitch_deg: f64,
    /// w_d: the weight of the eye nearer the camera once the head is turned by
    /// [`GazeConfig::max_yaw_deg`], from 0.5 (equal weights) at a frontal head, linearly in yaw.
    pub dominant_weight: f64,
}

impl Default for HeadCorrection {
    fn default() -> Self {
        Self {
            gain_yaw: 0.0,
            gain_pitch: 0.0,
            ref_yaw_deg: 0.0,
            ref_pitch_deg: 0.0,
            dominant_weight: 0.5,
        }
    }
}

impl HeadCorrection {
    /// Each eye's ray with the angle correction applied (the same rays when both gains are 0).
    pub fn apply(&self, raw: &[GazeRay; 2], fit: &FaceFit) -> [GazeRay; 2] {
        if self.gain_yaw == 0.0 && self.gain_pitch == 0.0 {
            return *raw;
        }
        let (yaw, pitch, _) = fit.pose.euler_deg();
        let shift = [
            (self.gain_yaw * (yaw - self.ref_yaw_deg)).to_radians(),
            (self.gain_pitch * (pitch - self.ref_pitch_deg)).to_radians(),
        ];
        let r = fit.pose.rotation;
        raw.map(|ray| {
            // Eye-in-head angles: 0 straight ahead (the head frame's −z), yaw towards +x.
            let h = r.transpose() * ray.direction;
            let a = [
                h.x.matan2(-h.z) + shift[0],
                h.y.matan2(h.x.mhypot(h.z)) + shift[1],
            ];
            let back = Vector3::new(
                a[1].mcos() * a[0].msin(),
                a[1].msin(),
                -a[1].mcos() * a[0].mcos(),
            );
            GazeRay {
                origin: ray.origin,
                direction: r * back,
            }
        })
    }

    /// The weights (right eye, left eye) of the combined direction for a face turned as `fit`.
    fn eye_weights(&self, fit: &FaceFit, max_yaw_deg: f64) -> (f64, f64) {
        let (yaw, _, _) = fit.pose.euler_deg();
        let w = 0.5 + (yaw.abs() / max_yaw_deg).min(1.0) * (self.dominant_weight - 0.5);
        // The head frame's +x (the subject's left) turned towards the camera: the left eye is
        // the nearer one.
        let left_near = (fit.pose.rotation * Vector3::new(1.0, 0.0, 0.0)).z < 0.0;
        if left_near {
            (1.0 - w, w)
        } else {
            (w, 1.0 - w)
        }
    }
}

impl Default for GazeConfig {
    fn default() -> Self {
        Self {
            min_eye_confidence: 0.25,
            max_yaw_deg: 60.0,
            filter: None,
            closed_eye_ratio: 0.10,
            open_eye_ratio: 0.18,
            head_correction: HeadCorrection::default(),
        }
    }
}

/// Where one face looks.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointOfGaze {
    /// The ray `hit` was located with, and so the one to show with it: the eyes' combined
    /// direction (corrected by the calibration, filtered if asked) or, where `source` is
    /// [`GazeSource::Head`], the head's. Not M3's `FaceLandmarks::gaze_combined`, which is the
    /// eye network's own estimate and stays the eyes' where the head stands in.
    pub ray: GazeRay,
    /// The two eyes' rays (right, left), corrected by the calibration.
    pub eyes: [GazeRay; 2],
    /// Eyes or head.
    pub source: GazeSource,
    /// 0..1: how far the eyes' estimate is to be trusted (head yaw, agreement of the two eyes,
    /// how open they are).
    pub confidence: f64,
    /// Angle between the head's facing direction and the gaze, degrees.
    pub head_to_gaze_deg: f64,
    /// Where `ray` lands among the targets (`None` without targets).
    pub hit: Option<TargetHit>,
}

/// The fitted face's eye centres (right, left): centroids of the posed eye-contour vertices,
/// camera frame, mm.
pub fn eye_centres(fit: &FaceFit) -> [Vector3<f64>; 2] {
    let v = fit.posed_vertices();
    let mean = |r: std::ops::Range<usize>| v[r].iter().sum::<Vector3<f64>>() / 6.0;
    // iBUG 36–41: the subject's right eye; 42–47: the left.
    [mean(36..42), mean(42..48)]
}

/// The per-eye rays of a face before any correction: from each eye centre along M3's gaze.
pub fn raw_eye_rays(landmarks: &FaceLandmarks, fit: &FaceFit) -> [GazeRay; 2] {
    let [re, le] = eye_centres(fit);
    let dir = |g: &[f32; 3]| {
        let d = Vector3::new(f64::from(g[0]), f64::from(g[1]), f64::from(g[2]));
        let n = d.norm();
        if n > 0.0 {
            d / n
        } else {
            Vector3::new(0.0, 0.0, -1.0)
        }
    };
    [
        GazeRay {
            origin: re,
            direction: dir(&landmarks.gaze_right),
        },
        GazeRay {
            origin: le,
            direction: dir(&landmarks.gaze_left),
        },
    ]
}

/// The point of gaze of one face: per-eye rays corrected by `calibration`, combined (the
/// normalised mean, from the midpoint of the eyes), the head direction where the eyes are not
/// trusted, filtered against `previous` when `config.filter` is set, located among `targets`.
pub fn point_of_gaze(
    landmarks: &FaceLandmarks,
    fit: &FaceFit,
    calibration: &GazeCalibration,
    config: &GazeConfig,
    previous: Option<&Vector3<f64>>,
    targets: &[Target],
) -> PointOfGaze {
    let raw = config
        .head_correction
        .apply(&raw_eye_rays(landmarks, fit), fit);
    let openness = eye_openness(&landmarks.points);
    point_of_gaze_from_rays(&raw, openness, fit, calibration, config, previous, targets)
}

/// The less open eye's aspect ratio in the 68 landmarks (iBUG eyes 36–41 and 42–47): the two
/// lid distances over twice the corner distance, about 0.3 for an open eye and 0 for a closed
/// one. 0 when an eye's corners coincide.
pub fn eye_openness(points: &[[f32; 2]; 68]) -> f64 {
    let d = |a: usize, b: usize| {
        let (p, q) = (points[a], points[b]);
        f64::from(p[0] - q[0]).mhypot(f64::from(p[1] - q[1]))
    };
    let ratio = |e: usize| {
        let width = d(e, e + 3);
        if width > 0.0 {
            (d(e + 1, e + 5) + d(e + 2, e + 4)) / (2.0 * width)
        } else {
            0.0
        }
    };
    ratio(36).min(ratio(42))
}

/// [`point_of_gaze`] from the face's eye rays before the tap calibration ([`raw_eye_rays`] with
/// `config.head_correction` applied), for a caller that keeps them too (the tracker records them
/// for taps).
pub fn point_of_gaze_from_rays(
    raw: &[GazeRay; 2],
    openness: f64,
    fit: &FaceFit,
    calibration: &GazeCalibration,
    config: &GazeConfig,
    previous: Option<&Vector3<f64>>,
    targets: &[Target],
) -> PointOfGaze {
    let eyes = [0, 1].map(|e| GazeRay {
        origin: raw[e].origin,
        direction: calibration.correct(e, &raw[e].direction),
    });
    let origin = (eyes[0].origin + eyes[1].origin) / 2.0;
    let head = -(fit.pose.rotation * Vector3::new(0.0, 0.0, 1.0));
    let (yaw, _, _) = fit.pose.euler_deg();
    let agreement = eyes[0].direction.dot(&eyes[1].direction).clamp(-1.0, 1.0);
    // Two eyes more than ~25° apart are not converging on anything: one estimate is wrong.
    let agree = ((agreement - 0.9) / 0.1).clamp(0.0, 1.0);
    let turn = (1.0 - yaw.abs() / config.max_yaw_deg).clamp(0.0, 1.0);
    // Closed eyes: M3's eye network still gives a direction, of nothing.
    let open = ((openness - config.closed_eye_ratio)
        / (config.open_eye_ratio - config.closed_eye_ratio))
        .clamp(0.0, 1.0);
    let confidence = agree * turn * open;
    let (mut direction, source) = if confidence >= config.min_eye_confidence {
        let (wr, wl) = config.head_correction.eye_weights(fit, config.max_yaw_deg);
        (
            (wr * eyes[0].direction + wl * eyes[1].direction).normalize(),
            GazeSource::Eyes,
        )
    } else {
        (head, GazeSource::Head)
    };
    if let Some(f) = &config.filter {
        direction = f.apply(previous, &direction);
    }
    let ray = GazeRay { origin, direction };
    PointOfGaze {
        ray,
        eyes,
        source,
        confidence,
        head_to_gaze_deg: crate::math::angle(&head, &direction).to_degrees(),
        hit: locate(targets, &ray),
    }
}

#[cfg(test)]
mod tests;

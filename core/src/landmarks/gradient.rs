//! The learning-free gradient landmark detector: 32 points from image gradients alone, for the
//! ultra-light mode (no network loaded for landmarks) and as a fallback when M3 cannot load.
//!
//! The face box (the detector's convention: the tight box of the 68 landmarks) is sampled into a
//! canonical patch, [`SCALE`] pixels per box side, turned by the face's roll. Each facial part is
//! then found in its own search region of that patch:
//!
//! 1. *Double sigmoidal filtering* of the region: the sigmoid of the intensity standardised by the
//!    region's mean and deviation, twice, so dark features (eyes, brows, nostrils, the mouth
//!    line) go to 0 and skin to 1 whatever the lighting.
//! 2. *Squared sigmoidal gradients* `Ex = (∂f/∂x)²`, `Ey = (∂f/∂y)²` of the filtered region.
//! 3. *Weighted projections*: a row projection (each row's sum, columns weighted by a Gaussian
//!    around the part's expected centre) places a part vertically; a column projection over the
//!    part's band, with its peaks at or above `p_x` % of the band's maximum (rows: `p_y` %),
//!    bounds it horizontally (eye and mouth corners, brow ends, nostril wings).
//! 4. Order: the eyes first (the roll angle comes from the two eye centres, and everything after
//!    runs in a patch de-rotated by it). Each eye's centre is where the most strong gradients
//!    point away from (Timm and Barth's means of gradients, weighted by darkness). The eyes'
//!    midpoint and distance then place every other point by the *expected geometry given the
//!    eyes* (`geometry.rs`, a linear map fitted on faces68 training faces by
//!    `core/models/train/fit_gradient_geometry.py`): a yawed or nodding face moves its eyes in its
//!    box and every other part with them, which the mean face alone cannot follow. The brows
//!    (x bounds from the search region and the expected geometry), the nose and the mouth are
//!    searched around where that geometry puts them, then the contour: cheeks, facial corners
//!    and chin sides from an x-gradient binarised at `p_x` % with short clusters removed by
//!    connected components, the chin bottom from the row projection of `Ey` below the mouth;
//!    the forehead centre, which shows no edge, from the geometry.
//!
//! All 32 points are always returned, each with a confidence in 0..1: each point moves from
//! where the geometry expects it towards its evidence by its confidence squared, so a part whose
//! evidence is missing stays where the eyes put it, with a low confidence that the fit uses as a
//! weight. The points' order is [`GRADIENT_NAMES`]; [`GRADIENT_TO_68`] maps the 27 that have an
//! iBUG-68 counterpart. Everything runs in buffers the detector owns: no allocation per face
//! after the first.
//!
//! The image analysis learns nothing; the geometry is a fixed table of 256 numbers (statistics
//! of annotated faces, as the mean face is), so the mode loads no model.

use super::warp::{Affine, sample};
use super::{FaceLandmarks, N_POINTS};
use crate::error::{Error, Result};
use crate::image::{GrayImage, Rect};
use crate::math::Libm;

/// Points the gradient detector gives.
pub const N_GRADIENT: usize = 32;

/// The points' names, in output order ("right" is the subject's right: the image's left on an
/// unmirrored frontal face, as in iBUG-68).
pub const GRADIENT_NAMES: [&str; N_GRADIENT] = [
    "forehead_centre",
    "right_cheek",
    "left_cheek",
    "right_facial_corner",
    "left_facial_corner",
    "right_chin_side",
    "left_chin_side",
    "chin_bottom",
    "right_brow_outer",
    "right_brow_middle",
    "right_brow_inner",
    "left_brow_inner",
    "left_brow_middle",
    "left_brow_outer",
    "right_eye_outer",
    "right_eye_upper_lid",
    "right_eye_inner",
    "right_eye_lower_lid",
    "left_eye_inner",
    "left_eye_upper_lid",
    "left_eye_outer",
    "left_eye_lower_lid",
    "nose_tip",
    "right_nostril",
    "subnasale",
    "left_nostril",
    "right_mouth_corner",
    "upper_lip_top",
    "left_mouth_corner",
    "lower_lip_bottom",
    "upper_lip_inner",
    "lower_lip_inner",
];

/// The iBUG-68 index of each point, `None` where 68 has no such point (the forehead and the lid
/// midpoints).
pub const GRADIENT_TO_68: [Option<usize>; N_GRADIENT] = [
    None,
    Some(1),
    Some(15),
    Some(4),
    Some(12),
    Some(6),
    Some(10),
    Some(8),
    Some(17),
    Some(19),
    Some(21),
    Some(22),
    Some(24),
    Some(26),
    Some(36),
    None,
    Some(39),
    None,
    Some(42),
    None,
    Some(45),
    None,
    Some(30),
    Some(31),
    Some(33),
    Some(35),
    Some(48),
    Some(51),
    Some(54),
    Some(57),
    Some(62),
    Some(66),
];

/// Canonical patch pixels per face-box side.
pub const SCALE: usize = 80;
/// Box units left of the box (and right of it) and above it that the patch covers: the forehead
/// lies above the detector's box, whose top is the brows.
const MARGIN_X: f32 = 0.15;
const MARGIN_TOP: f32 = 0.45;
const MARGIN_BOTTOM: f32 = 0.15;
const PATCH_W: usize = ((1.0 + 2.0 * MARGIN_X) * SCALE as f32) as usize;
const PATCH_H: usize = ((1.0 + MARGIN_TOP + MARGIN_BOTTOM) * SCALE as f32) as usize;

/// The mean frontal face in box units (u, v: 0..1 across the tight 68-point box), per point of
/// [`GRADIENT_NAMES`]: where a part is searched for, and where a point falls back to when its
/// evidence is missing. (Means of the frontal faces of faces68's train split, rounded; the
/// forehead centre 0.3 box heights above the eyes.)
const MEAN: [[f32; 2]; N_GRADIENT] = [
    [0.50, -0.12],
    [0.016, 0.345],
    [0.985, 0.331],
    [0.114, 0.730],
    [0.896, 0.715],
    [0.289, 0.915],
    [0.728, 0.906],
    [0.511, 0.997],
    [0.078, 0.121],
    [0.230, 0.041],
    [0.408, 0.085],
    [0.573, 0.078],
    [0.755, 0.032],
    [0.908, 0.110],
    [0.182, 0.203],
    [0.273, 0.168],
    [0.362, 0.217],
    [0.270, 0.230],
    [0.623, 0.214],
    [0.716, 0.165],
    [0.803, 0.197],
    [0.721, 0.226],
    [0.497, 0.457],
    [0.391, 0.512],
    [0.497, 0.544],
    [0.598, 0.512],
    [0.305, 0.667],
    [0.497, 0.637],
    [0.693, 0.662],
    [0.498, 0.776],
    [0.497, 0.671],
    [0.497, 0.712],
];

/// The patch rows the eye search reads: the eye regions (the mean eye row ± 0.12 box) with the
/// centroid windows and corner bands around them, and slack for a roll of up to about 30°.
const EYE_ROWS: (usize, usize) = (
    ((MARGIN_TOP + 0.21 - 0.3) * SCALE as f32) as usize,
    ((MARGIN_TOP + 0.21 + 0.3) * SCALE as f32) as usize,
);

/// The eyes' corners and lid midpoints, [`GRADIENT_NAMES`] indices.
const EYE_POINTS: std::ops::Range<usize> = 14..22;

/// Confidence of a point placed from the expected geometry alone.
const PRIOR_CONFIDENCE: f32 = 0.15;

/// The settle score (see `GradientDetector::settle`) above which the eyes found from the roll
/// hint are taken as a pair; below it, or with the parts found less clearly than
/// `SETTLED_PARTS` (mean confidence), other starting rolls are tried.
const SETTLED_SCORE: f32 = 0.2;

/// See `SETTLED_SCORE`.
const SETTLED_PARTS: f32 = 0.6;

/// Starts that settle within this many degrees of a roll already judged are taken as the same
/// answer.
const SAME_ROLL_DEG: f32 = 3.0;

/// How much more clearly (mean confidence) another start's parts must be found to replace the
/// hint's answer. On the synthetic faces a head tilted beyond the level start's reach, found from
/// a turned start, leads the level answer by more than this; on faces68 tuning faces margins near
/// it change hardly any face.
const FALLBACK_MARGIN: f32 = 0.09;

/// The starting rolls tried, relative to the hint, when the hint's own start finds no pair:
/// each start finds a face within about 10° of it, so 20° steps leave no gap out to ±50°.
const FALLBACK_TURNS_DEG: [f32; 6] = [-15.0, 15.0, -30.0, 30.0, -45.0, 45.0];

/// Settings of the gradient detector (the defaults are the published ones).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GradientConfig {
    /// Column-projection peak threshold, % of the band's maximum (Alg. 4's `p_x`).
    pub p_x: f32,
    /// Row-projection peak threshold, % of the region's maximum (Alg. 3's `p_y`).
    pub p_y: f32,
    /// Gain of each sigmoid, per standard deviation of the region.
    pub sigmoid_gain: f32,
}

impl Default for GradientConfig {
    fn default() -> Self {
        Self {
            p_x: 20.0,
            p_y: 50.0,
            sigmoid_gain: 2.0,
        }
    }
}

impl GradientConfig {
    /// Checks the ranges.
    ///
    /// # Errors
    /// [`Error::InvalidConfig`] for a threshold outside 0..100 or a gain that is not positive.
    pub fn validate(&self) -> Result<()> {
        for (name, v) in [("p_x", self.p_x), ("p_y", self.p_y)] {
            if !(v.is_finite() && (0.0..100.0).contains(&v)) {
                return Err(Error::InvalidConfig(format!(
                    "gradient detector {name} must be in 0..100 %, got {v}"
                )));
            }
        }
        if !(self.sigmoid_gain.is_finite() && self.sigmoid_gain > 0.0) {
            return Err(Error::InvalidConfig(format!(
                "gradient detector sigmoid_gain must be positive, got {}",
                self.sigmoid_gain
            )));
        }
        Ok(())
    }
}

/// What the detector finds on one face.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GradientPoints {
    /// The points in image pixels (CONTRACT pixel convention), [`GRADIENT_NAMES`] order.
    pub points: [[f32; 2]; N_GRADIENT],
    /// Per point, 0..1: how clearly its evidence stood out ([`PRIOR_CONFIDENCE`]-level where it
    /// fell back to the expected geometry).
    pub confidence: [f32; N_GRADIENT],
    /// The face's roll in the image, degrees (the eye line's angle; positive turns the face
    /// clockwise on screen, image y down).
    pub roll_deg: f32,
    /// The eyes' centres (the irises' centres where they show), image pixels: the subject's
    /// right eye, then the left.
    pub eye_centres: [[f32; 2]; 2],
}

impl Default for GradientPoints {
    fn default() -> Self {
        Self {
            points: [[0.0; 2]; N_GRADIENT],
            confidence: [0.0; N_GRADIENT],
            roll_deg: 0.0,
            eye_centres: [[0.0; 2]; 2],
        }
    }
}

impl GradientPoints {
    /// The mean frontal face placed in `face` (the detector's box convention), upright, every
    /// point at [`PRIOR_CONFIDENCE`]: what the detector falls back to where it finds nothing, and
    /// the baseline its accuracy is judged against.
    pub fn mean_face(face: &Rect) -> Self {
        let mut out = Self::default();
        for (i, m) in MEAN.iter().enumerate() {
            out.points[i] = [face.x + m[0] * face.w, face.y + m[1] * face.h];
            out.confidence[i] = PRIOR_CONFIDENCE;
        }
        for (e, o) in out.eye_centres.iter_mut().enumerate() {
            let m = mean_eye(e);
            *o = [face.x + m[0] * face.w, face.y + m[1] * face.h];
        }
        out
    }

    /// Mean confidence over the points with a 68-point counterpart: how much of the face the
    /// gradients found (the ultra-light tracker's face check).
    pub fn mean_confidence(&self) -> f32 {
        let (mut s, mut n) = (0.0, 0.0);
        for (c, m) in self.confidence.iter().zip(&GRADIENT_TO_68) {
            if m.is_some() {
                s += c;
                n += 1.0;
            }
        }
        s / n
    }

    /// The points as 68-point landmarks: each counterpart at its index with its confidence as
    /// weight; the 68 points without a counterpart placed by the mean face under the similarity
    /// that best fits the found points (so they are plausible for drawing and for the optical
    /// flow), with weight 0.
    pub fn to_landmarks(&self, out: &mut FaceLandmarks) {
        // Least-squares similarity from mean-face box units to the image over the counterparts.
        let (mut mu, mut mp, mut n) = ([0f64; 2], [0f64; 2], 0f64);
        for (i, m) in GRADIENT_TO_68.iter().enumerate() {
            if m.is_some() {
                let w = self.confidence[i].max(1e-3) as f64;
                mu[0] += w * MEAN[i][0] as f64;
                mu[1] += w * MEAN[i][1] as f64;
                mp[0] += w * self.points[i][0] as f64;
                mp[1] += w * self.points[i][1] as f64;
                n += w;
            }
        }
        mu = [mu[0] / n, mu[1] / n];
        mp = [mp[0] / n, mp[1] / n];
        let (mut a, mut b, mut d) = (0f64, 0f64, 0f64);
        for (i, m) in GRADIENT_TO_68.iter().enumerate() {
            if m.is_some() {
                let w = self.confidence[i].max(1e-3) as f64;
                let (x, y) = (MEAN[i][0] as f64 - mu[0], MEAN[i][1] as f64 - mu[1]);
                let (p, q) = (
                    self.points[i][0] as f64 - mp[0],
                    self.points[i][1] as f64 - mp[1],
                );
                a += w * (x * p + y * q);
                b += w * (x * q - y * p);
                d += w * (x * x + y * y);
            }
        }
        let (a, b) = if d > 0.0 { (a / d, b / d) } else { (0.0, 0.0) };
        for (k, p) in MEAN68.iter().enumerate() {
            let (x, y) = (p[0] as f64 - mu[0], p[1] as f64 - mu[1]);
            out.points[k] = [
                (mp[0] + a * x - b * y) as f32,
                (mp[1] + b * x + a * y) as f32,
            ];
            out.weights[k] = 0.0;
        }
        for (i, m) in GRADIENT_TO_68.iter().enumerate() {
            if let Some(k) = *m {
                out.points[k] = self.points[i];
                out.weights[k] = self.confidence[i];
            }
        }
        out.face_prob = self.mean_confidence();
    }
}

/// The mean frontal face's 68 points in box units (as [`MEAN`]).
const MEAN68: [[f32; 2]; N_POINTS] = [
    [0.007, 0.206],
    [0.016, 0.345],
    [0.035, 0.480],
    [0.063, 0.610],
    [0.114, 0.730],
    [0.193, 0.832],
    [0.289, 0.915],
    [0.393, 0.981],
    [0.511, 0.997],
    [0.626, 0.974],
    [0.728, 0.906],
    [0.821, 0.820],
    [0.896, 0.715],
    [0.944, 0.594],
    [0.969, 0.464],
    [0.985, 0.331],
    [0.993, 0.192],
    [0.078, 0.121],
    [0.140, 0.059],
    [0.230, 0.041],
    [0.322, 0.053],
    [0.408, 0.085],
    [0.573, 0.078],
    [0.663, 0.045],
    [0.755, 0.032],
    [0.845, 0.051],
    [0.908, 0.110],
    [0.495, 0.187],
    [0.495, 0.277],
    [0.496, 0.366],
    [0.497, 0.457],
    [0.391, 0.512],
    [0.443, 0.529],
    [0.497, 0.544],
    [0.550, 0.528],
    [0.598, 0.512],
    [0.182, 0.203],
    [0.240, 0.172],
    [0.307, 0.174],
    [0.362, 0.217],
    [0.304, 0.227],
    [0.237, 0.227],
    [0.623, 0.214],
    [0.683, 0.167],
    [0.749, 0.167],
    [0.803, 0.197],
    [0.754, 0.221],
    [0.688, 0.224],
    [0.305, 0.667],
    [0.378, 0.638],
    [0.450, 0.625],
    [0.497, 0.637],
    [0.550, 0.624],
    [0.623, 0.639],
    [0.693, 0.662],
    [0.626, 0.736],
    [0.555, 0.769],
    [0.498, 0.776],
    [0.447, 0.771],
    [0.375, 0.739],
    [0.334, 0.671],
    [0.449, 0.665],
    [0.497, 0.671],
    [0.550, 0.664],
    [0.664, 0.667],
    [0.551, 0.705],
    [0.497, 0.712],
    [0.448, 0.706],
];

/// Where the canonical patch lies in the image: the face box's centre and size (pixels) and the
/// turn about the centre (radians).
#[derive(Debug, Clone, Copy)]
struct Frame {
    centre: [f32; 2],
    w: f32,
    h: f32,
    roll: f32,
    /// Whether the size came from the face box (else from the eyes).
    from_box: bool,
}

impl Frame {
    /// The frame of an axis-aligned box around a face turned by `roll`: a turned face's box is
    /// larger than its upright one (for a turned rectangle `W = w·c + h·s`, `H = w·s + h·c`); the
    /// face's points fill the corners less than a rectangle does, so half that shrink is taken.
    /// (The settling of the roll starts from this frame; [`Frame::fitted`] sizes the final one.)
    fn of_box(face: &Rect, roll: f32) -> Self {
        let (c, s) = (roll.mcos().abs(), roll.msin().abs());
        let det = c * c - s * s;
        let (w, h) = if det > 0.3 {
            let w = ((face.w * c - face.h * s) / det).max(0.5 * face.w);
            let h = ((face.h * c - face.w * s) / det).max(0.5 * face.h);
            (0.5 * (w + face.w), 0.5 * (h + face.h))
        } else {
            (face.w, face.h)
        };
        Self {
            centre: face.center(),
            w,
            h,
            roll,
            from_box: true,
        }
    }

    /// This frame with a box-derived size made exact for its roll: the upright size whose mean
    /// face, turned by the roll, has `face` as its axis-aligned box (two fixed-point rounds: the
    /// extreme points depend a little on the aspect). The half shrink of [`Frame::of_box`]
    /// left the box too large once the face is turned, and the expected contour inside the face.
    /// A frame placed on the eyes is kept.
    fn fitted(self, face: &Rect) -> Self {
        if !self.from_box {
            return self;
        }
        let (c, s) = (self.roll.mcos(), self.roll.msin());
        let (mut w, mut h) = (face.w, face.h);
        for _ in 0..2 {
            let (mut x0, mut x1, mut y0, mut y1) = (f32::MAX, f32::MIN, f32::MAX, f32::MIN);
            for p in &MEAN68 {
                let (u, v) = ((p[0] - 0.5) * w, (p[1] - 0.5) * h);
                let (x, y) = (c * u - s * v, s * u + c * v);
                x0 = x0.min(x);
                x1 = x1.max(x);
                y0 = y0.min(y);
                y1 = y1.max(y);
            }
            w *= face.w / (x1 - x0).max(1e-3);
            h *= face.h / (y1 - y0).max(1e-3);
        }
        Self { w, h, ..self }
    }

    /// The frame of a face whose eye centres are at `r` and `l` (image pixels): turned by the
    /// eye line, the mean face's box placed on the eyes, square. (`settle` trades it for the
    /// box's frame where the line ends nearly level.)
    fn of_eyes(r: [f32; 2], l: [f32; 2]) -> Self {
        let (mr, ml) = (mean_eye(0), mean_eye(1));
        let (dx, dy) = (l[0] - r[0], l[1] - r[1]);
        let roll = dy.matan2(dx);
        let w = (dx * dx + dy * dy).sqrt() / (ml[0] - mr[0]);
        let h = w;
        // From the eyes' midpoint to the box centre, in the face's turned frame.
        let (ou, ov) = (
            (0.5 - 0.5 * (mr[0] + ml[0])) * w,
            (0.5 - 0.5 * (mr[1] + ml[1])) * h,
        );
        let (c, s) = (roll.mcos(), roll.msin());
        Self {
            centre: [
                0.5 * (r[0] + l[0]) + c * ou - s * ov,
                0.5 * (r[1] + l[1]) + s * ou + c * ov,
            ],
            w,
            h,
            roll,
            from_box: false,
        }
    }
}

/// The mean face's eye centre (0 right, 1 left), box units.
fn mean_eye(which: usize) -> [f32; 2] {
    let (a, b) = if which == 0 { (14, 16) } else { (18, 20) };
    [
        0.5 * (MEAN[a][0] + MEAN[b][0]),
        0.5 * (MEAN[a][1] + MEAN[b][1]),
    ]
}

/// A search region of the patch, pixels, half-open.
#[derive(Debug, Clone, Copy)]
struct Region {
    x0: usize,
    y0: usize,
    x1: usize,
    y1: usize,
}

impl Region {
    /// The region between patch points, clipped to the patch (never empty).
    fn new(x0: f32, y0: f32, x1: f32, y1: f32) -> Self {
        let cx = |v: f32| (v.round().max(1.0) as usize).min(PATCH_W - 2);
        let cy = |v: f32| (v.round().max(1.0) as usize).min(PATCH_H - 2);
        let (x0, x1, y0, y1) = (
            cx(x0.min(x1)),
            cx(x0.max(x1)),
            cy(y0.min(y1)),
            cy(y0.max(y1)),
        );
        Self {
            x0,
            y0,
            x1: x1.max(x0 + 1),
            y1: y1.max(y0 + 1),
        }
    }
}

/// The gradient detector. Holds its buffers; one per thread.
#[derive(Debug, Clone)]
pub struct GradientDetector {
    config: GradientConfig,
    patch: Vec<u8>,
    /// The double-sigmoid image of the last region filtered (0 dark .. 1 bright).
    f: Vec<f32>,
    ex: Vec<f32>,
    ey: Vec<f32>,
    proj: Vec<f32>,
    mask: Vec<u8>,
    label: Vec<u32>,
    sizes: Vec<u32>,
    stack: Vec<usize>,
    /// A band of the patch sampled alone (the eye search's rows).
    band: Vec<u8>,
    /// The eyes' centres found last, patch pixels: right, left (by means of gradients in the
    /// final frame, by darkness centroids while the roll settles).
    eye_centres: [[f32; 2]; 2],
    /// Where each point is expected given the eyes found (patch pixels): the searches after the
    /// eyes' are centred here.
    expected: [[f32; 2]; N_GRADIENT],
    /// Strong gradients of an eye region: x, y, unit gx, gy, magnitude.
    grads: Vec<[f32; 5]>,
}

impl Default for GradientDetector {
    fn default() -> Self {
        Self::new()
    }
}

/// Converts patch pixels to box units and back.
#[inline]
fn px(u: f32) -> f32 {
    (u + MARGIN_X) * SCALE as f32
}
#[inline]
fn py(v: f32) -> f32 {
    (v + MARGIN_TOP) * SCALE as f32
}

impl GradientDetector {
    /// A detector with the default settings.
    pub fn new() -> Self {
        let n = PATCH_W * PATCH_H;
        Self {
            config: GradientConfig::default(),
            patch: Vec::with_capacity(n),
            f: vec![1.0; n],
            ex: vec![0.0; n],
            ey: vec![0.0; n],
            proj: vec![0.0; PATCH_W.max(PATCH_H)],
            mask: vec![0; n],
            label: vec![0; n],
            sizes: Vec::with_capacity(256),
            stack: Vec::with_capacity(n),
            eye_centres: [[0.0; 2]; 2],
            grads: Vec::with_capacity(PATCH_W * PATCH_H / 8),
            expected: [[0.0; 2]; N_GRADIENT],
            band: Vec::with_capacity(PATCH_W * (EYE_ROWS.1 - EYE_ROWS.0)),
        }
    }

    /// A detector with `config`.
    ///
    /// # Errors
    /// [`Error::InvalidConfig`] when `config` is out of range.
    pub fn with_config(config: GradientConfig) -> Result<Self> {
        config.validate()?;
        Ok(Self {
            config,
            ..Self::new()
        })
    }

    /// The settings.
    pub fn config(&self) -> &GradientConfig {
        &self.config
    }

    /// Finds the 32 points of the face in `face` (the detector's box convention) of `image`.
    /// `roll_hint_deg` is where the roll search starts (0 for a face seen for the first time).
    /// Where the parts found from the hint are weak, starting rolls out to ±45° from it are tried
    /// as well (up to six more searches), so a first detection finds a face tilted by up to about
    /// ±50°.
    ///
    /// # Errors
    /// [`Error::InvalidInput`] for an empty image or a box that is not finite and positive.
    pub fn detect(
        &mut self,
        image: &GrayImage,
        face: &Rect,
        roll_hint_deg: f32,
        out: &mut GradientPoints,
    ) -> Result<()> {
        self.detect_from(image, face, roll_hint_deg, Some(SETTLED_PARTS), out)
    }

    /// As [`GradientDetector::detect`] for a face tracked from the last frame, whose roll is
    /// the hint: no other starting roll is tried, which keeps a tracked frame to one search (a
    /// head that turns faster than about 10° a frame is found again by the next detection).
    ///
    /// # Errors
    /// As [`GradientDetector::detect`].
    pub fn detect_tracked(
        &mut self,
        image: &GrayImage,
        face: &Rect,
        roll_hint_deg: f32,
        out: &mut GradientPoints,
    ) -> Result<()> {
        self.detect_from(image, face, roll_hint_deg, None, out)
    }

    /// [`GradientDetector::detect`]; with `weak_parts`, other starts tried where the hint finds
    /// no eye pair or parts whose mean confidence is under it.
    fn detect_from(
        &mut self,
        image: &GrayImage,
        face: &Rect,
        roll_hint_deg: f32,
        weak_parts: Option<f32>,
        out: &mut GradientPoints,
    ) -> Result<()> {
        if !face.is_valid() || !roll_hint_deg.is_finite() {
            return Err(Error::InvalidInput(format!(
                "gradient detector: bad face box {face:?} or roll {roll_hint_deg}"
            )));
        }
        // The eyes found in the patch turned by the hint set the frame (roll; and scale and
        // place where the face is tilted) in which every part is then found.
        let hint = roll_hint_deg.to_radians();
        let (score, frame) = self.settle(image, face, Frame::of_box(face, hint), out)?;
        self.finish(image, face, frame, out)?;
        // A start more than about 10° from the face's roll finds no level pair of eyes, or pairs
        // an eye with a brow (a first detection of a tilted head, or a track that lost the turn).
        // Where the hint's answer is weak, starts turned either way from it are tried and the
        // answer whose parts are found most clearly is kept. Judged by the eye pair alone this
        // was measured worse on real faces (a brow or a shadow pairs up with an eye in a wrongly
        // turned patch); the other parts do not line up there.
        let weak = weak_parts.is_some_and(|w| score < SETTLED_SCORE || out.mean_confidence() < w);
        if weak {
            let mut best = (out.mean_confidence(), frame);
            // Rolls already judged: starts that settle on one of them are not finished again.
            let mut seen = [frame.roll; 1 + FALLBACK_TURNS_DEG.len()];
            let mut n_seen = 1;
            for turn in FALLBACK_TURNS_DEG {
                let start = Frame::of_box(face, hint + turn.to_radians());
                let (s, f) = self.settle(image, face, start, out)?;
                let same = |r: &f32| (r - f.roll).abs() < SAME_ROLL_DEG.to_radians();
                if s < SETTLED_SCORE || seen[..n_seen].iter().any(same) {
                    continue;
                }
                seen[n_seen] = f.roll;
                n_seen += 1;
                self.finish(image, face, f, out)?;
                let c = out.mean_confidence();
                if c > best.0 + FALLBACK_MARGIN {
                    best = (c, f);
                }
            }
            self.finish(image, face, best.1, out)?;
        }
        Ok(())
    }

    /// Finds every part in the patch of `frame` and writes the points (image pixels), their
    /// confidences and the roll to `out`.
    fn finish(
        &mut self,
        image: &GrayImage,
        face: &Rect,
        frame: Frame,
        out: &mut GradientPoints,
    ) -> Result<()> {
        let frame = frame.fitted(face);
        let mut conf = [0f32; N_GRADIENT];
        let mut pts = [[0f32; 2]; N_GRADIENT];
        let map = self.sample(image, &frame)?;
        self.eyes(&mut pts, &mut conf, true);
        self.expected = self.given_eyes();
        self.brows(&mut pts, &mut conf);
        self.nose(&mut pts, &mut conf);
        self.mouth(&mut pts, &mut conf);
        self.contour(&mut pts, &mut conf);
        // Each point moves from where the eyes' geometry expects it towards what its evidence
        // says, by its confidence squared: weak evidence cannot pull a point far from the
        // geometry. On real faces the parts' own evidence is weak next to the eyes' geometry:
        // on faces68 tuning faces the evidence alone is well behind the geometry alone, and
        // this blend about level with it; it is what finds the parts of faces unlike the
        // average (the synthetic faces' wide jaw and high brows).
        for (i, p) in pts.iter_mut().enumerate() {
            let prior = self.expected[i];
            // The eyes' own evidence is their centres, which the expected geometry already
            // holds; their corners and lids found from gradients measured worse than it.
            let k = if EYE_POINTS.contains(&i) {
                0.0
            } else {
                conf[i] * conf[i]
            };
            *p = [
                prior[0] + k * (p[0] - prior[0]),
                prior[1] + k * (p[1] - prior[1]),
            ];
        }
        for (o, p) in out.points.iter_mut().zip(&pts) {
            // Patch and image coordinates share the pixel convention: the map applies as is.
            let q = map.apply([p[0] as f64, p[1] as f64]);
            *o = [q[0] as f32, q[1] as f32];
        }
        out.confidence = conf;
        out.roll_deg = frame.roll.to_degrees();
        for (o, c) in out.eye_centres.iter_mut().zip(&self.eye_centres) {
            let q = map.apply([c[0] as f64, c[1] as f64]);
            *o = [q[0] as f32, q[1] as f32];
        }
        Ok(())
    }

    /// Finds the eyes in the patch of `frame`, then re-centres the frame on them (roll, scale,
    /// place) until the roll settles: eyes found in a patch turned by less than the face's roll
    /// under-read it, each eye's row being searched level. Returns how clearly a level pair of
    /// eyes stands in the last frame (the weaker eye's confidence, less the roll still left) and
    /// that frame.
    fn settle(
        &mut self,
        image: &GrayImage,
        face: &Rect,
        mut frame: Frame,
        out: &mut GradientPoints,
    ) -> Result<(f32, Frame)> {
        let (pts, conf) = (&mut out.points, &mut out.confidence);
        let mut score = 0.0;
        // Up to three rounds (a tilted face needs them; on faces68 validation three rounds and
        // two are about as accurate).
        for _ in 0..3 {
            // Only the rows the eye search reads: a third of the patch.
            let map = self.sample_rows(image, &frame, EYE_ROWS)?;
            self.eyes(pts, conf, false);
            let (r, l) = (eye_centre(pts, 0), eye_centre(pts, 1));
            let delta = (l[1] - r[1]).matan2(l[0] - r[0]);
            // Eyes much nearer or further apart than the frame's scale expects are not a pair.
            let expected = (mean_eye(1)[0] - mean_eye(0)[0]) * SCALE as f32;
            let ratio = (l[0] - r[0]).mhypot(l[1] - r[1]) / expected;
            let paired = (0.8..1.25).contains(&ratio);
            score = conf[14].min(conf[20])
                - delta.abs() / 45f32.to_radians()
                - if paired { 0.0 } else { 1.0 };
            if conf[14].min(conf[20]) <= PRIOR_CONFIDENCE
                || delta.abs() > 45f32.to_radians()
                || !paired
            {
                break;
            }
            let to_image = |p: [f32; 2]| {
                let q = map.apply([p[0] as f64, p[1] as f64]);
                [q[0] as f32, q[1] as f32]
            };
            let next = Frame::of_eyes(to_image(r), to_image(l));
            let settled = (next.roll - frame.roll).abs() < 1f32.to_radians();
            frame = next;
            if settled {
                break;
            }
        }
        // Where the eyes end nearly level the detector's box measures the face's place and size
        // better than two eye centres do; a tilted face's axis-aligned box does not. The roll
        // settles on frames placed on the eyes throughout: switching to the box's frame inside
        // the loop let a tilted head settle below the switch, short of its roll (and was less
        // accurate on faces68 tuning faces).
        if !frame.from_box && frame.roll.abs() < 12f32.to_radians() {
            frame = Frame::of_box(face, frame.roll);
        }
        Ok((score, frame))
    }

    /// Samples the canonical patch of `frame` and returns its map to the image.
    fn sample(&mut self, image: &GrayImage, frame: &Frame) -> Result<Affine> {
        self.sample_rows(image, frame, (0, PATCH_H))
    }

    /// Samples rows `rows.0..rows.1` of the canonical patch of `frame` (the others keep what they
    /// held) and returns the whole patch's map to the image.
    fn sample_rows(
        &mut self,
        image: &GrayImage,
        frame: &Frame,
        rows: (usize, usize),
    ) -> Result<Affine> {
        let (c, s) = (frame.roll.mcos() as f64, frame.roll.msin() as f64);
        let k = 1.0 / SCALE as f64;
        let (bw, bh) = (frame.w as f64, frame.h as f64);
        let [cx, cy] = frame.centre;
        // Patch pixel (px, py) → box units (u, v) → offset from the box centre in pixels →
        // turned by the roll about the centre.
        let (u0, v0) = (-(MARGIN_X as f64) - 0.5, -(MARGIN_TOP as f64) - 0.5);
        let (a, b) = (bw * k, bh * k);
        let m = [
            c * a,
            -s * b,
            cx as f64 + c * bw * u0 - s * bh * v0,
            s * a,
            c * b,
            cy as f64 + s * bw * u0 + c * bh * v0,
        ];
        let map = Affine { m };
        if rows == (0, PATCH_H) {
            sample(image, &map, PATCH_W, PATCH_H, &mut self.patch)?;
        } else {
            // The band's own map: the whole patch's, shifted down by the band's first row.
            let y0 = rows.0 as f64;
            let band = Affine {
                m: [m[0], m[1], m[2] + m[1] * y0, m[3], m[4], m[5] + m[4] * y0],
            };
            sample(image, &band, PATCH_W, rows.1 - rows.0, &mut self.band)?;
            self.patch.resize(PATCH_W * PATCH_H, 0);
            self.patch[rows.0 * PATCH_W..rows.1 * PATCH_W].copy_from_slice(&self.band);
        }
        Ok(map)
    }

    /// Double sigmoidal filtering and squared gradients over `r` (Alg. 1–2).
    fn prepare(&mut self, r: Region) {
        let g = self.config.sigmoid_gain;
        let (x0, x1) = (r.x0, r.x1);
        let (mut s, mut s2) = (0u32, 0u64);
        for y in r.y0..r.y1 {
            for &v in &self.patch[y * PATCH_W + x0..y * PATCH_W + x1] {
                s += u32::from(v);
                s2 += u64::from(v) * u64::from(v);
            }
        }
        let n = ((x1 - x0) * (r.y1 - r.y0)) as f32;
        let mean = s as f32 / n;
        let sd = (s2 as f32 / n - mean * mean).max(1.0).sqrt();
        // Both passes as `sigmoid(k·v + c)`: one multiply-add per pixel before the sigmoid.
        let (k, c) = (g / sd, -g * mean / sd);
        let (mut t, mut t2) = (0f32, 0f32);
        for y in r.y0..r.y1 {
            let row = y * PATCH_W;
            let (src, dst) = (
                &self.patch[row + x0..row + x1],
                &mut self.f[row + x0..row + x1],
            );
            for (d, &v) in dst.iter_mut().zip(src) {
                let v = sigmoid(k * v as f32 + c);
                *d = v;
                t += v;
                t2 += v * v;
            }
        }
        let mean = t / n;
        let sd = (t2 / n - mean * mean).max(1e-6).sqrt();
        let (k, c) = (g / sd, -g * mean / sd);
        for y in r.y0..r.y1 {
            let row = y * PATCH_W;
            for v in &mut self.f[row + x0..row + x1] {
                *v = sigmoid(k * *v + c);
            }
        }
        // Central differences inside the region; its border gets none (0).
        for y in r.y0..r.y1 {
            let row = y * PATCH_W;
            let inner_y = y > r.y0 && y + 1 < r.y1;
            self.ex[row + x0] = 0.0;
            self.ex[row + x1 - 1] = 0.0;
            for x in x0 + 1..x1.saturating_sub(1).max(x0 + 1) {
                let gx = 0.5 * (self.f[row + x + 1] - self.f[row + x - 1]);
                self.ex[row + x] = gx * gx;
            }
            if inner_y {
                let (up, here, down) = (row - PATCH_W, row, row + PATCH_W);
                for x in x0..x1 {
                    let gy = 0.5 * (self.f[down + x] - self.f[up + x]);
                    self.ey[here + x] = gy * gy;
                }
            } else {
                self.ey[row + x0..row + x1].fill(0.0);
            }
        }
    }

    /// Row projection over `r` of `what`, columns weighted by a Gaussian at `cx` (σ `sx`), into
    /// `proj[y0..y1]`.
    fn rows(&mut self, r: Region, what: Source, cx: f32, sx: f32) {
        let mut weights = [0f32; PATCH_W];
        for (x, w) in weights.iter_mut().enumerate().take(r.x1).skip(r.x0) {
            let d = (x as f32 + 0.5 - cx) / sx;
            *w = (-0.5 * d * d).mexp();
        }
        for y in r.y0..r.y1 {
            let row = y * PATCH_W;
            let s = (r.x0..r.x1)
                .zip(&weights[r.x0..r.x1])
                .map(|(x, w)| w * self.value(what, row + x))
                .sum();
            self.proj[y] = s;
        }
    }

    /// Column projection over `r` of `what`, rows weighted by a Gaussian at `cy` (σ `sy`), into
    /// `proj[x0..x1]`.
    fn cols(&mut self, r: Region, what: Source, cy: f32, sy: f32) {
        for x in r.x0..r.x1 {
            self.proj[x] = 0.0;
        }
        for y in r.y0..r.y1 {
            let d = (y as f32 + 0.5 - cy) / sy;
            let w = (-0.5 * d * d).mexp();
            for x in r.x0..r.x1 {
                self.proj[x] += w * self.value(what, y * PATCH_W + x);
            }
        }
    }

    #[inline]
    fn value(&self, what: Source, i: usize) -> f32 {
        match what {
            Source::Dark => {
                let d = 1.0 - self.f[i];
                d * d
            }
            Source::Ex => self.ex[i],
            Source::Ey => self.ey[i],
            Source::Raw => {
                let d = 1.0 - self.patch[i] as f32 / 255.0;
                d * d * d * d
            }
        }
    }

    /// The peak of `proj[lo..hi]` at or above `p` % of its maximum nearest to `expect`, with its
    /// contrast (peak over the range's mean, 0..1); `None` when the range is flat.
    fn peak(&self, lo: usize, hi: usize, p: f32, expect: f32) -> Option<(f32, f32)> {
        let s = &self.proj[lo..hi];
        let max = s.iter().fold(0f32, |m, &v| m.max(v));
        let mean = s.iter().sum::<f32>() / s.len().max(1) as f32;
        if max <= 1e-6 || max <= mean * 1.05 {
            return None;
        }
        let t = max * p / 100.0;
        // (position, score): nearest the expectation, stronger peaks preferred (4 pixels of
        // distance per full peak height).
        let mut best: Option<(f32, f32)> = None;
        for i in 0..s.len() {
            let left = i == 0 || s[i] >= s[i - 1];
            let right = i + 1 == s.len() || s[i] >= s[i + 1];
            if s[i] >= t && left && right {
                // Sub-pixel by a parabola through the neighbours.
                let off = if i > 0 && i + 1 < s.len() {
                    let (a, b, c) = (s[i - 1], s[i], s[i + 1]);
                    let den = a - 2.0 * b + c;
                    if den.abs() > 1e-9 {
                        (0.5 * (a - c) / den).clamp(-0.5, 0.5)
                    } else {
                        0.0
                    }
                } else {
                    0.0
                };
                let at = (lo + i) as f32 + 0.5 + off;
                let score = (at - expect).abs() - 4.0 * s[i] / max;
                if best.is_none_or(|(_, b)| score < b) {
                    best = Some((at, score));
                }
            }
        }
        let contrast = (1.0 - mean / max).clamp(0.0, 1.0);
        best.map(|(at, _)| (at, contrast))
    }

    /// The outermost positions of `proj[lo..hi]` at or above `p` % of its maximum, searching
    /// outwards from `centre`, as (left, right); `None` when flat.
    fn bounds(&self, lo: usize, hi: usize, p: f32, centre: f32) -> Option<(f32, f32)> {
        let s = &self.proj[lo..hi];
        let max = s.iter().fold(0f32, |m, &v| m.max(v));
        if max <= 1e-6 {
            return None;
        }
        let t = max * p / 100.0;
        let c = ((centre - lo as f32).max(0.0) as usize).min(s.len() - 1);
        // From the centre outwards, the last run over the threshold that still connects through
        // gaps of at most a few pixels.
        let gap = (SCALE / 20).max(2);
        let walk = |dir: isize| -> Option<usize> {
            let mut last = None;
            let mut miss = 0;
            let mut i = c as isize;
            while i >= 0 && (i as usize) < s.len() {
                if s[i as usize] >= t {
                    last = Some(i as usize);
                    miss = 0;
                } else if last.is_some() {
                    miss += 1;
                    if miss > gap {
                        break;
                    }
                }
                i += dir;
            }
            last
        };
        match (walk(-1), walk(1)) {
            (Some(a), Some(b)) => Some(((lo + a) as f32 + 0.5, (lo + b) as f32 + 0.5)),
            _ => None,
        }
    }

    /// Darkness-weighted centroid over `r` (sharpened: dark pixels count most).
    fn dark_centroid(&self, r: Region) -> Option<[f32; 2]> {
        self.centroid(r, Source::Dark)
    }

    /// Centroid over `r` weighted by the square of `what`, with the region's least value taken
    /// off first (so a uniform background adds nothing).
    fn centroid(&self, r: Region, what: Source) -> Option<[f32; 2]> {
        let mut floor = f32::MAX;
        for y in r.y0..r.y1 {
            for x in r.x0..r.x1 {
                floor = floor.min(self.value(what, y * PATCH_W + x));
            }
        }
        let (mut sx, mut sy, mut sw) = (0f32, 0f32, 0f32);
        for y in r.y0..r.y1 {
            for x in r.x0..r.x1 {
                let d = self.value(what, y * PATCH_W + x) - floor;
                let w = d * d;
                sx += w * (x as f32 + 0.5);
                sy += w * (y as f32 + 0.5);
                sw += w;
            }
        }
        (sw > 1e-6).then(|| [sx / sw, sy / sw])
    }

    /// The eyes: per eye the row of the strongest x-gradient energy near the expected row, the
    /// corners from the column projection of `Ex` over that row's band, the lids from `Ey` above
    /// and below the centre.
    fn eyes(
        &mut self,
        pts: &mut [[f32; 2]; N_GRADIENT],
        conf: &mut [f32; N_GRADIENT],
        precise: bool,
    ) {
        let p = self.config;
        for (eye, (outer, upper, inner, lower)) in
            [(14, 15, 16, 17), (20, 19, 18, 21)].into_iter().enumerate()
        {
            let cu = 0.5 * (MEAN[outer][0] + MEAN[inner][0]);
            let cv = 0.5 * (MEAN[outer][1] + MEAN[inner][1]);
            let (cx, cy) = (px(cu), py(cv));
            let s = SCALE as f32;
            let r = Region::new(cx - 0.17 * s, cy - 0.1 * s, cx + 0.17 * s, cy + 0.12 * s);
            self.prepare(r);
            self.rows(r, Source::Ex, cx, 0.07 * s);
            let row = self.peak(r.y0, r.y1, p.p_y, cy);
            let (row, c_row) = row.unwrap_or((cy, 0.0));
            // The eye's centre: where the most image gradients point away from (the iris and
            // the lids' dark outline are closed curves round it), darker places preferred.
            // Settling the roll needs only a rough centre: there the darkest blob near the row
            // found, by a centroid re-centred on itself, at a fraction of the cost.
            let c = if precise {
                self.gradient_centre(r, [cx, cy])
            } else {
                let mut c = [cx, row];
                for _ in 0..4 {
                    let w = Region::new(
                        c[0] - 0.1 * s,
                        c[1] - 0.05 * s,
                        c[0] + 0.1 * s,
                        c[1] + 0.05 * s,
                    );
                    match self.centroid(w, Source::Raw) {
                        Some(n) => c = n,
                        None => break,
                    }
                }
                c
            };
            let row = c[1];
            self.eye_centres[eye] = c;
            let band = 0.035 * s;
            let br = Region::new(r.x0 as f32, row - 2.0 * band, r.x1 as f32, row + 2.0 * band);
            self.cols(br, Source::Ex, row, band);
            let found = self.bounds(br.x0, br.x1, p.p_x, cx);
            let (l, rt) =
                found.unwrap_or((px(MEAN[outer.min(inner)][0]), px(MEAN[outer.max(inner)][0])));
            // Plausible width: 0.12–0.26 box widths.
            let width_ok = (rt - l) > 0.1 * s && (rt - l) < 0.28 * s;
            let c_bounds = if found.is_some() && width_ok {
                c_row.max(0.3)
            } else {
                0.5 * c_row
            };
            // Without clear corners, the mean eye's width about the eye's dark centre.
            let half = 0.5 * (MEAN[outer.max(inner)][0] - MEAN[outer.min(inner)][0]) * s;
            let (l, rt) = if width_ok {
                (l, rt)
            } else {
                (c[0] - half, c[0] + half)
            };
            let (xo, xi) = if outer < inner { (l, rt) } else { (rt, l) };
            let inside = Region::new(l + 2.0, row - band, rt - 2.0, row + band);
            let centre = self.dark_centroid(inside).unwrap_or([0.5 * (l + rt), row]);
            // The corners lie on the eye's axis: the dark centroid's row, which the iris and
            // lashes centre better than the gradient energy's peak.
            let row = centre[1];
            pts[outer] = [xo, row];
            pts[inner] = [xi, row];
            conf[outer] = c_bounds.max(PRIOR_CONFIDENCE * 0.5);
            conf[inner] = conf[outer];
            // Lids: Ey in the centre column band.
            let col = Region::new(centre[0] - 2.0, row - 0.08 * s, centre[0] + 3.0, row);
            self.rows(col, Source::Ey, centre[0], 2.0);
            let up = self.peak(col.y0, col.y1, p.p_y, row - 0.035 * s);
            let col2 = Region::new(centre[0] - 2.0, row, centre[0] + 3.0, row + 0.07 * s);
            self.rows(col2, Source::Ey, centre[0], 2.0);
            let down = self.peak(col2.y0, col2.y1, p.p_y, row + 0.02 * s);
            pts[upper] = [centre[0], up.map_or(row - 0.03 * s, |u| u.0)];
            pts[lower] = [centre[0], down.map_or(row + 0.02 * s, |d| d.0)];
            conf[upper] = up.map_or(PRIOR_CONFIDENCE, |u| u.1);
            conf[lower] = down.map_or(PRIOR_CONFIDENCE, |d| d.1);
        }
    }

    /// Where each point is expected given the eye centres found last (patch pixels): the linear
    /// map of [`geometry::GIVEN_EYES`] from the eyes' midpoint and distance in the patch, which
    /// the roll has levelled. A yawed or nodding face moves its eyes in its box, and every other
    /// part with them, so this places the parts far better than the mean face does (on faces68
    /// training faces kept out of the map's fit; `models/MODEL_CARD.md`, "Gradient landmark
    /// detector", compares the two on the validation split).
    fn given_eyes(&self) -> [[f32; 2]; N_GRADIENT] {
        let [r, l] = self.eye_centres;
        let s = SCALE as f32;
        let x = [
            1.0,
            0.5 * (r[0] + l[0]) / s - MARGIN_X,
            0.5 * (r[1] + l[1]) / s - MARGIN_TOP,
            (l[0] - r[0]) / s,
        ];
        let mut out = [[0f32; 2]; N_GRADIENT];
        for (o, w) in out.iter_mut().zip(&geometry::GIVEN_EYES) {
            let u: f32 = w[0].iter().zip(&x).map(|(a, b)| a * b).sum();
            let v: f32 = w[1].iter().zip(&x).map(|(a, b)| a * b).sum();
            *o = [px(u), py(v)];
        }
        out
    }

    /// The centre of a dark round feature in `r` by means of gradients (Timm and Barth, 2011):
    /// the place `c` that maximises the mean of `max(0, d·g)²` over the strong gradients `g`
    /// (unit vectors; strong: over the mean magnitude plus 0.3 deviations), `d` the unit vector
    /// from `c` to each, weighted by the darkness at `c`. `expect` (patch pixels) weighs
    /// candidates by a broad Gaussian, so the brow or hair above does not win on a tie.
    fn gradient_centre(&mut self, r: Region, expect: [f32; 2]) -> [f32; 2] {
        let s = SCALE as f32;
        self.grads.clear();
        let (mut sum, mut sum2) = (0f32, 0f32);
        for y in r.y0 + 1..r.y1 - 1 {
            for x in r.x0 + 1..r.x1 - 1 {
                let at = |xx: usize, yy: usize| f32::from(self.patch[yy * PATCH_W + xx]);
                let gx = 0.5 * (at(x + 1, y) - at(x - 1, y));
                let gy = 0.5 * (at(x, y + 1) - at(x, y - 1));
                let m = gx.mhypot(gy);
                sum += m;
                sum2 += m * m;
                self.grads.push([x as f32 + 0.5, y as f32 + 0.5, gx, gy, m]);
            }
        }
        let n = self.grads.len().max(1) as f32;
        let mean = sum / n;
        let t = mean + 0.3 * (sum2 / n - mean * mean).max(0.0).sqrt();
        self.grads.retain(|g| g[4] > t && g[4] > 1e-3);
        for g in &mut self.grads {
            g[2] /= g[4];
            g[3] /= g[4];
        }
        let (sx, sy) = (0.12 * s, 0.07 * s);
        let score = |x: usize, y: usize| {
            let (cx, cy) = (x as f32 + 0.5, y as f32 + 0.5);
            let mut acc = 0f32;
            for g in &self.grads {
                let (dx, dy) = (g[0] - cx, g[1] - cy);
                let d2 = dx * dx + dy * dy;
                if d2 < 0.25 {
                    continue;
                }
                let dot = (dx * g[2] + dy * g[3]).max(0.0);
                acc += dot * dot / d2;
            }
            let dark = 1.0 - f32::from(self.patch[y * PATCH_W + x]) / 255.0;
            let (ex, ey) = ((cx - expect[0]) / sx, (cy - expect[1]) / sy);
            acc * dark * (-0.5 * (ex * ex + ey * ey)).mexp()
        };
        // Every second pixel, then the best one's neighbours: the objective is smooth at a
        // pixel's scale, and this is a quarter of the work.
        let mut best = (f32::MIN, (r.x0 + 1, r.y0 + 1));
        for y in (r.y0 + 1..r.y1 - 1).step_by(2) {
            for x in (r.x0 + 1..r.x1 - 1).step_by(2) {
                let v = score(x, y);
                if v > best.0 {
                    best = (v, (x, y));
                }
            }
        }
        let (bx, by) = best.1;
        for y in by.saturating_sub(1).max(r.y0 + 1)..(by + 2).min(r.y1 - 1) {
            for x in bx.saturating_sub(1).max(r.x0 + 1)..(bx + 2).min(r.x1 - 1) {
                let v = score(x, y);
                if v > best.0 {
                    best = (v, (x, y));
                }
            }
        }
        [best.1.0 as f32 + 0.5, best.1.1 as f32 + 0.5]
    }

    /// The brows: per brow the darkest row above its eye, the ends from the column projection of
    /// the darkness over that row's band within the expected span.
    fn brows(&mut self, pts: &mut [[f32; 2]; N_GRADIENT], conf: &mut [f32; N_GRADIENT]) {
        let p = self.config;
        let s = SCALE as f32;
        for (eye_outer, eye_inner, outer, middle, inner) in
            [(14, 16, 8, 9, 10), (20, 18, 13, 12, 11)]
        {
            let eo = pts[eye_outer];
            let ei = pts[eye_inner];
            let row = 0.5 * (eo[1] + ei[1]);
            let cx = 0.5 * (eo[0] + ei[0]);
            let lo_x = eo[0].min(ei[0]) - 0.1 * s;
            let hi_x = eo[0].max(ei[0]) + 0.07 * s;
            let e = &self.expected;
            let expect = (e[outer][1] + e[middle][1] + e[inner][1]) / 3.0;
            let r = Region::new(lo_x, row - 0.24 * s, hi_x, row - 0.05 * s);
            self.prepare(r);
            self.rows(r, Source::Dark, cx, 0.08 * s);
            let (brow, c_row) = self
                .peak(r.y0, r.y1, p.p_y, expect)
                .unwrap_or((expect, 0.0));
            let band = 0.03 * s;
            let br = Region::new(
                r.x0 as f32,
                brow - 2.0 * band,
                r.x1 as f32,
                brow + 2.0 * band,
            );
            self.cols(br, Source::Dark, brow, band);
            let found = self.bounds(br.x0, br.x1, p.p_x, cx);
            let (mut l, mut rt) = found.unwrap_or((lo_x + 0.04 * s, hi_x - 0.04 * s));
            // The expected geometry bounds the brow: no further out than 0.1 box beyond the eye
            // corner, and not across the face's centre line.
            l = l.max(lo_x);
            rt = rt.min(hi_x);
            let ok = found.is_some() && rt - l > 0.12 * s;
            let c = if ok { c_row.max(0.3) } else { PRIOR_CONFIDENCE };
            let (xo, xi) = if eo[0] < ei[0] { (l, rt) } else { (rt, l) };
            for (k, x) in [(outer, xo), (middle, 0.5 * (xo + xi)), (inner, xi)] {
                let col = Region::new(x - 2.0, brow - 0.06 * s, x + 3.0, brow + 0.06 * s);
                let y = self.dark_centroid(col).map_or(brow, |q| q[1]);
                pts[k] = [x, y];
                conf[k] = c;
            }
        }
    }

    /// The nose: the nostrils' row (the darkest below the eyes, near the expected depth), the
    /// wings from the column projection of `Ex` over it, the tip and the subnasale on the line
    /// between the eyes' midpoint and the nostrils.
    fn nose(&mut self, pts: &mut [[f32; 2]; N_GRADIENT], conf: &mut [f32; N_GRADIENT]) {
        let p = self.config;
        let (r_eye, l_eye) = (eye_centre(pts, 0), eye_centre(pts, 1));
        let cx = 0.5 * (r_eye[0] + l_eye[0]);
        let ey = 0.5 * (r_eye[1] + l_eye[1]);
        let d = (l_eye[0] - r_eye[0]).abs().max(0.2 * SCALE as f32);
        let r = Region::new(cx - 0.45 * d, ey + 0.45 * d, cx + 0.45 * d, ey + 0.95 * d);
        self.prepare(r);
        self.rows(r, Source::Dark, cx, 0.2 * d);
        let expect = 0.5 * (self.expected[23][1] + self.expected[25][1]);
        let cx = self.expected[24][0];
        let (row, c_row) = self
            .peak(r.y0, r.y1, p.p_y, expect)
            .unwrap_or((expect, 0.0));
        let band = 0.06 * d;
        let br = Region::new(r.x0 as f32, row - 2.0 * band, r.x1 as f32, row + 2.0 * band);
        self.cols(br, Source::Ex, row, band);
        let found = self.bounds(br.x0, br.x1, p.p_x, cx);
        let (l, rt) = found.unwrap_or((cx - 0.24 * d, cx + 0.24 * d));
        let ok = found.is_some() && rt - l > 0.25 * d && rt - l < 0.8 * d;
        let (l, rt) = if ok {
            (l, rt)
        } else {
            (cx - 0.24 * d, cx + 0.24 * d)
        };
        let c = if ok { c_row.max(0.3) } else { PRIOR_CONFIDENCE };
        let mid = 0.5 * (l + rt);
        pts[23] = [l, row];
        pts[25] = [rt, row];
        pts[24] = [mid, row + 0.07 * d];
        pts[22] = [mid, row - 0.12 * d];
        conf[23] = c;
        conf[25] = c;
        conf[24] = c * 0.8;
        conf[22] = c * 0.6;
    }

    /// The mouth: the mouth line (the darkest row below the nose), the corners from the column
    /// projection of `Ex` over it, the lips' outer and inner edges from `Ey` in the centre column.
    fn mouth(&mut self, pts: &mut [[f32; 2]; N_GRADIENT], conf: &mut [f32; N_GRADIENT]) {
        let p = self.config;
        let (r_eye, l_eye) = (eye_centre(pts, 0), eye_centre(pts, 1));
        let d = (l_eye[0] - r_eye[0]).abs().max(0.2 * SCALE as f32);
        let cx = pts[24][0];
        let nose = pts[24][1];
        let r = Region::new(cx - 0.7 * d, nose + 0.12 * d, cx + 0.7 * d, nose + 0.75 * d);
        self.prepare(r);
        self.rows(r, Source::Dark, cx, 0.25 * d);
        let expect = 0.5 * (self.expected[26][1] + self.expected[28][1]);
        let (row, c_row) = self
            .peak(r.y0, r.y1, p.p_y, expect)
            .unwrap_or((expect, 0.0));
        // The lips darken a band; the line where they meet is the darkest row of the unfiltered
        // patch within it.
        let near = Region::new(cx - 0.3 * d, row - 0.12 * d, cx + 0.3 * d, row + 0.12 * d);
        self.rows(near, Source::Raw, cx, 0.2 * d);
        let row = self.peak(near.y0, near.y1, p.p_y, row).map_or(row, |q| q.0);
        let band = 0.06 * d;
        let br = Region::new(r.x0 as f32, row - 2.0 * band, r.x1 as f32, row + 2.0 * band);
        self.cols(br, Source::Ex, row, band);
        let found = self.bounds(br.x0, br.x1, p.p_x, cx);
        let (l, rt) = found.unwrap_or((cx - 0.4 * d, cx + 0.4 * d));
        let ok = found.is_some() && rt - l > 0.4 * d && rt - l < 1.3 * d;
        let (l, rt) = if ok {
            (l, rt)
        } else {
            (cx - 0.4 * d, cx + 0.4 * d)
        };
        let c = if ok { c_row.max(0.3) } else { PRIOR_CONFIDENCE };
        let mid = 0.5 * (l + rt);
        pts[26] = [l, row];
        pts[28] = [rt, row];
        conf[26] = c;
        conf[28] = c;
        let edge = |this: &mut Self, from: f32, to: f32, expect: f32| {
            let col = Region::new(mid - 2.0, from, mid + 3.0, to);
            this.rows(col, Source::Ey, mid, 2.0);
            this.peak(col.y0, col.y1, p.p_y, expect)
        };
        let top = edge(self, row - 0.3 * d, row - 0.04 * d, row - 0.15 * d);
        let bottom = edge(self, row + 0.05 * d, row + 0.35 * d, row + 0.2 * d);
        let inner_top = edge(self, row - 0.08 * d, row, row - 0.01 * d);
        let inner_bottom = edge(self, row, row + 0.1 * d, row + 0.02 * d);
        for (k, e, dflt) in [
            (27, top, row - 0.15 * d),
            (29, bottom, row + 0.2 * d),
            (30, inner_top, row),
            (31, inner_bottom, row + 0.02 * d),
        ] {
            pts[k] = [mid, e.map_or(dflt, |e| e.0)];
            conf[k] = e.map_or(PRIOR_CONFIDENCE, |e| e.1.max(0.3) * c.max(0.3));
        }
    }

    /// The contour (Alg. 5): the forehead centre from the expected geometry; cheeks, facial corners and
    /// chin sides on the face's edge (`Ex` binarised at `p_x` %, clusters shorter than a tenth of
    /// the face removed by connected components) nearest the expected place on their row; the
    /// chin bottom from the row projection of `Ey` below the mouth.
    fn contour(&mut self, pts: &mut [[f32; 2]; N_GRADIENT], conf: &mut [f32; N_GRADIENT]) {
        let p = self.config;
        let s = SCALE as f32;
        let (r_eye, l_eye) = (eye_centre(pts, 0), eye_centre(pts, 1));
        let cx = 0.5 * (r_eye[0] + l_eye[0]);
        let ey = 0.5 * (r_eye[1] + l_eye[1]);
        let d = (l_eye[0] - r_eye[0]).abs().max(0.2 * s);
        let ex = self.expected;
        let expect = |i: usize| ex[i];
        // The forehead shows no edge of its own: the geometry places it.
        pts[0] = ex[0];
        conf[0] = PRIOR_CONFIDENCE;
        // Chin bottom: Ey below the mouth in the centre columns.
        let mouth = 0.5 * (pts[26][1] + pts[28][1]);
        let e8 = expect(7);
        let r = Region::new(
            cx - 0.25 * d,
            mouth + 0.25 * d,
            cx + 0.25 * d,
            e8[1] + 0.3 * d,
        );
        self.prepare(r);
        self.rows(r, Source::Ey, cx, 0.15 * d);
        match self.peak(r.y0, r.y1, p.p_y, e8[1]) {
            Some((y, c)) => {
                pts[7] = [cx, y];
                conf[7] = c.max(0.3);
            }
            None => {
                pts[7] = e8;
                conf[7] = PRIOR_CONFIDENCE;
            }
        }
        // The sides: binarised Ex over the face's sides, short clusters removed. (Two bands,
        // one per side, leaving out the middle, were no faster and less accurate on the
        // contour.)
        let r = Region::new(cx - 1.3 * d, ey, cx + 1.3 * d, pts[7][1] + 0.1 * d);
        self.prepare(r);
        let mut max = 0f32;
        for y in r.y0..r.y1 {
            for &v in &self.ex[y * PATCH_W + r.x0..y * PATCH_W + r.x1] {
                max = max.max(v);
            }
        }
        let t = max * p.p_x / 100.0;
        for y in r.y0..r.y1 {
            let row = y * PATCH_W;
            for x in r.x0..r.x1 {
                self.mask[row + x] = u8::from(max > 1e-6 && self.ex[row + x] >= t);
            }
        }
        self.remove_short_clusters(r, (0.1 * d).max(3.0) as u32);
        for i in [1, 2, 3, 4, 5, 6] {
            let e = expect(i);
            let y = (e[1].max(r.y0 as f32 + 0.5) as usize).min(r.y1 - 1);
            // The edge pixel on this row (± 1 row) nearest the expected x, within 0.4 eye
            // distances.
            let mut best: Option<(f32, f32)> = None;
            for yy in y.saturating_sub(1).max(r.y0)..=(y + 1).min(r.y1 - 1) {
                for x in r.x0..r.x1 {
                    if self.mask[yy * PATCH_W + x] != 0 {
                        let dist = (x as f32 + 0.5 - e[0]).abs();
                        if dist < 0.4 * d && best.is_none_or(|(b, _)| dist < b) {
                            best = Some((dist, x as f32 + 0.5));
                        }
                    }
                }
            }
            match best {
                Some((dist, x)) => {
                    pts[i] = [x, e[1]];
                    conf[i] = (1.0 - dist / (0.4 * d)).clamp(0.3, 1.0);
                }
                None => {
                    pts[i] = e;
                    conf[i] = PRIOR_CONFIDENCE;
                }
            }
        }
    }

    /// Clears the mask's 8-connected clusters in `r` with fewer than `min` pixels.
    fn remove_short_clusters(&mut self, r: Region, min: u32) {
        for y in r.y0..r.y1 {
            for x in r.x0..r.x1 {
                self.label[y * PATCH_W + x] = 0;
            }
        }
        self.sizes.clear();
        for y in r.y0..r.y1 {
            for x in r.x0..r.x1 {
                let i = y * PATCH_W + x;
                if self.mask[i] == 0 || self.label[i] != 0 {
                    continue;
                }
                self.sizes.push(0);
                let id = self.sizes.len() as u32;
                self.stack.clear();
                self.stack.push(i);
                self.label[i] = id;
                while let Some(j) = self.stack.pop() {
                    self.sizes[id as usize - 1] += 1;
                    let (jx, jy) = (j % PATCH_W, j / PATCH_W);
                    for (dx, dy) in NEIGHBOURS {
                        let (nx, ny) = (jx as isize + dx, jy as isize + dy);
                        if nx < r.x0 as isize
                            || ny < r.y0 as isize
                            || nx >= r.x1 as isize
                            || ny >= r.y1 as isize
                        {
                            continue;
                        }
                        let n = ny as usize * PATCH_W + nx as usize;
                        if self.mask[n] != 0 && self.label[n] == 0 {
                            self.label[n] = id;
                            self.stack.push(n);
                        }
                    }
                }
            }
        }
        for y in r.y0..r.y1 {
            for x in r.x0..r.x1 {
                let i = y * PATCH_W + x;
                if self.label[i] != 0 && self.sizes[self.label[i] as usize - 1] < min {
                    self.mask[i] = 0;
                }
            }
        }
    }
}

const NEIGHBOURS: [(isize, isize); 8] = [
    (-1, -1),
    (0, -1),
    (1, -1),
    (-1, 0),
    (1, 0),
    (-1, 1),
    (0, 1),
    (1, 1),
];

/// What a projection sums.
#[derive(Debug, Clone, Copy)]
enum Source {
    /// Squared darkness of the filtered image, `(1 − f)²`.
    Dark,
    Ex,
    Ey,
    /// Darkness of the unfiltered patch, to the fourth power (the darkest rows stand out).
    Raw,
}

/// A sigmoid without `exp`: `½ + ½·v / (1 + |v|)`, monotone from 0 to 1 with slope ½ at 0 like
/// the logistic's ¼·2; it runs twice on every pixel of every search region, where the logistic's
/// `exp` was most of the detector's time.
#[inline]
fn sigmoid(v: f32) -> f32 {
    0.5 + 0.5 * v / (1.0 + v.abs())
}

/// The centre of eye `which` (0 right, 1 left) from its corners.
fn eye_centre(pts: &[[f32; 2]; N_GRADIENT], which: usize) -> [f32; 2] {
    let (a, b) = if which == 0 { (14, 16) } else { (18, 20) };
    [0.5 * (pts[a][0] + pts[b][0]), 0.5 * (pts[a][1] + pts[b][1])]
}

mod geometry;

#[cfg(test)]
mod tests;

//! Tracking quality with reasons an app can act on ("more light", "come closer", "hold still").
//!
//! Per face, each measurement is turned into a factor in 0..1 that is 0.5 exactly at its
//! threshold ([`QualityConfig`]) and moves linearly to 0 or 1 over the measurement's width; a
//! reason is listed when its factor is below 0.5, and the face's score is the product of the
//! factors. The measurements, all cheap (a fixed grid of samples, whatever the face's size):
//!
//! | reason | measurement |
//! |---|---|
//! | [`QualityReason::Dark`] | mean luma over a grid of samples of the face's inner box |
//! | [`QualityReason::Overexposed`] | fraction of those samples at or above [`SATURATED_LUMA`] |
//! | [`QualityReason::Blurred`] | sharpness: mean absolute luma step between neighbours at 1/96 of the face's size, over the samples' standard deviation; below an absolute bar, or below a fraction of the same face's recent frames |
//! | [`QualityReason::Small`] | the larger side of the 68 landmarks' box, pixels |
//! | [`QualityReason::PartlyOutside`] | fraction of that box's area outside the frame |
//! | [`QualityReason::Turned`] | the fit's head-frame yaw and pitch |
//! | [`QualityReason::Occluded`] | M3 level 1's face probability on the region, and the fit's RMS residual over the eye distance |
//!
//! The frame has reasons of its own, from the whole frame: dark, overexposed and blurred (against
//! the recent frames only: a scene has no absolute sharpness), [`QualityReason::NoFace`] and
//! [`QualityReason::Lost`] (a face tracked on the previous frame is gone).

use crate::fit::FaceFit;
use crate::image::{GrayImage, Rect};
use crate::landmarks::FaceLandmarks;
use serde::{Deserialize, Serialize};

/// Luma at or above which a sample counts as saturated.
pub const SATURATED_LUMA: u8 = 250;

/// Samples per side of the face's (and the frame's) measuring grid.
const GRID: usize = 32;

/// Weight of a new frame in a track's reference sharpness (an exponential average over about
/// ten frames).
const SHARPNESS_EMA: f32 = 0.1;

/// Frames of a track (or of the stream) before the relative blur test applies.
const SHARPNESS_WARMUP: u32 = 3;

/// Why a face or a frame is poor. Names (`name`) are CONTRACT's.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum QualityReason {
    /// Too little light: mean luma below [`QualityConfig::dark_luma`].
    Dark,
    /// Too much light: more than [`QualityConfig::overexposed_fraction`] of the samples saturated.
    Overexposed,
    /// Motion or focus blur: sharpness below [`QualityConfig::min_sharpness`], or below
    /// [`QualityConfig::blur_drop`] × the recent frames'.
    Blurred,
    /// The face is smaller than [`QualityConfig::min_face_px`].
    Small,
    /// More than [`QualityConfig::max_outside_fraction`] of the face is outside the frame.
    PartlyOutside,
    /// The head is turned past [`QualityConfig::max_yaw_deg`] or [`QualityConfig::max_pitch_deg`].
    Turned,
    /// The landmarks are unsure: low face probability or a fit that does not agree with them
    /// (a hand, a mask, hair over the face).
    Occluded,
    /// The frame has no face (frame reasons only).
    NoFace,
    /// A face tracked on the previous frame is gone (frame reasons only).
    Lost,
}

impl QualityReason {
    /// Every reason, in CONTRACT's order.
    pub const ALL: [QualityReason; 9] = [
        QualityReason::Dark,
        QualityReason::Overexposed,
        QualityReason::Blurred,
        QualityReason::Small,
        QualityReason::PartlyOutside,
        QualityReason::Turned,
        QualityReason::Occluded,
        QualityReason::NoFace,
        QualityReason::Lost,
    ];

    /// The snake_case name CONTRACT uses.
    pub fn name(self) -> &'static str {
        match self {
            QualityReason::Dark => "dark",
            QualityReason::Overexposed => "overexposed",
            QualityReason::Blurred => "blurred",
            QualityReason::Small => "small",
            QualityReason::PartlyOutside => "partly_outside",
            QualityReason::Turned => "turned",
            QualityReason::Occluded => "occluded",
            QualityReason::NoFace => "no_face",
            QualityReason::Lost => "lost",
        }
    }

    fn bit(self) -> u16 {
        1 << (self as u16)
    }
}

/// A set of [`QualityReason`]s (no allocation).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Hash)]
pub struct QualityReasons(u16);

impl QualityReasons {
    /// No reason.
    pub const NONE: Self = Self(0);

    /// Adds `r`.
    pub fn insert(&mut self, r: QualityReason) {
        self.0 |= r.bit();
    }

    /// Whether `r` is in the set.
    pub fn contains(self, r: QualityReason) -> bool {
        self.0 & r.bit() != 0
    }

    /// Whether the set is empty.
    pub fn is_empty(self) -> bool {
        self.0 == 0
    }

    /// The reasons, in [`QualityReason::ALL`]'s order.
    pub fn iter(self) -> impl Iterator<Item = QualityReason> {
        QualityReason::ALL
            .into_iter()
            .filter(move |r| self.contains(*r))
    }
}

/// A face's quality: the score and the reasons that lower it.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct FaceQuality {
    /// 0..1: the product of every measurement's factor (0.5 at its threshold).
    pub score: f32,
    /// The measurements past their thresholds.
    pub reasons: QualityReasons,
    /// The raw measurements, for an app that sets its own bars.
    pub measures: QualityMeasures,
}

/// What [`FaceQuality`] was decided on.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct QualityMeasures {
    /// Mean luma of the face's inner box, 0..255.
    pub mean_luma: f32,
    /// Fraction of its samples at or above [`SATURATED_LUMA`].
    pub saturated: f32,
    /// Sharpness (see the module's table).
    pub sharpness: f32,
    /// The face's recent sharpness (the reference of the relative blur test; this frame's own
    /// where the track is new).
    pub reference_sharpness: f32,
    /// Larger side of the landmarks' box, pixels.
    pub face_px: f32,
    /// Fraction of that box outside the frame.
    pub outside: f32,
}

/// Thresholds of the quality reasons. Every field has a default (`#[serde(default)]`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct QualityConfig {
    /// Mean luma (0..255) below which a face or frame is dark.
    pub dark_luma: f32,
    /// Fraction of saturated samples above which a face or frame is overexposed.
    pub overexposed_fraction: f32,
    /// Sharpness below which a face is blurred whatever its past.
    pub min_sharpness: f32,
    /// A face (or frame) is blurred when its sharpness falls below this fraction of its recent
    /// frames'.
    pub blur_drop: f32,
    /// Larger side of the landmarks' box (pixels) below which a face is small.
    pub min_face_px: f32,
    /// Fraction of the face's box outside the frame above which it is partly outside.
    pub max_outside_fraction: f32,
    /// Head-frame yaw (degrees, either way) past which the head is turned.
    pub max_yaw_deg: f32,
    /// Head-frame pitch (degrees, either way) past which the head is turned.
    pub max_pitch_deg: f32,
    /// M3 level 1's face probability below which the face is occluded.
    pub min_face_probability: f32,
    /// The fit's RMS residual over the outer-eye distance above which the face is occluded.
    pub max_fit_residual: f32,
}

impl Default for QualityConfig {
    fn default() -> Self {
        Self {
            dark_luma: 40.0,
            overexposed_fraction: 0.25,
            min_sharpness: 0.08,
            blur_drop: 0.6,
            min_face_px: 64.0,
            max_outside_fraction: 0.1,
            max_yaw_deg: 45.0,
            max_pitch_deg: 30.0,
            min_face_probability: 0.7,
            max_fit_residual: 0.06,
        }
    }
}

impl QualityConfig {
    /// Checks every field's range.
    ///
    /// # Errors
    /// [`crate::Error::InvalidConfig`] naming the first bad field.
    pub fn validate(&self) -> crate::Result<()> {
        let checks: [(&str, f32, f32, f32); 10] = [
            ("dark_luma", self.dark_luma, 0.0, 255.0),
            ("overexposed_fraction", self.overexposed_fraction, 0.0, 1.0),
            ("min_sharpness", self.min_sharpness, 0.0, 100.0),
            ("blur_drop", self.blur_drop, 0.0, 1.0),
            ("min_face_px", self.min_face_px, 0.0, 1e6),
            ("max_outside_fraction", self.max_outside_fraction, 0.0, 1.0),
            ("max_yaw_deg", self.max_yaw_deg, 0.0, 180.0),
            ("max_pitch_deg", self.max_pitch_deg, 0.0, 180.0),
            ("min_face_probability", self.min_face_probability, 0.0, 1.0),
            ("max_fit_residual", self.max_fit_residual, 0.0, 100.0),
        ];
        for (name, v, lo, hi) in checks {
            if !(v.is_finite() && (lo..=hi).contains(&v)) {
                return Err(crate::Error::InvalidConfig(format!(
                    "quality.{name} must be in {lo}..={hi}, got {v}"
                )));
            }
        }
        Ok(())
    }
}

/// Luma statistics of a grid of samples: mean, saturated fraction, sharpness.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LumaStats {
    /// Mean luma.
    pub mean: f32,
    /// Fraction at or above [`SATURATED_LUMA`].
    pub saturated: f32,
    /// Mean absolute step to the neighbours `step` pixels right and down, over the samples'
    /// standard deviation (at least 4 luma levels, so flat noise does not read sharp).
    pub sharpness: f32,
}

/// [`LumaStats`] of `image` over `region` (clipped to the image), sampled on a
/// [`GRID`]×[`GRID`] grid, with neighbour steps of `step` pixels. `None` when the clipped region
/// is empty.
pub fn luma_stats(image: &GrayImage, region: &Rect, step: usize) -> Option<LumaStats> {
    let (w, h) = (image.width(), image.height());
    let finite = [region.x, region.y, region.w, region.h]
        .iter()
        .all(|v| v.is_finite());
    if w < 2 || h < 2 || !finite {
        return None;
    }
    let step = step.max(1);
    let x0 = region.x.max(0.0);
    let y0 = region.y.max(0.0);
    let x1 = (region.x + region.w).min((w - 1) as f32);
    let y1 = (region.y + region.h).min((h - 1) as f32);
    if !(x1 > x0 && y1 > y0) {
        return None;
    }
    let data = image.data();
    let (mut sum, mut sum2, mut sat, mut steps) = (0u64, 0u64, 0u32, 0u64);
    let n = (GRID * GRID) as u64;
    for gy in 0..GRID {
        let y = (y0 + (y1 - y0) * (gy as f32 + 0.5) / GRID as f32) as usize;
        let yd = (y + step).min(h - 1);
        for gx in 0..GRID {
            let x = (x0 + (x1 - x0) * (gx as f32 + 0.5) / GRID as f32) as usize;
            let xr = (x + step).min(w - 1);
            let v = data[y * w + x];
            let (r, d) = (data[y * w + xr], data[yd * w + x]);
            sum += u64::from(v);
            sum2 += u64::from(v) * u64::from(v);
            sat += u32::from(v >= SATURATED_LUMA);
            steps += u64::from(v.abs_diff(r)) + u64::from(v.abs_diff(d));
        }
    }
    let mean = sum as f32 / n as f32;
    let var = (sum2 as f32 / n as f32 - mean * mean).max(0.0);
    let sd = var.sqrt().max(4.0);
    Some(LumaStats {
        mean,
        saturated: sat as f32 / n as f32,
        sharpness: steps as f32 / (2.0 * n as f32) / sd,
    })
}

/// The factor of a measurement `m` that is good above `threshold`: 0.5 there, 0 at
/// `threshold - width`, 1 at `threshold + width`.
fn above(m: f32, threshold: f32, width: f32) -> f32 {
    (0.5 + (m - threshold) / (2.0 * width.max(1e-6))).clamp(0.0, 1.0)
}

/// The factor of a measurement that is good below `threshold`.
fn below(m: f32, threshold: f32, width: f32) -> f32 {
    above(-m, -threshold, width)
}

/// A track's (or the stream's) recent sharpness.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SharpnessHistory {
    reference: f32,
    frames: u32,
}

impl SharpnessHistory {
    /// Forgets the history (a new track or stream).
    pub fn reset(&mut self) {
        *self = Self::default();
    }

    /// The factor of `sharpness` against the history (1 while too short to judge), then
    /// `sharpness` joins the history unless it is blurred. Returns (factor, reference).
    fn judge(&mut self, sharpness: f32, drop: f32) -> (f32, f32) {
        if self.frames == 0 {
            self.reference = sharpness;
        }
        let reference = self.reference;
        let f = if self.frames >= SHARPNESS_WARMUP && reference > 0.0 {
            above(sharpness / reference, drop, 0.5 * drop)
        } else {
            1.0
        };
        if f >= 0.5 {
            self.reference += SHARPNESS_EMA * (sharpness - self.reference);
            self.frames = self.frames.saturating_add(1);
        }
        (f, reference)
    }
}

/// What a face's quality is judged on beyond the image.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FaceEvidence<'a> {
    /// The 68 landmarks, image pixels.
    pub points: &'a [[f32; 2]],
    /// Head-frame yaw and pitch of the fit, degrees.
    pub yaw_pitch_deg: (f32, f32),
    /// M3 level 1's face probability (1 where the estimator has none).
    pub face_probability: f32,
    /// The fit's RMS reprojection residual, pixels.
    pub fit_rms_px: f32,
}

impl<'a> FaceEvidence<'a> {
    /// The evidence of a face's landmarks and fit. `m3`: the landmarks are M3's, whose face
    /// probability counts; the gradient detector's "probability" is its points' mean confidence,
    /// which its own face check already holds to a bar of its own.
    pub fn of(landmarks: &'a FaceLandmarks, fit: &FaceFit, m3: bool) -> Self {
        let (yaw, pitch, _) = fit.pose.euler_deg();
        Self {
            points: &landmarks.points,
            yaw_pitch_deg: (yaw as f32, pitch as f32),
            face_probability: if m3 { landmarks.face_prob } else { 1.0 },
            fit_rms_px: fit.report.rms_px as f32,
        }
    }
}

/// The quality of one face in `image`, its sharpness judged against `history` (which it
/// updates).
pub fn face_quality(
    image: &GrayImage,
    face: &FaceEvidence<'_>,
    config: &QualityConfig,
    history: &mut SharpnessHistory,
) -> FaceQuality {
    let b = Rect::bounding(face.points);
    let face_px = b.w.max(b.h).max(0.0);
    let (iw, ih) = (image.width() as f32, image.height() as f32);
    let inside_w = ((b.x + b.w).min(iw) - b.x.max(0.0)).max(0.0);
    let inside_h = ((b.y + b.h).min(ih) - b.y.max(0.0)).max(0.0);
    let area = (b.w * b.h).max(1e-6);
    let outside = (1.0 - inside_w * inside_h / area).clamp(0.0, 1.0);
    // The inner box: the face without the background around the jaw and temples.
    let inner = Rect::new(b.x + 0.15 * b.w, b.y + 0.15 * b.h, 0.7 * b.w, 0.7 * b.h);
    let step = (face_px / 96.0).round().max(1.0) as usize;
    let stats = luma_stats(image, &inner, step).unwrap_or_default();
    let eye = {
        let (r, l) = (face.points[36], face.points[45]);
        ((l[0] - r[0]).powi(2) + (l[1] - r[1]).powi(2))
            .sqrt()
            .max(1.0)
    };
    let c = config;
    let (rel, reference) = history.judge(stats.sharpness, c.blur_drop);
    let factors = [
        (QualityReason::Dark, above(stats.mean, c.dark_luma, 20.0)),
        (
            QualityReason::Overexposed,
            below(stats.saturated, c.overexposed_fraction, 0.15),
        ),
        (
            QualityReason::Blurred,
            above(stats.sharpness, c.min_sharpness, 0.5 * c.min_sharpness).min(rel),
        ),
        (
            QualityReason::Small,
            above(face_px, c.min_face_px, 0.5 * c.min_face_px),
        ),
        (
            QualityReason::PartlyOutside,
            below(outside, c.max_outside_fraction, 0.1),
        ),
        (
            QualityReason::Turned,
            below(face.yaw_pitch_deg.0.abs(), c.max_yaw_deg, 15.0).min(below(
                face.yaw_pitch_deg.1.abs(),
                c.max_pitch_deg,
                15.0,
            )),
        ),
        (
            QualityReason::Occluded,
            above(face.face_probability, c.min_face_probability, 0.15).min(below(
                face.fit_rms_px / eye,
                c.max_fit_residual,
                0.5 * c.max_fit_residual,
            )),
        ),
    ];
    let mut reasons = QualityReasons::NONE;
    let mut score = 1.0f32;
    for (r, f) in factors {
        score *= f;
        if f < 0.5 {
            reasons.insert(r);
        }
    }
    FaceQuality {
        score,
        reasons,
        measures: QualityMeasures {
            mean_luma: stats.mean,
            saturated: stats.saturated,
            sharpness: stats.sharpness,
            reference_sharpness: reference,
            face_px,
            outside,
        },
    }
}

/// The frame's own reasons: its light (whole-frame grid), its sharpness against the stream's
/// recent frames (`history`, updated), no face, and a face lost since the previous frame.
pub fn frame_reasons(
    image: &GrayImage,
    config: &QualityConfig,
    history: &mut SharpnessHistory,
    faces: usize,
    lost: bool,
) -> QualityReasons {
    let mut reasons = QualityReasons::NONE;
    let (w, h) = (image.width(), image.height());
    let step = (w.max(h) / 320).max(1);
    if let Some(s) = luma_stats(image, &Rect::new(0.0, 0.0, w as f32, h as f32), step) {
        if s.mean < config.dark_luma {
            reasons.insert(QualityReason::Dark);
        }
        if s.saturated > config.overexposed_fraction {
            reasons.insert(QualityReason::Overexposed);
        }
        if history.judge(s.sharpness, config.blur_drop).0 < 0.5 {
            reasons.insert(QualityReason::Blurred);
        }
    }
    if faces == 0 {
        reasons.insert(QualityReason::NoFace);
    }
    if lost {
        reasons.insert(QualityReason::Lost);
    }
    reasons
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A frame of a textured square (the "face") on a mid-grey background.
    fn textured(w: usize, h: usize, scale: f32, offset: f32) -> GrayImage {
        let mut img = GrayImage::new(w, h);
        for y in 0..h {
            for x in 0..w {
                let (fx, fy) = (x as f32, y as f32);
                // Broadband, as a face is: slow shading that a blur keeps, fine detail it
                // removes.
                let v = 128.0
                    + 45.0 * (0.03 * fx + 0.02 * fy).sin()
                    + 25.0 * (0.6 * fx + 0.2 * fy).sin()
                    + 15.0 * (0.9 * fx - 0.4 * fy + 1.0).sin();
                img.data_mut()[y * w + x] = (v * scale + offset).clamp(0.0, 255.0) as u8;
            }
        }
        img
    }

    fn square_points(x: f32, y: f32, side: f32) -> [[f32; 2]; 68] {
        let mut p = [[0.0; 2]; 68];
        for (i, q) in p.iter_mut().enumerate() {
            let a = i as f32 / 68.0 * std::f32::consts::TAU;
            *q = [
                x + 0.5 * side * (1.0 + a.cos()),
                y + 0.5 * side * (1.0 + a.sin()),
            ];
        }
        // Outer eye corners a third of the side apart.
        p[36] = [x + 0.33 * side, y + 0.4 * side];
        p[45] = [x + 0.67 * side, y + 0.4 * side];
        p
    }

    fn evidence(points: &[[f32; 2]]) -> FaceEvidence<'_> {
        FaceEvidence {
            points,
            yaw_pitch_deg: (0.0, 0.0),
            face_probability: 1.0,
            fit_rms_px: 1.0,
        }
    }

    fn reasons(img: &GrayImage, e: &FaceEvidence<'_>) -> Vec<&'static str> {
        let mut h = SharpnessHistory::default();
        face_quality(img, e, &QualityConfig::default(), &mut h)
            .reasons
            .iter()
            .map(QualityReason::name)
            .collect()
    }

    #[test]
    fn each_fault_names_its_reason_and_a_clean_face_none() {
        let pts = square_points(100.0, 80.0, 200.0);
        let clean = textured(400, 360, 1.0, 0.0);
        let q = face_quality(
            &clean,
            &evidence(&pts),
            &QualityConfig::default(),
            &mut SharpnessHistory::default(),
        );
        assert!(q.reasons.is_empty(), "{:?}", q);
        assert!(q.score > 0.5);
        assert_eq!(
            reasons(&textured(400, 360, 0.15, 0.0), &evidence(&pts)),
            ["dark"]
        );
        assert_eq!(
            reasons(&textured(400, 360, 1.0, 150.0), &evidence(&pts)),
            ["overexposed"]
        );
        let small = square_points(100.0, 80.0, 40.0);
        assert!(reasons(&clean, &evidence(&small)).contains(&"small"));
        let out = square_points(300.0, 80.0, 200.0);
        assert_eq!(reasons(&clean, &evidence(&out)), ["partly_outside"]);
        let mut e = evidence(&pts);
        e.yaw_pitch_deg = (60.0, 0.0);
        assert_eq!(reasons(&clean, &e), ["turned"]);
        e.yaw_pitch_deg = (0.0, -40.0);
        assert_eq!(reasons(&clean, &e), ["turned"]);
        let mut e = evidence(&pts);
        e.face_probability = 0.3;
        assert_eq!(reasons(&clean, &e), ["occluded"]);
        e.face_probability = 1.0;
        e.fit_rms_px = 20.0;
        assert_eq!(reasons(&clean, &e), ["occluded"]);
    }

    #[test]
    fn a_face_that_blurs_after_sharp_frames_is_blurred() {
        let pts = square_points(100.0, 80.0, 200.0);
        let sharp = textured(400, 360, 1.0, 0.0);
        // A horizontal box blur over 9 pixels.
        let mut blurred = sharp.clone();
        let w = sharp.width();
        for y in 0..sharp.height() {
            for x in 0..w {
                let (a, b) = (x.saturating_sub(4), (x + 4).min(w - 1));
                let s: u32 = (a..=b).map(|k| u32::from(sharp.get(k, y))).sum();
                blurred.data_mut()[y * w + x] = (s / (b - a + 1) as u32) as u8;
            }
        }
        let cfg = QualityConfig {
            min_sharpness: 0.0,
            ..QualityConfig::default()
        };
        let mut h = SharpnessHistory::default();
        for _ in 0..5 {
            let q = face_quality(&sharp, &evidence(&pts), &cfg, &mut h);
            assert!(!q.reasons.contains(QualityReason::Blurred));
        }
        let q = face_quality(&blurred, &evidence(&pts), &cfg, &mut h);
        assert!(q.reasons.contains(QualityReason::Blurred), "{q:?}");
        // A new track judges the blurred face on its own: no history, no relative drop.
        h.reset();
        let q = face_quality(&blurred, &evidence(&pts), &cfg, &mut h);
        assert!(!q.reasons.contains(QualityReason::Blurred), "{q:?}");
    }

    #[test]
    fn frame_reasons_see_the_light_without_a_face() {
        let cfg = QualityConfig::default();
        let mut h = SharpnessHistory::default();
        let dark = textured(320, 240, 0.1, 0.0);
        let r = frame_reasons(&dark, &cfg, &mut h, 0, false);
        assert_eq!(
            r.iter().map(QualityReason::name).collect::<Vec<_>>(),
            ["dark", "no_face"]
        );
        let r = frame_reasons(&textured(320, 240, 1.0, 0.0), &cfg, &mut h, 1, true);
        assert_eq!(
            r.iter().map(QualityReason::name).collect::<Vec<_>>(),
            ["lost"]
        );
    }

    #[test]
    fn degenerate_regions_and_images_do_not_panic() {
        let img = GrayImage::new(1, 1);
        assert!(luma_stats(&img, &Rect::new(0.0, 0.0, 1.0, 1.0), 1).is_none());
        let img = textured(64, 48, 1.0, 0.0);
        assert!(luma_stats(&img, &Rect::new(100.0, 100.0, 10.0, 10.0), 1).is_none());
        assert!(luma_stats(&img, &Rect::new(f32::NAN, 0.0, 10.0, 10.0), 1).is_none());
        let pts = [[f32::NAN; 2]; 68];
        let _ = face_quality(
            &img,
            &evidence(&pts),
            &QualityConfig::default(),
            &mut SharpnessHistory::default(),
        );
        let cfg = QualityConfig::default();
        assert!(cfg.validate().is_ok());
        let bad = QualityConfig {
            blur_drop: f32::NAN,
            ..cfg
        };
        assert!(bad.validate().is_err());
    }
}

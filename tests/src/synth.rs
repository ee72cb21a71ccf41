//! Synthetic face-tracking sequences with ground truth, and oracle detector / landmark estimator
//! built from that truth — shared by the tracker tests and the tracking measurements (correct-frame
//! rate tracking vs re-detect-every-frame, per-frame time, jitter with the flow filter on and off).
//!
//! A sequence is a run of *segments*. Each segment shows one annotated face image (faces68) moved
//! by a smooth similarity transform (translation, scale, rotation: sums of slow sinusoids with
//! random phases) over a fixed textured background; its first `still_frames` frames hold the
//! transform still (for jitter), and a new segment is a *cut*: another image at a place that does
//! not overlap the last one, which a tracker must notice and re-detect. Landmarks are transformed
//! with the image, so the truth is exact. Frames are rendered on demand into a caller-held buffer
//! (sequences of any length cost one frame of memory).
//!
//! Pixel convention: CONTRACT (pixel (i, j) covers [i, i+1)×[j, j+1)).

use monotrack_core::Result;
use monotrack_core::image::{GrayImage, Rect};
use monotrack_core::landmarks::{FaceLandmarks, N_POINTS};
use monotrack_core::track::{LandmarkEstimator, RegionDetector};
use std::cell::Cell;
use std::path::Path;
use std::rc::Rc;

/// One annotated face image (luma) with its 68 landmarks.
#[derive(Debug, Clone)]
pub struct FaceSample {
    /// Upright luma of the whole source image.
    pub image: GrayImage,
    /// The face's 68 landmarks in the source image's pixels.
    pub landmarks: [[f32; 2]; N_POINTS],
    /// Source file name (for reports).
    pub name: String,
}

/// Loads up to `max` validation faces of `faces68/train.jsonl` (line i is validation when
/// i % 10 == 0; the first annotated face of each image) whose 68-point box spans at least
/// `min_size` pixels.
///
/// # Errors
/// A message when the manifest or an image cannot be read.
pub fn load_validation_faces(
    data: &Path,
    max: usize,
    min_size: f32,
) -> std::result::Result<Vec<FaceSample>, String> {
    load_split_faces(data, true, max, min_size)
}

/// [`load_validation_faces`] of the validation split (`validation`) or of the training split
/// (every other line).
///
/// # Errors
/// A message when the manifest or an image cannot be read.
pub fn load_split_faces(
    data: &Path,
    validation: bool,
    max: usize,
    min_size: f32,
) -> std::result::Result<Vec<FaceSample>, String> {
    let dir = data.join("faces68");
    let text = std::fs::read_to_string(dir.join("train.jsonl"))
        .map_err(|e| format!("faces68/train.jsonl: {e}"))?;
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        if (i % 10 == 0) != validation || line.trim().is_empty() {
            continue;
        }
        if out.len() >= max {
            break;
        }
        let v: serde_json::Value =
            serde_json::from_str(line).map_err(|e| format!("line {}: {e}", i + 1))?;
        let Some(pts) = v["faces"][0]["landmarks68"].as_array() else {
            continue;
        };
        if pts.len() != N_POINTS {
            continue;
        }
        let mut lm = [[0.0f32; 2]; N_POINTS];
        for (o, p) in lm.iter_mut().zip(pts) {
            *o = [
                p[0].as_f64().unwrap_or(f64::NAN) as f32,
                p[1].as_f64().unwrap_or(f64::NAN) as f32,
            ];
        }
        if lm.iter().any(|p| !p[0].is_finite() || !p[1].is_finite()) {
            continue;
        }
        let b = Rect::bounding(&lm);
        if b.w.max(b.h) < min_size {
            continue;
        }
        let name = v["image"].as_str().unwrap_or_default().to_string();
        let img = image::open(dir.join(&name))
            .map_err(|e| format!("{name}: {e}"))?
            .to_rgb8();
        let (w, h) = (img.width() as usize, img.height() as usize);
        let mut luma = GrayImage::new(w, h);
        monotrack_core::image::rgb_to_contract_luma(img.as_raw(), luma.data_mut());
        out.push(FaceSample {
            image: luma,
            landmarks: lm,
            name,
        });
    }
    Ok(out)
}

/// Normalised mean error: mean point distance / distance between points 36 and 45 of the truth
/// (CONTRACT's NME).
pub fn nme(points: &[[f32; 2]; N_POINTS], truth: &[[f32; 2]; N_POINTS]) -> f32 {
    let iod =
        ((truth[36][0] - truth[45][0]).powi(2) + (truth[36][1] - truth[45][1]).powi(2)).sqrt();
    let s: f32 = points
        .iter()
        .zip(truth)
        .map(|(p, t)| ((p[0] - t[0]).powi(2) + (p[1] - t[1]).powi(2)).sqrt())
        .sum();
    s / N_POINTS as f32 / iod.max(1e-6)
}

/// A small deterministic generator (SplitMix64), so sequences are identical everywhere.
#[derive(Debug, Clone)]
pub struct SplitMix(u64);

impl SplitMix {
    /// Seeded generator.
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }

    /// Next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }

    /// Uniform in [lo, hi).
    pub fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.uniform()
    }

    /// Standard normal (Box–Muller).
    pub fn normal(&mut self) -> f32 {
        let u1 = self.uniform().max(1e-7);
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (2.0 * std::f32::consts::PI * u2).cos()
    }
}

/// Sequence settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SeqConfig {
    /// Frame width, pixels.
    pub width: usize,
    /// Frame height, pixels.
    pub height: usize,
    /// Frames per segment (a cut starts each segment after the first).
    pub segment_frames: usize,
    /// Number of segments.
    pub segments: usize,
    /// Frames at the start of each segment with no motion.
    pub still_frames: usize,
    /// Range of the face's size (larger side of the 68-point box), pixels.
    pub face_px: (f32, f32),
    /// Translation amplitude of the motion, pixels.
    pub translation_px: f32,
    /// Relative scale amplitude (0.15 = ±15 %).
    pub scale_amplitude: f32,
    /// Rotation amplitude, degrees.
    pub rotation_deg: f32,
    /// Each segment's face turned in roll by this much before its motion, one way in even
    /// segments and the other in odd ones (a head held tilted), degrees.
    pub roll_offset_deg: f32,
    /// Shortest motion period, frames (sets the top speed: 2π·amplitude / period per frame).
    pub min_period_frames: f32,
    /// Seed.
    pub seed: u64,
    /// Standard deviation of Gaussian sensor noise added to every pixel, grey levels, fresh per
    /// frame (0 = none). Without it a still face gives identical frames, and landmark jitter on
    /// still segments would measure nothing for a deterministic estimator.
    pub noise_sigma: f32,
    /// Draw only the source pixels within this margin (a fraction of the face box's larger side)
    /// around the annotated face, background elsewhere; `None` draws the whole source image. Source
    /// images may show other, unannotated people, whom a detector rightly finds but the truth does
    /// not know.
    pub crop_margin: Option<f32>,
    /// Brightness swing: each frame's pixels scaled by `1 + A·sin(2π·t / 90)` (t the frame), as a
    /// camera's exposure follows a moving face (0 = none; 0.3 is a strong swing).
    pub brightness_amplitude: f32,
    /// Blur fast frames: a box blur whose radius is a quarter of the face centre's motion since
    /// the last frame, up to 4 px (a phone's exposure smears a fast face); none under 4 px of
    /// motion.
    pub motion_blur: bool,
}

impl Default for SeqConfig {
    fn default() -> Self {
        Self {
            width: 640,
            height: 480,
            segment_frames: 60,
            segments: 4,
            still_frames: 15,
            face_px: (130.0, 200.0),
            translation_px: 50.0,
            scale_amplitude: 0.12,
            rotation_deg: 12.0,
            roll_offset_deg: 0.0,
            min_period_frames: 60.0,
            seed: 7,
            noise_sigma: 0.0,
            crop_margin: None,
            brightness_amplitude: 0.0,
            motion_blur: false,
        }
    }
}

impl SeqConfig {
    /// The clips `track_eval` reports (BENCHMARKS.md, "Tracking"): 6 segments of 60 frames (5
    /// cuts), 20 still frames each, faces 100–200 px, 2 grey levels of sensor noise, the source
    /// drawn within half a face of each face.
    pub fn eval_clips() -> Self {
        Self {
            segments: 6,
            segment_frames: 60,
            still_frames: 20,
            face_px: (100.0, 200.0),
            noise_sigma: 2.0,
            crop_margin: Some(0.5),
            seed: 21,
            ..Self::default()
        }
    }

    /// Total frames.
    pub fn frames(&self) -> usize {
        self.segment_frames * self.segments
    }
}

/// One segment's motion: base similarity plus sinusoids.
#[derive(Debug, Clone, Copy)]
struct Segment {
    face: usize,
    center: [f32; 2],
    scale: f32,
    angle: f32,
    /// (amplitude, angular frequency, phase) for x, y, scale, angle.
    waves: [[f32; 3]; 4],
}

/// The truth of one frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameTruth {
    /// 68 landmarks in frame pixels.
    pub landmarks: [[f32; 2]; N_POINTS],
    /// Tight box of the landmarks.
    pub face_box: Rect,
    /// First frame of a segment after the first (a cut).
    pub cut: bool,
    /// Within the segment's still part.
    pub still: bool,
    /// Segment index.
    pub segment: usize,
}

impl Default for FrameTruth {
    fn default() -> Self {
        Self {
            landmarks: [[0.0; 2]; N_POINTS],
            face_box: Rect::default(),
            cut: false,
            still: false,
            segment: 0,
        }
    }
}

/// A synthetic sequence over some face images.
#[derive(Debug, Clone)]
pub struct Sequence {
    config: SeqConfig,
    faces: Vec<FaceSample>,
    segments: Vec<Segment>,
    background: GrayImage,
}

impl Sequence {
    /// Plans the segments (faces, places, motions) of a sequence over `faces` (at least 2).
    ///
    /// # Errors
    /// A message for fewer than 2 faces or a frame smaller than 64×64.
    pub fn new(config: SeqConfig, faces: Vec<FaceSample>) -> std::result::Result<Self, String> {
        if faces.len() < 2 {
            return Err("a sequence needs at least 2 face images".into());
        }
        if config.width < 64 || config.height < 64 {
            return Err("frames must be at least 64x64".into());
        }
        let mut rng = SplitMix::new(config.seed);
        let mut segments: Vec<Segment> = Vec::with_capacity(config.segments);
        let mut background = GrayImage::new(config.width, config.height);
        for y in 0..config.height {
            for x in 0..config.width {
                let (fx, fy) = (x as f32, y as f32);
                let v = 110.0
                    + 35.0 * (0.021 * fx + 0.013 * fy).sin()
                    + 20.0 * (0.053 * fx - 0.037 * fy + 1.3).sin() * (0.011 * fy).cos();
                background.data_mut()[y * config.width + x] = v.clamp(0.0, 255.0) as u8;
            }
        }
        let mut last_box: Option<Rect> = None;
        let mut last_face = usize::MAX;
        for _ in 0..config.segments {
            let mut face = (rng.next_u64() % faces.len() as u64) as usize;
            if face == last_face {
                face = (face + 1) % faces.len();
            }
            let src = Rect::bounding(&faces[face].landmarks);
            let size = rng.range(config.face_px.0, config.face_px.1);
            let scale = size / src.w.max(src.h);
            let margin = 0.5 * size * (1.0 + config.scale_amplitude) + config.translation_px;
            let mut center = [0.5 * config.width as f32, 0.5 * config.height as f32];
            for _ in 0..100 {
                let lo = [
                    margin.min(0.5 * config.width as f32),
                    margin.min(0.5 * config.height as f32),
                ];
                center = [
                    rng.range(lo[0], config.width as f32 - lo[0]),
                    rng.range(lo[1], config.height as f32 - lo[1]),
                ];
                let b = Rect::new(center[0] - 0.5 * size, center[1] - 0.5 * size, size, size);
                // A cut must not land where the last face was, or a tracker could not tell.
                if last_box.is_none_or(|l| l.iou(&b) < 0.05) {
                    break;
                }
            }
            let mut wave = |amp: f32| {
                let period = rng.range(config.min_period_frames, 2.0 * config.min_period_frames);
                [
                    amp,
                    2.0 * std::f32::consts::PI / period,
                    rng.range(0.0, std::f32::consts::TAU),
                ]
            };
            let waves = [
                wave(config.translation_px),
                wave(config.translation_px),
                wave(config.scale_amplitude),
                wave(config.rotation_deg.to_radians()),
            ];
            let sign = if segments.len().is_multiple_of(2) {
                1.0
            } else {
                -1.0
            };
            let angle = rng.range(-0.15, 0.15) + sign * config.roll_offset_deg.to_radians();
            let seg = Segment {
                face,
                center,
                scale,
                angle,
                waves,
            };
            segments.push(seg);
            last_face = face;
            let t = motion_time(&config, config.segment_frames - 1);
            let (c, s, _) = similarity(&seg, t);
            let half = 0.5 * size * s / seg.scale;
            last_box = Some(Rect::new(c[0] - half, c[1] - half, 2.0 * half, 2.0 * half));
        }
        Ok(Self {
            config,
            faces,
            segments,
            background,
        })
    }

    /// Settings.
    pub fn config(&self) -> &SeqConfig {
        &self.config
    }

    /// Total frames.
    pub fn len(&self) -> usize {
        self.config.frames()
    }

    /// Whether the sequence has no frame.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The face images.
    pub fn faces(&self) -> &[FaceSample] {
        &self.faces
    }

    /// Renders frame `i` into `image` (resized, allocation reused) and returns its truth.
    pub fn render(&self, i: usize, image: &mut GrayImage) -> FrameTruth {
        let cfg = &self.config;
        let k = (i / cfg.segment_frames).min(self.segments.len() - 1);
        let local = i - k * cfg.segment_frames;
        let seg = &self.segments[k];
        let (c, s, a) = similarity(seg, motion_time(cfg, local));
        let face = &self.faces[seg.face];
        let src_box = Rect::bounding(&face.landmarks);
        let qc = src_box.center();
        let (sin, cos) = a.sin_cos();
        // Forward: p = s·R·(q − qc) + c.
        let mut truth = FrameTruth {
            cut: k > 0 && local == 0,
            still: local < cfg.still_frames,
            segment: k,
            ..Default::default()
        };
        for (o, q) in truth.landmarks.iter_mut().zip(&face.landmarks) {
            let (dx, dy) = (q[0] - qc[0], q[1] - qc[1]);
            *o = [
                s * (cos * dx - sin * dy) + c[0],
                s * (sin * dx + cos * dy) + c[1],
            ];
        }
        truth.face_box = Rect::bounding(&truth.landmarks);

        image.resize(cfg.width, cfg.height);
        image.data_mut().copy_from_slice(self.background.data());
        let src = &face.image;
        let (sw, sh) = (src.width() as f32, src.height() as f32);
        // Source region drawn: the whole image, or the face box with a margin.
        let (qx0, qy0, qx1, qy1) = match cfg.crop_margin {
            Some(m) => {
                let d = m * src_box.w.max(src_box.h);
                (
                    src_box.x - d - 0.5,
                    src_box.y - d - 0.5,
                    src_box.x + src_box.w + d - 0.5,
                    src_box.y + src_box.h + d - 0.5,
                )
            }
            None => (0.0, 0.0, sw - 1.0, sh - 1.0),
        };
        let (qx0, qy0) = (qx0.max(0.0), qy0.max(0.0));
        let (qx1, qy1) = (qx1.min(sw - 1.0), qy1.min(sh - 1.0));
        let inv = 1.0 / s;
        let out = image.data_mut();
        for y in 0..cfg.height {
            let py = y as f32 + 0.5 - c[1];
            for x in 0..cfg.width {
                let px = x as f32 + 0.5 - c[0];
                // Inverse: q = Rᵀ·(p − c)/s + qc, then to pixel-index coordinates (− 0.5).
                let qx = inv * (cos * px + sin * py) + qc[0] - 0.5;
                let qy = inv * (-sin * px + cos * py) + qc[1] - 0.5;
                if qx < qx0 || qy < qy0 || qx >= qx1 || qy >= qy1 {
                    continue;
                }
                let (ix, iy) = (qx as usize, qy as usize);
                let (fx, fy) = (qx - ix as f32, qy - iy as f32);
                let d = src.data();
                let w = src.width();
                let v00 = f32::from(d[iy * w + ix]);
                let v10 = f32::from(d[iy * w + ix + 1]);
                let v01 = f32::from(d[(iy + 1) * w + ix]);
                let v11 = f32::from(d[(iy + 1) * w + ix + 1]);
                let v =
                    (1.0 - fy) * ((1.0 - fx) * v00 + fx * v10) + fy * ((1.0 - fx) * v01 + fx * v11);
                out[y * cfg.width + x] = (v + 0.5) as u8;
            }
        }
        if cfg.brightness_amplitude > 0.0 {
            let g = 1.0
                + cfg.brightness_amplitude * (2.0 * std::f32::consts::PI * i as f32 / 90.0).sin();
            for v in out.iter_mut() {
                *v = (f32::from(*v) * g).round().clamp(0.0, 255.0) as u8;
            }
        }
        if cfg.motion_blur && local > 0 {
            let (c0, ..) = similarity(seg, motion_time(cfg, local - 1));
            let moved = (c[0] - c0[0]).hypot(c[1] - c0[1]);
            if moved >= 4.0 {
                box_blur(out, cfg.width, cfg.height, ((moved / 4.0) as usize).min(4));
            }
        }
        if cfg.noise_sigma > 0.0 {
            let mut rng = SplitMix::new(cfg.seed ^ (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
            for v in out.iter_mut() {
                let n = f32::from(*v) + cfg.noise_sigma * rng.normal();
                *v = n.round().clamp(0.0, 255.0) as u8;
            }
        }
        truth
    }
}

/// A separable box blur of radius `r` in place (rows, then columns; edges clamped).
fn box_blur(img: &mut [u8], w: usize, h: usize, r: usize) {
    let mut line = vec![0u32; w.max(h)];
    for y in 0..h {
        blur_line(img, y * w, 1, w, r, &mut line);
    }
    for x in 0..w {
        blur_line(img, x, w, h, r, &mut line);
    }
}

/// The box blur of radius `r` along the `n` pixels of `img` from `start`, `step` apart.
fn blur_line(img: &mut [u8], start: usize, step: usize, n: usize, r: usize, line: &mut [u32]) {
    for (i, v) in line[..n].iter_mut().enumerate() {
        *v = u32::from(img[start + i * step]);
    }
    let width = (2 * r + 1) as u32;
    for i in 0..n {
        let s: u32 = (0..=2 * r)
            .map(|k| line[(i + k).saturating_sub(r).min(n - 1)])
            .sum();
        img[start + i * step] = (s / width) as u8;
    }
}

/// Motion time of a segment's `local` frame: frozen during the still part.
fn motion_time(cfg: &SeqConfig, local: usize) -> f32 {
    local.saturating_sub(cfg.still_frames) as f32
}

/// Centre, scale and angle of a segment at motion time `t`.
fn similarity(seg: &Segment, t: f32) -> ([f32; 2], f32, f32) {
    let w = |k: usize| {
        let [a, om, ph] = seg.waves[k];
        // Zero at t = 0, so each segment starts at its drawn pose (upright but for the drawn tilt,
        // where the detector first meets the face) and the still part joins the motion without a
        // jump; and within ±amplitude, as `SeqConfig` states and the face's placement margin
        // assumes. (A wave a·(sin(ωt + φ) − sin φ) reached twice its amplitude: a "±35°" roll
        // turned the head by up to about twice that.) The phase only picks the direction.
        let dir = if ph < std::f32::consts::PI { 1.0 } else { -1.0 };
        dir * a * (om * t).sin()
    };
    (
        [seg.center[0] + w(0), seg.center[1] + w(1)],
        seg.scale * (1.0 + w(2)),
        seg.angle + w(3),
    )
}

/// The truth the oracles answer from, shared with the test driving the sequence.
pub type SharedTruth = Rc<Cell<FrameTruth>>;

/// A detector that returns the true face box (tight 68-point box) and counts its calls.
#[derive(Debug)]
pub struct OracleDetector {
    truth: SharedTruth,
    /// Calls so far.
    pub calls: usize,
}

impl OracleDetector {
    /// Over `truth`.
    pub fn new(truth: SharedTruth) -> Self {
        Self { truth, calls: 0 }
    }
}

impl RegionDetector for OracleDetector {
    fn detect(&mut self, _image: &GrayImage, out: &mut Vec<(Rect, f32)>) -> Result<()> {
        self.calls += 1;
        out.clear();
        out.push((self.truth.get().face_box, 0.99));
        Ok(())
    }
}

/// IoU of a box with the true face box above which the oracle estimator sees the face.
pub const ORACLE_MIN_IOU: f32 = 0.5;

/// A landmark estimator that returns the true landmarks plus Gaussian noise when the box covers
/// the true face (IoU ≥ [`ORACLE_MIN_IOU`]); otherwise the true shape squeezed into the given box
/// (what a landmark net does on a wrong crop). Its face confidence is 0.95 / 0.05 by the same rule.
#[derive(Debug)]
pub struct OracleLandmarks {
    truth: SharedTruth,
    rng: SplitMix,
    /// Noise standard deviation per coordinate, pixels.
    pub noise_px: f32,
    /// `estimate` calls so far.
    pub estimate_calls: usize,
    /// `face_confidence` calls so far.
    pub confidence_calls: usize,
}

impl OracleLandmarks {
    /// Over `truth`, with `noise_px` noise and a seed.
    pub fn new(truth: SharedTruth, noise_px: f32, seed: u64) -> Self {
        Self {
            truth,
            rng: SplitMix::new(seed),
            noise_px,
            estimate_calls: 0,
            confidence_calls: 0,
        }
    }
}

impl LandmarkEstimator for OracleLandmarks {
    fn estimate(&mut self, _image: &GrayImage, face: &Rect, out: &mut FaceLandmarks) -> Result<()> {
        self.estimate_calls += 1;
        let t = self.truth.get();
        *out = FaceLandmarks::default();
        out.yaw_probs = [0.0, 0.0, 1.0, 0.0, 0.0];
        out.mouth = [0.0, 0.0, 0.0, 1.0];
        out.brows = [0.0, 0.0, 1.0];
        if face.iou(&t.face_box) >= ORACLE_MIN_IOU {
            out.face_prob = 0.95;
            for (o, p) in out.points.iter_mut().zip(&t.landmarks) {
                *o = [
                    p[0] + self.noise_px * self.rng.normal(),
                    p[1] + self.noise_px * self.rng.normal(),
                ];
            }
        } else {
            out.face_prob = 0.05;
            let b = t.face_box;
            for (o, p) in out.points.iter_mut().zip(&t.landmarks) {
                *o = [
                    face.x + (p[0] - b.x) / b.w.max(1.0) * face.w,
                    face.y + (p[1] - b.y) / b.h.max(1.0) * face.h,
                ];
            }
        }
        Ok(())
    }

    fn face_confidence(
        &mut self,
        _image: &GrayImage,
        face: &Rect,
        _out: &mut FaceLandmarks,
    ) -> Result<f32> {
        self.confidence_calls += 1;
        Ok(if face.iou(&self.truth.get().face_box) >= ORACLE_MIN_IOU {
            0.95
        } else {
            0.05
        })
    }
}

/// Mean over landmarks of the RMS distance of each landmark from its mean position over a run of
/// frames (pixels): the jitter of a still face, whose true landmarks do not move.
pub fn jitter(run: &[[[f32; 2]; N_POINTS]]) -> f32 {
    if run.len() < 2 {
        return 0.0;
    }
    let n = run.len() as f32;
    let mut total = 0.0;
    for i in 0..N_POINTS {
        let mx = run.iter().map(|p| p[i][0]).sum::<f32>() / n;
        let my = run.iter().map(|p| p[i][1]).sum::<f32>() / n;
        let var = run
            .iter()
            .map(|p| (p[i][0] - mx).powi(2) + (p[i][1] - my).powi(2))
            .sum::<f32>()
            / n;
        total += var.sqrt();
    }
    total / N_POINTS as f32
}

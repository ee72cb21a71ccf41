//! The quality reasons on clips made to have each fault (`core::track::quality`): how often a
//! fault's reason fires on its clips, and how often any reason fires on clean clips. Shared by
//! the `quality_reasons` test (bounds, CI) and the `quality_eval` example (the reported figures).
//!
//! A clip is one segment of a synthetic sequence ([`Sequence`]): a faces68 validation face moving
//! slowly over a textured background, with sensor noise; one tracker (video mode, default
//! settings) runs the clips one after the other, reset at each. Faults, applied to every frame of a clip:
//! - dark: luma × 0.12 (a dim room at a phone's short exposure);
//! - overexposed: luma × 2.2 + 60, clipped (a face in sunlight at an exposure set for the room);
//! - blurred: from the clip's [`BLUR_FROM`]th frame on, a horizontal box blur over a tenth of the
//!   face's size (a head turning fast at a long exposure), after sharp frames;
//! - small: the face drawn 36–48 px large instead of 130–200;
//! - partly outside: the frame shifted so that 35 % of the face's width is past the left edge;
//! - occluded: a flat grey patch over the lower half of the face (a hand over nose and mouth).
//!
//! A fault fires on a frame when its reason is among the first face's reasons or the frame's own
//! (a dark frame where no face is found still says dark).

use crate::synth::{FaceSample, SeqConfig, Sequence};
use monotrack_core::image::{GrayImage, Rect};
use monotrack_core::track::quality::{QualityReason, QualityReasons};
use monotrack_core::track::{Tracker, TrackerConfig};

/// Frames per clip.
pub const CLIP_FRAMES: usize = 10;

/// The frame of a clip from which the blurred fault's blur applies.
pub const BLUR_FROM: usize = 5;

/// A fault a clip is made to have.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fault {
    /// No fault.
    Clean,
    /// Too little light.
    Dark,
    /// Too much light.
    Overexposed,
    /// Motion blur after sharp frames.
    Blurred,
    /// A small face.
    Small,
    /// The face partly outside the frame.
    PartlyOutside,
    /// A patch over the lower face.
    Occluded,
}

impl Fault {
    /// Every fault, clean first.
    pub const ALL: [Fault; 7] = [
        Fault::Clean,
        Fault::Dark,
        Fault::Overexposed,
        Fault::Blurred,
        Fault::Small,
        Fault::PartlyOutside,
        Fault::Occluded,
    ];

    /// The reason the fault should raise (`None` for clean clips).
    pub fn reason(self) -> Option<QualityReason> {
        match self {
            Fault::Clean => None,
            Fault::Dark => Some(QualityReason::Dark),
            Fault::Overexposed => Some(QualityReason::Overexposed),
            Fault::Blurred => Some(QualityReason::Blurred),
            Fault::Small => Some(QualityReason::Small),
            Fault::PartlyOutside => Some(QualityReason::PartlyOutside),
            Fault::Occluded => Some(QualityReason::Occluded),
        }
    }

    /// A name for reports.
    pub fn name(self) -> &'static str {
        match self {
            Fault::Clean => "clean",
            other => other.reason().map(QualityReason::name).unwrap_or("clean"),
        }
    }
}

/// What the clips of one fault gave.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FaultStats {
    /// Frames judged (for the blurred fault, the blurred frames only).
    pub frames: usize,
    /// Of those, frames with a face.
    pub with_face: usize,
    /// Frames where the fault's reason fired (for clean clips: where any reason fired).
    pub fired: usize,
    /// Per reason ([`QualityReason::ALL`] order), the frames it fired on.
    pub per_reason: [usize; 9],
    /// Mean face score over the frames with a face.
    pub mean_score: f64,
}

impl FaultStats {
    /// `fired / frames`.
    pub fn rate(&self) -> f64 {
        self.fired as f64 / self.frames.max(1) as f64
    }
}

fn box_blur_rows(img: &mut GrayImage, radius: usize) {
    let (w, h) = (img.width(), img.height());
    let mut row = vec![0u8; w];
    for y in 0..h {
        row.copy_from_slice(img.row(y));
        let mut acc: u32 = 0;
        let mut prefix = Vec::with_capacity(w + 1);
        prefix.push(0u32);
        for v in &row {
            acc += u32::from(*v);
            prefix.push(acc);
        }
        let out = &mut img.data_mut()[y * w..(y + 1) * w];
        for (x, o) in out.iter_mut().enumerate() {
            let a = x.saturating_sub(radius);
            let b = (x + radius + 1).min(w);
            *o = ((prefix[b] - prefix[a]) / (b - a) as u32) as u8;
        }
    }
}

/// Applies `fault` to frame `local` (of its clip) in place; `face` is the truth's face box.
fn apply(fault: Fault, local: usize, img: &mut GrayImage, face: &Rect) {
    let (w, h) = (img.width(), img.height());
    match fault {
        Fault::Clean | Fault::Small => {}
        Fault::Dark => img
            .data_mut()
            .iter_mut()
            .for_each(|v| *v = (f32::from(*v) * 0.12).round() as u8),
        Fault::Overexposed => img
            .data_mut()
            .iter_mut()
            .for_each(|v| *v = (f32::from(*v) * 2.2 + 60.0).min(255.0) as u8),
        Fault::Blurred => {
            if local >= BLUR_FROM {
                let radius = (face.w.max(face.h) / 20.0).round().max(2.0) as usize;
                box_blur_rows(img, radius);
            }
        }
        Fault::PartlyOutside => {
            // Shift left so the face's left 35 % is past the edge; the vacated right part
            // repeats the last column.
            let shift = (face.x + 0.35 * face.w).max(0.0).round() as usize;
            let shift = shift.min(w - 1);
            let data = img.data_mut();
            for y in 0..h {
                let r = &mut data[y * w..(y + 1) * w];
                r.copy_within(shift.., 0);
                let last = r[w - 1 - shift];
                r[w - shift..].fill(last);
            }
        }
        Fault::Occluded => {
            let x0 = face.x.max(0.0) as usize;
            let x1 = ((face.x + face.w).max(0.0) as usize).min(w);
            let y0 = ((face.y + 0.5 * face.h).max(0.0) as usize).min(h);
            let y1 = ((face.y + 1.05 * face.h).max(0.0) as usize).min(h);
            for y in y0..y1 {
                img.data_mut()[y * w + x0..y * w + x1].fill(120);
            }
        }
    }
}

/// The clips' sequence settings for `fault` over `clips` clips.
pub fn clip_config(fault: Fault, clips: usize, seed: u64) -> SeqConfig {
    SeqConfig {
        segments: clips,
        segment_frames: CLIP_FRAMES,
        still_frames: 2,
        face_px: if fault == Fault::Small {
            (36.0, 48.0)
        } else {
            (130.0, 200.0)
        },
        translation_px: 8.0,
        scale_amplitude: 0.03,
        rotation_deg: 3.0,
        min_period_frames: 60.0,
        noise_sigma: 2.0,
        crop_margin: Some(0.5),
        seed,
        ..SeqConfig::default()
    }
}

/// Runs a fresh tracker with `config` over `clips` clips of `faces` made to have `fault`.
///
/// # Errors
/// A message for tracker or sequence errors.
pub fn run_fault(
    fault: Fault,
    faces: &[FaceSample],
    clips: usize,
    config: TrackerConfig,
    seed: u64,
) -> Result<FaultStats, String> {
    let seq = Sequence::new(clip_config(fault, clips, seed), faces.to_vec())?;
    let mut tracker = Tracker::with_default_models(config).map_err(|e| e.to_string())?;
    let mut img = GrayImage::default();
    let mut stats = FaultStats::default();
    let mut score_sum = 0.0;
    for i in 0..seq.len() {
        let truth = seq.render(i, &mut img);
        let local = i % CLIP_FRAMES;
        if local == 0 {
            // Each clip is a stream of its own: no face lost at the cut.
            tracker.reset();
        }
        apply(fault, local, &mut img, &truth.face_box);
        let r = tracker
            .process(&img, (i as i64 + 1) * 33_333_333)
            .map_err(|e| e.to_string())?;
        if fault == Fault::Blurred && local < BLUR_FROM {
            continue;
        }
        let mut reasons: QualityReasons = r.reasons;
        if let Some(f) = r.faces.first() {
            stats.with_face += 1;
            score_sum += f64::from(f.quality.score);
            for q in f.quality.reasons.iter() {
                reasons.insert(q);
            }
        }
        stats.frames += 1;
        for (k, q) in QualityReason::ALL.iter().enumerate() {
            if reasons.contains(*q) {
                stats.per_reason[k] += 1;
            }
        }
        let fired = match fault.reason() {
            Some(q) => reasons.contains(q),
            None => !reasons.is_empty(),
        };
        stats.fired += usize::from(fired);
    }
    stats.mean_score = score_sum / stats.with_face.max(1) as f64;
    Ok(stats)
}

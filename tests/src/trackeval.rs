//! Scoring a [`FaceTracker`] against ground truth over a clip: correct-frame rate, per-frame time per stage, and landmark jitter on still segments. Shared by
//! the `track_models` test (quality bounds, CI) and the `track_eval` example (the reported numbers,
//! run in the optimised `bench` profile).
//!
//! A frame is *correct* when the tracker reports a face whose landmarks have an NME (inter-ocular,
//! [`crate::synth::nme`]) below the caller's threshold against the truth; when several faces are
//! reported the one nearest the truth is scored. Frames without truth (a video frame where the
//! reference found no face) are run but not scored.

use crate::synth::{FaceSample, SeqConfig, Sequence, jitter, nme};
use monotrack_core::image::frame::{Frame, FrameDesc, PixelFormat};
use monotrack_core::image::{GrayImage, Rect};
use monotrack_core::landmarks::N_POINTS;
use monotrack_core::track::{FaceTracker, LandmarkEstimator, RegionDetector};
use std::time::Instant;

/// One frame of a clip with its truth.
#[derive(Debug, Clone)]
pub struct ClipFrame {
    /// Upright luma.
    pub image: GrayImage,
    /// True (or reference) 68 landmarks; `None` = not scored.
    pub truth: Option<[[f32; 2]; N_POINTS]>,
    /// Frames sharing a `Some(k)` show a face that does not move (jitter is measured over them).
    pub still_run: Option<usize>,
}

/// A synthetic clip from `faces` (see [`Sequence`]); still runs are the still parts of the
/// segments, without their first frame (the detection frame of the segment).
///
/// # Errors
/// As [`Sequence::new`].
pub fn synthetic_clip(config: SeqConfig, faces: Vec<FaceSample>) -> Result<Vec<ClipFrame>, String> {
    let seq = Sequence::new(config, faces)?;
    Ok((0..seq.len())
        .map(|i| {
            let mut image = GrayImage::default();
            let t = seq.render(i, &mut image);
            let first = i % config.segment_frames == 0;
            ClipFrame {
                image,
                truth: Some(t.landmarks),
                still_run: (t.still && !first).then_some(t.segment),
            }
        })
        .collect())
}

/// What a run of a tracker over a clip measured. Times are per frame, microseconds, means over
/// all frames (from the tracker's own stage timings, except `wall_us`).
#[derive(Debug, Clone, Default)]
pub struct ClipStats {
    /// Frames run.
    pub frames: usize,
    /// Frames with truth.
    pub scored: usize,
    /// Scored frames where a face was reported.
    pub with_face: usize,
    /// Scored frames with a correct face.
    pub correct: usize,
    /// Scored frames where no face was reported although all 68 truth points lie in the frame.
    pub no_face_visible: usize,
    /// Mean NME over scored frames with a reported face.
    pub mean_nme: f32,
    /// Mean intersection over union of the reported face's region with the truth's box (the
    /// tight box of its 68 points, the detector's convention) over scored frames with a face:
    /// how well the region follows the face's place and size, whatever the landmarks do.
    pub mean_iou: f32,
    /// Frames on which the detector ran.
    pub detector_runs: usize,
    /// Mean `process` wall time.
    pub wall_us: f64,
    /// Mean of the tracker's `total_us`.
    pub total_us: f64,
    /// Mean frame → luma time (0 for [`Input::Luma`]).
    pub image_us: f64,
    /// Mean region time (detector or NCC + face check).
    pub region_us: f64,
    /// Mean detector time (part of region).
    pub detect_us: f64,
    /// Mean landmark time.
    pub landmarks_us: f64,
    /// Mean flow-filter time.
    pub flow_us: f64,
    /// Mean fit time.
    pub fit_us: f64,
    /// Mean over still runs of [`jitter`] of the reported landmarks, pixels (0 without still runs).
    pub jitter_px: f32,
    /// Mean inter-ocular distance of the truth on the still runs, pixels (to read jitter as NME).
    pub jitter_iod_px: f32,
}

impl ClipStats {
    /// Correct frames / scored frames.
    pub fn correct_rate(&self) -> f64 {
        self.correct as f64 / self.scored.max(1) as f64
    }
}

/// How [`run_clip_with`] hands the clip's frames to the tracker.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Input {
    /// As camera frames: [`FaceTracker::process_frame`] on a `Gray8` frame, the way an app passes
    /// a YUV frame's Y plane. The tracker copies it into the luma buffer it keeps, as it converts
    /// every camera format; that copy is the frame's `image` time and counts in its total.
    Gray8Frame,
    /// [`FaceTracker::process`] on the clip's own images. Every frame is then a different buffer
    /// that no step before the tracker has read, so the tracker's first reads of it wait for
    /// memory (a long clip does not fit in the caches).
    Luma,
}

/// [`run_clip_with`] on the clip's luma images ([`Input::Luma`]).
///
/// # Errors
/// As [`run_clip_with`].
pub fn run_clip<D: RegionDetector, L: LandmarkEstimator>(
    tracker: &mut FaceTracker<D, L>,
    clip: &[ClipFrame],
    correct_nme: f32,
) -> monotrack_core::Result<ClipStats> {
    run_clip_with(tracker, clip, correct_nme, Input::Luma)
}

/// Runs `tracker` (fresh or reset) over `clip` at 30 fps timestamps and scores it with the NME
/// threshold `correct_nme`.
///
/// # Errors
/// The tracker's error on the first frame it fails.
pub fn run_clip_with<D: RegionDetector, L: LandmarkEstimator>(
    tracker: &mut FaceTracker<D, L>,
    clip: &[ClipFrame],
    correct_nme: f32,
    input: Input,
) -> monotrack_core::Result<ClipStats> {
    tracker.reset();
    let mut s = ClipStats::default();
    let mut nme_sum = 0.0f64;
    let mut iou_sum = 0.0f64;
    let mut runs: Vec<Vec<[[f32; 2]; N_POINTS]>> = Vec::new();
    let mut iods: Vec<f32> = Vec::new();
    // `TRACK_EVAL_TRACE=FILE`: one line per frame with truth (frame, roll°, motion px, eye
    // distance px, reported, NME, detector ran, fully in the frame), for finding where a clip
    // loses its frames.
    let mut trace = std::env::var_os("TRACK_EVAL_TRACE")
        .and_then(|p| std::fs::File::create(p).ok())
        .map(std::io::BufWriter::new);
    let mut last_centre: Option<[f32; 2]> = None;
    for (i, f) in clip.iter().enumerate() {
        let ts = i as i64 * 33_333_333;
        let t = Instant::now();
        let r = match input {
            Input::Gray8Frame => {
                let (w, h) = (f.image.width() as u32, f.image.height() as u32);
                let frame =
                    Frame::new(f.image.data(), FrameDesc::packed(w, h, PixelFormat::Gray8))?;
                tracker.process_frame(&frame, ts)?
            }
            Input::Luma => tracker.process(&f.image, ts)?,
        };
        s.wall_us += t.elapsed().as_secs_f64() * 1e6;
        s.frames += 1;
        s.detector_runs += usize::from(r.detector_ran);
        let tm = &r.timings;
        s.total_us += tm.total_us as f64;
        s.image_us += tm.image_us as f64;
        s.region_us += tm.region_us as f64;
        s.detect_us += tm.detect_us as f64;
        s.landmarks_us += tm.landmarks_us as f64;
        s.flow_us += tm.flow_us as f64;
        s.fit_us += tm.fit_us as f64;
        let Some(truth) = &f.truth else {
            continue;
        };
        s.scored += 1;
        let tb = Rect::bounding(truth);
        let centre = [tb.x + tb.w / 2.0, tb.y + tb.h / 2.0];
        let motion = last_centre.map_or(0.0, |c| (centre[0] - c[0]).hypot(centre[1] - c[1]));
        last_centre = Some(centre);
        let best = r.faces.iter().max_by(|a, b| {
            Rect::bounding(&a.landmarks.points)
                .iou(&tb)
                .total_cmp(&Rect::bounding(&b.landmarks.points).iou(&tb))
        });
        let e = best.map(|face| nme(&face.landmarks.points, truth));
        let (fw, fh) = (f.image.width() as f32, f.image.height() as f32);
        let visible = truth
            .iter()
            .all(|p| p[0] >= 0.0 && p[1] >= 0.0 && p[0] < fw && p[1] < fh);
        if best.is_none() && visible {
            s.no_face_visible += 1;
        }
        if let Some(t) = &mut trace {
            use std::io::Write;
            let roll = (truth[45][1] - truth[36][1]).atan2(truth[45][0] - truth[36][0]);
            let iod = (truth[45][1] - truth[36][1]).hypot(truth[45][0] - truth[36][0]);
            let _ = writeln!(
                t,
                "{i} {:.1} {motion:.1} {iod:.1} {} {:.4} {} {}",
                roll.to_degrees(),
                u8::from(best.is_some()),
                e.unwrap_or(f32::NAN),
                u8::from(r.detector_ran),
                u8::from(visible)
            );
        }
        let (Some(face), Some(e)) = (best, e) else {
            continue;
        };
        s.with_face += 1;
        nme_sum += f64::from(e);
        iou_sum += f64::from(face.rect.iou(&tb));
        if e < correct_nme {
            s.correct += 1;
        }
        if let Some(k) = f.still_run {
            if runs.len() <= k {
                runs.resize(k + 1, Vec::new());
            }
            runs[k].push(face.landmarks.points);
            let iod = ((truth[36][0] - truth[45][0]).powi(2)
                + (truth[36][1] - truth[45][1]).powi(2))
            .sqrt();
            iods.push(iod);
        }
    }
    let n = s.frames.max(1) as f64;
    for v in [
        &mut s.wall_us,
        &mut s.total_us,
        &mut s.image_us,
        &mut s.region_us,
        &mut s.detect_us,
        &mut s.landmarks_us,
        &mut s.flow_us,
        &mut s.fit_us,
    ] {
        *v /= n;
    }
    s.mean_nme = (nme_sum / s.with_face.max(1) as f64) as f32;
    s.mean_iou = (iou_sum / s.with_face.max(1) as f64) as f32;
    let runs: Vec<_> = runs.iter().filter(|r| r.len() >= 2).collect();
    s.jitter_px = runs.iter().map(|r| jitter(r)).sum::<f32>() / runs.len().max(1) as f32;
    s.jitter_iod_px = iods.iter().sum::<f32>() / iods.len().max(1) as f32;
    Ok(s)
}

/// Markdown table header matching [`table_row`].
pub fn table_header() -> String {
    "| run | frames | correct | no face | mean NME | box IoU | detector runs | per frame (ms) | image | region | of which detect | landmarks | flow | fit | still jitter (px) |\n\
     |---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"
        .to_string()
}

/// One markdown table row of `s`.
pub fn table_row(name: &str, s: &ClipStats) -> String {
    format!(
        "| {name} | {} | {:.1} % ({}/{}) | {} | {:.2} % | {:.3} | {} | {:.3} | {:.3} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {} |",
        s.frames,
        100.0 * s.correct_rate(),
        s.correct,
        s.scored,
        s.scored - s.with_face,
        100.0 * s.mean_nme,
        s.mean_iou,
        s.detector_runs,
        s.total_us / 1e3,
        s.image_us / 1e3,
        s.region_us / 1e3,
        s.detect_us / 1e3,
        s.landmarks_us / 1e3,
        s.flow_us / 1e3,
        s.fit_us / 1e3,
        if s.jitter_iod_px > 0.0 {
            format!("{:.3}", s.jitter_px)
        } else {
            "–".into()
        },
    )
}

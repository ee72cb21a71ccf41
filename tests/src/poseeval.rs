//! The pose uncertainty's calibration data: on annotated faces, the pose the shipped tracker
//! reports (detector, M3 single pass, MSBP, on the whole image) against the pose MSBP fits to the
//! landmarks people annotated, with the same camera, together with the standard deviations the
//! tracker reports. The difference is the part of the pose's error the landmarks cause; the
//! uncertainty is calibrated to it (`core::fit::uncertainty`).

use crate::synth::FaceSample;
use monotrack_core::camera::Intrinsics;
use monotrack_core::fit::uncertainty::pose_uncertainty_raw;
use monotrack_core::fit::{Msbp, MsbpConfig};
use monotrack_core::image::Rect;
use monotrack_core::model::{FaceModel, N_LANDMARKS};
use monotrack_core::track::{Mode, Tracker, TrackerConfig};

/// The names of the six numbers, in [`PoseSample`]'s order.
pub const COMPONENTS: [&str; 6] = ["yaw", "pitch", "roll", "x", "y", "z"];

/// One face: reported minus reference (degrees for the angles, mm for the translation), and the
/// reported standard deviations, yaw, pitch, roll, x, y, z.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseSample {
    /// The face's place in the list it came from.
    pub index: usize,
    /// Reported pose minus the annotations' pose.
    pub error: [f64; 6],
    /// The reported standard deviations.
    pub sd: [f64; 6],
    /// The covariance's standard deviations for landmark errors of 1 px (uncalibrated, not scaled
    /// by the residual).
    pub sd_per_px: [f64; 6],
    /// The fit's RMS residual, pixels.
    pub rms_px: f64,
    /// Outer-eye distance of the reported landmarks, pixels.
    pub eye_px: f64,
}

/// A tracker as the SDK's image mode runs it, but with M3 in single pass (the mode streams run).
///
/// # Errors
/// Model loading errors.
pub fn still_tracker() -> monotrack_core::Result<Tracker> {
    let mut t = Tracker::with_default_models(TrackerConfig {
        mode: Mode::Image,
        ..TrackerConfig::default()
    })?;
    t.estimator_mut().set_mirror_average(false);
    Ok(t)
}

fn wrap(d: f64) -> f64 {
    (d + 180.0).rem_euclid(360.0) - 180.0
}

/// The samples of `faces` whose face the tracker finds (the reported face overlapping the
/// annotated box best, by at least 0.5).
///
/// # Errors
/// Tracker or fit errors.
pub fn pose_samples(
    tracker: &mut Tracker,
    faces: &[FaceSample],
) -> monotrack_core::Result<Vec<PoseSample>> {
    let mut msbp = Msbp::new(MsbpConfig::default());
    let mut out = Vec::with_capacity(faces.len());
    for (k, f) in faces.iter().enumerate() {
        let truth_box = Rect::bounding(&f.landmarks);
        let r = tracker.process(&f.image, k as i64)?;
        let Some(face) = r
            .faces
            .iter()
            .map(|x| (Rect::bounding(&x.landmarks.points).iou(&truth_box), x))
            .filter(|(iou, _)| *iou >= 0.5)
            .max_by(|a, b| a.0.total_cmp(&b.0))
            .map(|(_, x)| *x)
        else {
            continue;
        };
        let cam = Intrinsics::default_for(f.image.width() as u32, f.image.height() as u32)?;
        let mut pts = [[0.0f64; 2]; N_LANDMARKS];
        for (o, p) in pts.iter_mut().zip(&f.landmarks) {
            *o = [f64::from(p[0]), f64::from(p[1])];
        }
        let reference = msbp.fit(&pts, None, &cam, None)?;
        let (y, p, r) = face.fit.pose.euler_deg();
        let (ry, rp, rr) = reference.pose.euler_deg();
        let d = face.fit.pose.translation - reference.pose.translation;
        let u = face.fit.uncertainty;
        let mut fitted = [[0.0f64; 2]; N_LANDMARKS];
        for (o, p) in fitted.iter_mut().zip(&face.landmarks.points) {
            *o = [f64::from(p[0]), f64::from(p[1])];
        }
        let raw = pose_uncertainty_raw(
            FaceModel::builtin(),
            &face.fit.shape,
            &face.fit.animation,
            &face.fit.pose,
            &cam,
            &fitted,
            &[1.0; N_LANDMARKS],
        );
        // The raw SDs carry the residual's scale, sqrt(RSS / (2n - 6)): divided out.
        let n = N_LANDMARKS as f64;
        let per_px = face.fit.report.rms_px * (2.0 * n / (2.0 * n - 6.0)).sqrt();
        let unit = |v: f64| v / per_px.max(1e-9);
        let (a, b) = (face.landmarks.points[36], face.landmarks.points[45]);
        out.push(PoseSample {
            index: k,
            sd_per_px: [
                unit(raw.rotation_deg[0]),
                unit(raw.rotation_deg[1]),
                unit(raw.rotation_deg[2]),
                unit(raw.translation_mm[0]),
                unit(raw.translation_mm[1]),
                unit(raw.translation_mm[2]),
            ],
            rms_px: face.fit.report.rms_px,
            eye_px: f64::from((b[0] - a[0]).hypot(b[1] - a[1])),
            error: [wrap(y - ry), wrap(p - rp), wrap(r - rr), d.x, d.y, d.z],
            sd: [
                u.rotation_deg[0],
                u.rotation_deg[1],
                u.rotation_deg[2],
                u.translation_mm[0],
                u.translation_mm[1],
                u.translation_mm[2],
            ],
        });
    }
    Ok(out)
}

/// Per component, the fraction of `samples` whose |error| is within `k` standard deviations.
pub fn coverage(samples: &[PoseSample], k: f64) -> [f64; 6] {
    std::array::from_fn(|c| {
        let n = samples
            .iter()
            .filter(|s| s.error[c].abs() <= k * s.sd[c])
            .count();
        n as f64 / samples.len().max(1) as f64
    })
}

/// Per component, the `q` quantile (0..1) of |error| / sd: the factor that would make `q` of
/// the samples fall within one standard deviation.
pub fn ratio_quantile(samples: &[PoseSample], q: f64) -> [f64; 6] {
    std::array::from_fn(|c| {
        let mut r: Vec<f64> = samples
            .iter()
            .map(|s| s.error[c].abs() / s.sd[c].max(1e-12))
            .collect();
        r.sort_by(f64::total_cmp);
        if r.is_empty() {
            return f64::NAN;
        }
        let i = ((r.len() - 1) as f64 * q).round() as usize;
        r[i]
    })
}

/// The calibration half of a split's samples (even places in its list) and the check half (odd).
pub fn halves(samples: &[PoseSample]) -> (Vec<PoseSample>, Vec<PoseSample>) {
    samples.iter().partition(|s| s.index % 2 == 0)
}

/// Per component, the factor on the reported SDs that brings the coverage at one and two SDs
/// nearest 68.27 % and 95.45 % together (least squares over both): the errors' tails are heavier
/// than a Gaussian's, so no one factor meets both.
pub fn calibration_factor(samples: &[PoseSample]) -> [f64; 6] {
    std::array::from_fn(|c| {
        let mut r: Vec<f64> = samples
            .iter()
            .map(|s| s.error[c].abs() / s.sd[c].max(1e-12))
            .collect();
        r.sort_by(f64::total_cmp);
        let Some(&top) = r.last() else {
            return f64::NAN;
        };
        let n = r.len() as f64;
        let within = |k: f64| r.iter().filter(|v| **v <= k).count() as f64 / n;
        let mut best = (f64::INFINITY, 1.0);
        for i in 1..=4000 {
            let k = top * f64::from(i) / 4000.0;
            let loss = (within(k) - 0.6827).powi(2) + (within(2.0 * k) - 0.9545).powi(2);
            if loss < best.0 {
                best = (loss, k);
            }
        }
        best.1
    })
}

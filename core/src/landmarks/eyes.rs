//! Per-eye openness from the 68 landmarks: each eye's aspect ratio (Soukupová and Čech's EAR,
//! the lids' mean opening over the corners' distance) mapped through a logistic to 0..1.
//!
//! The eyes are the subject's own (CONTRACT.md's landmark order): the right eye is points 36–41
//! (image left for a frontal face), the left eye 42–47. Per eye, with p1 … p6 its six points in
//! iBUG order (p1 the outer corner for the right eye, the inner for the left; p4 the other
//! corner; p2, p3 the upper lid; p5, p6 the lower), EAR = (|p2 − p6| + |p3 − p5|) / (2 |p1 − p4|).

use super::N_POINTS;
use crate::math::Libm;

/// The eye aspect ratio at which [`eye_openness`] reads 0.5.
///
/// Fitted with [`EYE_OPEN_SLOPE`] by `models/train/eval_eye_openness.py --fit`: a class-balanced
/// logistic regression on the faces68 training split of "open" (the annotated EAR at or above
/// [`CLOSED_EAR`]) on the EAR of the SDK's own landmarks (`monotrack landmarks`); the validation
/// split's figures are in `models/m3/eye_openness_metrics.json`. It lies above [`CLOSED_EAR`]
/// because the landmarks of a closed eye seldom close as far as its annotation does.
pub const EYE_OPEN_CENTRE: f32 = 0.2142;

/// The logistic's slope per unit of EAR (fitted with [`EYE_OPEN_CENTRE`]).
pub const EYE_OPEN_SLOPE: f32 = 42.5;

/// An annotated eye aspect ratio below which the eye counts as closed, in fitting and evaluating
/// the openness (the lids' opening under an eighth of the eye's width: a blink, not a squint).
pub const CLOSED_EAR: f32 = 0.12;

/// The first point of each eye in the 68: the subject's right eye, then the left.
const EYE_START: [usize; 2] = [36, 42];

/// How open each of the subject's eyes is, 0 (closed) .. 1 (open).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct EyeOpenness {
    /// The subject's left eye (points 42–47).
    pub left: f32,
    /// The subject's right eye (points 36–41).
    pub right: f32,
}

/// Each eye's aspect ratio (EAR, module docs): the subject's right eye, then the left. An eye
/// whose corners coincide has ratio 0.
pub fn eye_aspect_ratios(points: &[[f32; 2]; N_POINTS]) -> [f32; 2] {
    let d = |a: usize, b: usize| (points[a][0] - points[b][0]).mhypot(points[a][1] - points[b][1]);
    EYE_START.map(|e| {
        let width = d(e, e + 3);
        if width > 0.0 {
            (d(e + 1, e + 5) + d(e + 2, e + 4)) / (2.0 * width)
        } else {
            0.0
        }
    })
}

/// An eye aspect ratio as openness: the logistic of [`EYE_OPEN_CENTRE`] and [`EYE_OPEN_SLOPE`].
pub fn openness_from_ear(ear: f32) -> f32 {
    1.0 / (1.0 + (-EYE_OPEN_SLOPE * (ear - EYE_OPEN_CENTRE)).mexp())
}

/// Openness of both of the subject's eyes from the 68 landmarks (image pixels, any similarity
/// of the face gives the same values). Allocates nothing.
pub fn eye_openness(points: &[[f32; 2]; N_POINTS]) -> EyeOpenness {
    let [right, left] = eye_aspect_ratios(points).map(openness_from_ear);
    EyeOpenness { left, right }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 68 points with both eyes drawn as hexagons of the given lid openings (fraction of the
    /// eye's width) and everything else at the origin.
    fn face(right_open: f32, left_open: f32) -> [[f32; 2]; N_POINTS] {
        let mut p = [[0.0; 2]; N_POINTS];
        for (e, x0, open) in [(36, 100.0, right_open), (42, 160.0, left_open)] {
            let (w, y) = (30.0, 200.0);
            let h = open * w / 2.0;
            p[e] = [x0, y];
            p[e + 1] = [x0 + w / 3.0, y - h];
            p[e + 2] = [x0 + 2.0 * w / 3.0, y - h];
            p[e + 3] = [x0 + w, y];
            p[e + 4] = [x0 + 2.0 * w / 3.0, y + h];
            p[e + 5] = [x0 + w / 3.0, y + h];
        }
        p
    }

    #[test]
    fn aspect_ratio_is_the_lids_opening_over_the_width() {
        let [r, l] = eye_aspect_ratios(&face(0.3, 0.05));
        assert!((r - 0.3).abs() < 1e-6 && (l - 0.05).abs() < 1e-6, "{r} {l}");
    }

    #[test]
    fn each_eye_reads_its_own_points() {
        let o = eye_openness(&face(0.3, 0.02));
        assert!(o.right > 0.5 && o.left < 0.5, "{o:?}");
        let o = eye_openness(&face(0.02, 0.3));
        assert!(o.left > 0.5 && o.right < 0.5, "{o:?}");
    }

    #[test]
    fn closed_reads_below_a_half_and_open_above() {
        assert!(openness_from_ear(0.0) < 0.5);
        assert!(openness_from_ear(0.5 * CLOSED_EAR) < 0.5);
        assert!((openness_from_ear(EYE_OPEN_CENTRE) - 0.5).abs() < 1e-6);
        assert!(openness_from_ear(0.3) > 0.5);
        // Monotone, inside 0..1.
        let mut last = 0.0;
        for k in 0..=50 {
            let v = openness_from_ear(k as f32 * 0.01);
            assert!((0.0..=1.0).contains(&v) && v >= last);
            last = v;
        }
    }

    #[test]
    fn scale_and_translation_do_not_change_it() {
        let p = face(0.2, 0.1);
        let q: [[f32; 2]; N_POINTS] = p.map(|[x, y]| [2.5 * x + 40.0, 2.5 * y - 7.0]);
        let (a, b) = (eye_openness(&p), eye_openness(&q));
        assert!((a.left - b.left).abs() < 1e-5 && (a.right - b.right).abs() < 1e-5);
    }

    #[test]
    fn coincident_corners_read_closed() {
        let o = eye_openness(&[[3.0, 4.0]; N_POINTS]);
        assert!(o.left < 0.5 && o.right < 0.5);
    }
}

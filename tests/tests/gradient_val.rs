//! The learning-free gradient detector on real faces: the faces68 validation split (the first
//! face of each validation image), from ground-truth boxes (the tight box of the 68 points, the
//! detector's convention). Its 27 points with a 68-point counterpart must clearly beat the mean
//! face placed in the same box — the answer it would give with no image evidence at all — and its
//! eye centres must land near the truth. Skips with a printed reason when `../shared` is absent.
//!
//! Run alone with `cargo test -p monotrack-tests --test gradient_val -- --nocapture`.

use monotrack_core::image::Rect;
use monotrack_core::landmarks::{GRADIENT_TO_68, GradientDetector, GradientPoints};
use monotrack_tests::synth::load_validation_faces;

/// Bound on the detector's mean NME as a fraction of the mean face's, with margin above what the
/// shipped detector gives here; a detector whose points stay near the mean face, as with the mean
/// face's own geometry in place of the eyes', sits at 1.
const MAX_NME_RATIO: f64 = 0.85;
/// Fewest faces, as a fraction, where the detector must beat the mean face (with margin below
/// what the shipped detector gives).
const MIN_BETTER: f64 = 0.75;
/// Bound on the median eye-centre error, fraction of the outer eye-corner distance: above what
/// the shipped detector gives, far below the mean face in the box.
const MAX_MEDIAN_EYE_ERROR: f64 = 0.07;

fn dist(a: [f32; 2], b: [f32; 2]) -> f64 {
    f64::from((a[0] - b[0]).hypot(a[1] - b[1]))
}

#[test]
#[cfg_attr(not(shared_data), ignore = "needs ../shared/data")]
fn gradient_points_beat_the_mean_face_on_validation_faces() {
    let data = monotrack_tests::shared_data();
    let faces = load_validation_faces(&data, usize::MAX, 0.0).expect("faces68 validation faces");
    assert!(faces.len() > 80, "{} faces", faces.len());
    let mut det = GradientDetector::new();
    let mut out = GradientPoints::default();
    let (mut sum, mut sum_prior, mut better) = (0f64, 0f64, 0usize);
    let mut eye_errors = Vec::new();
    for f in &faces {
        let lm = &f.landmarks;
        let bx = Rect::bounding(lm);
        det.detect(&f.image, &bx, 0.0, &mut out).unwrap();
        let prior = GradientPoints::mean_face(&bx);
        let iod = dist(lm[36], lm[45]);
        let (mut e, mut e0) = (0f64, 0f64);
        for (g, m) in GRADIENT_TO_68.iter().enumerate() {
            if let Some(k) = *m {
                e += dist(out.points[g], lm[k]) / iod / 27.0;
                e0 += dist(prior.points[g], lm[k]) / iod / 27.0;
            }
        }
        sum += e;
        sum_prior += e0;
        better += usize::from(e < e0);
        for (eye, first) in [36, 42].into_iter().enumerate() {
            let c = lm[first..first + 6]
                .iter()
                .fold([0f32; 2], |a, p| [a[0] + p[0] / 6.0, a[1] + p[1] / 6.0]);
            eye_errors.push(dist(out.eye_centres[eye], c) / iod);
        }
    }
    let n = faces.len() as f64;
    let (nme, nme_prior) = (sum / n, sum_prior / n);
    eye_errors.sort_by(f64::total_cmp);
    let eye_median = eye_errors[eye_errors.len() / 2];
    eprintln!(
        "{} faces: NME {:.2} % against the mean face's {:.2} % (ratio {:.2}), better on {better}; \
         eye centres median error {:.1} %",
        faces.len(),
        100.0 * nme,
        100.0 * nme_prior,
        nme / nme_prior,
        100.0 * eye_median
    );
    assert!(
        nme < MAX_NME_RATIO * nme_prior,
        "NME {nme:.4} vs mean face {nme_prior:.4}"
    );
    assert!(better as f64 >= MIN_BETTER * n, "better on {better} of {n}");
    assert!(
        eye_median < MAX_MEDIAN_EYE_ERROR,
        "eye centres median {eye_median:.3}"
    );
}

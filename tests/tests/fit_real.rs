//! MSBP on the real 68-point annotations of `../shared/data/faces68` (validation split of
//! `core/models/M3_IO.md`: line i is validation when i % 10 == 0), CONTRACT default intrinsics per
//! image. Checks and prints: median reprojection RMS (relative to the face's inter-ocular distance,
//! since image faces range from ~40 to ~400 px), agreement of the fitted yaw with the MediaPipe
//! teacher's yaw, frontal faces near yaw 0, and fitted units mostly inside their plausible ±1.5.
//! Skips with a printed reason when `../shared` is absent.

use monotrack_core::camera::Intrinsics;
use monotrack_core::fit::{Msbp, MsbpConfig};
use monotrack_core::model::N_LANDMARKS;
use serde::Deserialize;
use std::collections::HashMap;

#[derive(Deserialize)]
struct Face {
    landmarks68: Vec<[f64; 2]>,
}
#[derive(Deserialize)]
struct Line {
    image: String,
    width: u32,
    height: u32,
    faces: Vec<Face>,
}
#[derive(Deserialize)]
struct Teacher {
    image: String,
    face_index: usize,
    yaw_deg: Option<f64>,
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

#[test]
#[cfg_attr(not(shared_data), ignore = "needs ../shared/data")]
fn msbp_on_real_landmarks() {
    let data = monotrack_tests::shared_data();
    let train = std::fs::read_to_string(data.join("faces68/train.jsonl")).unwrap();
    let mut teacher = HashMap::new();
    for l in std::fs::read_to_string(data.join("faces68/teacher_mediapipe.jsonl"))
        .unwrap()
        .lines()
    {
        let t: Teacher = serde_json::from_str(l).unwrap();
        if let Some(y) = t.yaw_deg {
            teacher.insert((t.image, t.face_index), y);
        }
    }
    let mut msbp = Msbp::new(MsbpConfig::default());
    let (mut rms_rel, mut rms_px, mut yaw_diff, mut frontal_yaw, mut unit_abs) =
        (vec![], vec![], vec![], vec![], vec![]);
    for (i, text) in train.lines().enumerate() {
        if i % 10 != 0 {
            continue;
        }
        let line: Line = serde_json::from_str(text).unwrap();
        let cam = Intrinsics::default_for(line.width, line.height).unwrap();
        for (k, face) in line.faces.iter().enumerate() {
            let pts: [[f64; 2]; N_LANDMARKS] = std::array::from_fn(|j| face.landmarks68[j]);
            let fit = msbp.fit(&pts, None, &cam, None).unwrap();
            let iod =
                ((pts[45][0] - pts[36][0]).powi(2) + (pts[45][1] - pts[36][1]).powi(2)).sqrt();
            rms_px.push(fit.report.rms_px);
            rms_rel.push(fit.report.rms_px / iod);
            unit_abs.extend(fit.shape.iter().chain(&fit.animation).map(|v| v.abs()));
            let (yaw, _, _) = fit.pose.euler_deg();
            if let Some(&ty) = teacher.get(&(line.image.clone(), k)) {
                yaw_diff.push((yaw - ty).abs());
                if ty.abs() < 10.0 {
                    frontal_yaw.push(yaw.abs());
                }
            }
        }
    }
    let n = rms_px.len();
    let within = unit_abs.iter().filter(|v| **v <= 1.5).count() as f64 / unit_abs.len() as f64;
    let (m_rel, m_px) = (median(&mut rms_rel), median(&mut rms_px));
    let m_yaw = median(&mut yaw_diff);
    let m_front = median(&mut frontal_yaw);
    println!("MSBP on faces68 validation split: {n} faces");
    println!(
        "  median reprojection RMS {m_px:.2} px = {:.2}% of inter-ocular distance",
        m_rel * 100.0
    );
    println!(
        "  yaw vs MediaPipe teacher ({} faces): median |diff| {m_yaw:.2} deg; teacher-frontal (|yaw| < 10 deg, {} faces): median |yaw| {m_front:.2} deg",
        yaw_diff.len(),
        frontal_yaw.len()
    );
    println!("  units within +-1.5: {:.1}%", within * 100.0);
    assert!(n > 100, "validation split has {n} faces");
    assert!(m_rel < 0.05, "median RMS {m_rel} of IOD");
    assert!(m_yaw < 3.5, "median yaw difference {m_yaw}");
    assert!(m_front < 7.0, "frontal faces median |yaw| {m_front}");
    assert!(within > 0.88, "{within}");
}

//! Synthetic round trips for the 3D fits: random poses (yaw, pitch ±60°,
//! roll ±30°, depth 0.3–1.5 m), shapes and expressions (each unit ~ N(0, 0.5²) clipped to ±1),
//! projected through a 1280×720 camera with the CONTRACT's default intrinsics, plus 1 px Gaussian
//! noise. MSBP must recover rotation within 1° and depth within 2% (medians); FFBP's figures are
//! printed beside it (weak perspective is expected to be worse at 0.3 m).

use monotrack_core::camera::Intrinsics;
use monotrack_core::fit::{Ffbp, FfbpConfig, Msbp, MsbpConfig, Pose};
use monotrack_core::model::{FaceModel, N_ANIM, N_LANDMARKS, N_SHAPE};
use nalgebra::Vector3;
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use rand_distr::{Distribution, Normal};

const SAMPLES: usize = 300;
const SEED: u64 = 20261122;

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

struct Case {
    truth: Pose,
    obs: [[f64; 2]; N_LANDMARKS],
}

fn cases(cam: &Intrinsics) -> Vec<Case> {
    let mut rng = StdRng::seed_from_u64(SEED);
    let unit = Normal::<f64>::new(0.0, 0.5).unwrap();
    let noise = Normal::<f64>::new(0.0, 1.0).unwrap();
    let model = FaceModel::builtin();
    (0..SAMPLES)
        .map(|_| {
            let z: f64 = rng.random_range(300.0..1500.0);
            // Keep the face inside the image: lateral offset up to 30% of the half field of view.
            let tx = rng.random_range(-0.3..0.3) * z * cam.cx / cam.fx;
            let ty = rng.random_range(-0.3..0.3) * z * cam.cy / cam.fy;
            let truth = Pose::from_euler_deg(
                rng.random_range(-60.0..60.0),
                rng.random_range(-60.0..60.0),
                rng.random_range(-30.0..30.0),
                Vector3::new(tx, ty, z),
            );
            let shape: [f64; N_SHAPE] =
                std::array::from_fn(|_| unit.sample(&mut rng).clamp(-1.0, 1.0));
            let anim: [f64; N_ANIM] =
                std::array::from_fn(|_| unit.sample(&mut rng).clamp(-1.0, 1.0));
            let mut obs = [[0.0; 2]; N_LANDMARKS];
            model.project_into(
                &shape,
                &anim,
                &truth.rotation,
                &truth.translation,
                cam,
                &mut obs,
            );
            for p in obs.iter_mut() {
                p[0] += noise.sample(&mut rng);
                p[1] += noise.sample(&mut rng);
            }
            Case { truth, obs }
        })
        .collect()
}

#[test]
fn msbp_and_ffbp_synthetic_round_trip() {
    let cam = Intrinsics::default_for(1280, 720).unwrap();
    let cases = cases(&cam);
    let mut msbp = Msbp::new(MsbpConfig::default());
    let mut ffbp = Ffbp::new(FfbpConfig::default());
    let (mut m_rot, mut m_depth, mut m_rms) = (vec![], vec![], vec![]);
    let (mut f_rot, mut f_depth, mut f_rms) = (vec![], vec![], vec![]);
    for c in &cases {
        let fit = msbp.fit(&c.obs, None, &cam, None).unwrap();
        m_rot.push(fit.pose.rotation_angle_to(&c.truth));
        m_depth.push((fit.pose.translation.z / c.truth.translation.z - 1.0).abs());
        m_rms.push(fit.report.rms_px);
        let fit = ffbp.fit(&c.obs, None, &cam).unwrap();
        f_rot.push(fit.pose.rotation_angle_to(&c.truth));
        f_depth.push((fit.pose.translation.z / c.truth.translation.z - 1.0).abs());
        f_rms.push(fit.report.rms_px);
    }
    let (mr, md, mm) = (median(&mut m_rot), median(&mut m_depth), median(&mut m_rms));
    let (fr, fd, fm) = (median(&mut f_rot), median(&mut f_depth), median(&mut f_rms));
    println!("synthetic round trip, {SAMPLES} faces, 1 px noise:");
    println!(
        "  MSBP: median rotation error {mr:.3} deg, median depth error {:.2}%, median RMS {mm:.2} px, p90 rotation {:.2} deg",
        md * 100.0,
        m_rot[SAMPLES * 9 / 10]
    );
    println!(
        "  FFBP: median rotation error {fr:.3} deg, median depth error {:.2}%, median RMS {fm:.2} px, p90 rotation {:.2} deg",
        fd * 100.0,
        f_rot[SAMPLES * 9 / 10]
    );
    assert!(mr < 1.0, "MSBP median rotation error {mr} deg");
    assert!(md < 0.02, "MSBP median depth error {md}");
    // FFBP is the light mode: only sanity bounds here, its figures are reported above.
    assert!(fr < 10.0 && fd < 0.2, "FFBP {fr} deg {fd}");
}

//! Body fitting (CLFBA, `core::body`) for Kotlin and Swift: floor calibration and a per-sequence
//! `BodyTracker` that estimates the body's dimensions once over its first frames and then fits the
//! pose alone per frame (what `monotrack body-fit` does for a `"sequence"`).

use crate::MonotrackError;
use crate::error::{guard, guard_infallible};
use crate::types::{CameraIntrinsics, Point2, Vec3, named};
use monotrack_core::body::calib::calibrate_floor_extrinsics;
use monotrack_core::body::fit::DEFAULT_PRIOR_WEIGHT_PX;
use monotrack_core::body::skeleton::{N_POSE, dim};
use monotrack_core::body::{
    BodyCamera, BodyFitConfig, BodyFitter, Convention, DimensionEstimator, Dimensions, Joint,
    Joints2d, N_JOINTS, Skeleton, calibrate_floor,
};
use monotrack_core::camera::Intrinsics;
use nalgebra::{Matrix3, Vector3};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Instant;

/// The 15 body joints (CONTRACT.md names; HumanEva-I definitions by default).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, uniffi::Enum)]
pub enum BodyJoint {
    /// Pelvis (the root).
    Pelvis,
    /// Top of the spine.
    Thorax,
    /// Left shoulder.
    LShoulder,
    /// Left elbow.
    LElbow,
    /// Left wrist.
    LWrist,
    /// Right shoulder.
    RShoulder,
    /// Right elbow.
    RElbow,
    /// Right wrist.
    RWrist,
    /// Left hip.
    LHip,
    /// Left knee.
    LKnee,
    /// Left ankle.
    LAnkle,
    /// Right hip.
    RHip,
    /// Right knee.
    RKnee,
    /// Right ankle.
    RAnkle,
    /// Head.
    Head,
}

impl From<BodyJoint> for Joint {
    fn from(j: BodyJoint) -> Self {
        match j {
            BodyJoint::Pelvis => Joint::Pelvis,
            BodyJoint::Thorax => Joint::Thorax,
            BodyJoint::LShoulder => Joint::LShoulder,
            BodyJoint::LElbow => Joint::LElbow,
            BodyJoint::LWrist => Joint::LWrist,
            BodyJoint::RShoulder => Joint::RShoulder,
            BodyJoint::RElbow => Joint::RElbow,
            BodyJoint::RWrist => Joint::RWrist,
            BodyJoint::LHip => Joint::LHip,
            BodyJoint::LKnee => Joint::LKnee,
            BodyJoint::LAnkle => Joint::LAnkle,
            BodyJoint::RHip => Joint::RHip,
            BodyJoint::RKnee => Joint::RKnee,
            BodyJoint::RAnkle => Joint::RAnkle,
            BodyJoint::Head => Joint::Head,
        }
    }
}

impl From<Joint> for BodyJoint {
    fn from(j: Joint) -> Self {
        const ALL: [BodyJoint; N_JOINTS] = [
            BodyJoint::Pelvis,
            BodyJoint::Thorax,
            BodyJoint::LShoulder,
            BodyJoint::LElbow,
            BodyJoint::LWrist,
            BodyJoint::RShoulder,
            BodyJoint::RElbow,
            BodyJoint::RWrist,
            BodyJoint::LHip,
            BodyJoint::LKnee,
            BodyJoint::LAnkle,
            BodyJoint::RHip,
            BodyJoint::RKnee,
            BodyJoint::RAnkle,
            BodyJoint::Head,
        ];
        ALL[j.index()]
    }
}

/// How the caller's joints are defined.
#[derive(Debug, Clone, Copy, PartialEq, Eq, uniffi::Enum)]
pub enum BodyConvention {
    /// HumanEva-I (CONTRACT.md's `body-fit`).
    HumanEva,
    /// Human3.6M (pelvis at the hips' midpoint).
    Human36m,
}

impl From<BodyConvention> for Convention {
    fn from(c: BodyConvention) -> Self {
        match c {
            BodyConvention::HumanEva => Convention::HumanEva,
            BodyConvention::Human36m => Convention::Human36M,
        }
    }
}

/// A calibrated camera in a world frame whose floor is z = 0 with z up: X_cam = R·X + t.
#[derive(Debug, Clone, PartialEq, uniffi::Record)]
pub struct BodyCameraPose {
    /// Intrinsics, pixels.
    pub intrinsics: CameraIntrinsics,
    /// World → camera rotation R, 9 values row-major.
    pub rotation: Vec<f64>,
    /// World → camera translation t, millimetres.
    pub translation_mm: Vec3,
}

impl TryFrom<&BodyCameraPose> for BodyCamera {
    type Error = MonotrackError;
    fn try_from(c: &BodyCameraPose) -> Result<Self, MonotrackError> {
        if c.rotation.len() != 9 {
            return Err(MonotrackError::InvalidConfig {
                msg: format!("rotation needs 9 values, got {}", c.rotation.len()),
            });
        }
        let r = Matrix3::from_fn(|i, j| c.rotation[3 * i + j]);
        let t = Vector3::new(c.translation_mm.x, c.translation_mm.y, c.translation_mm.z);
        let k = Intrinsics::new(
            c.intrinsics.fx,
            c.intrinsics.fy,
            c.intrinsics.cx,
            c.intrinsics.cy,
        )?;
        Ok(BodyCamera::new(k, r, t)?)
    }
}

impl From<&BodyCamera> for BodyCameraPose {
    fn from(c: &BodyCamera) -> Self {
        Self {
            intrinsics: c.intrinsics.into(),
            rotation: (0..9).map(|k| c.rotation[(k / 3, k % 3)]).collect(),
            translation_mm: Vec3 {
                x: c.translation.x,
                y: c.translation.y,
                z: c.translation.z,
            },
        }
    }
}

/// A floor calibration's result.
#[derive(Debug, Clone, PartialEq, uniffi::Record)]
pub struct FloorCalibrationResult {
    /// The camera, in the floor rectangle's frame (origin at corner 0, x towards corner 1, z up).
    pub camera: BodyCameraPose,
    /// RMS reprojection error of the four corners, pixels.
    pub rms_px: f64,
    /// Whether the corners ran clockwise seen from above.
    pub flipped: bool,
}

/// Calibrates the camera from the four image corners of a floor rectangle (thesis 5.1.1): corner 1
/// is `width_mm` from corner 0, corner 2 is `depth_mm` from corner 1. With `intrinsics` only the
/// pose is solved; without, the focal length too, with the principal point at the image centre.
///
/// # Errors
/// `InvalidConfig` for not exactly four corners, non-finite or degenerate corners, sizes that are
/// not positive, an empty image, or corners that admit no camera.
#[uniffi::export]
pub fn calibrate_floor_camera(
    corners_px: Vec<Point2>,
    width_mm: f64,
    depth_mm: f64,
    image_width: u32,
    image_height: u32,
    intrinsics: Option<CameraIntrinsics>,
) -> Result<FloorCalibrationResult, MonotrackError> {
    guard(|| {
        let corners: [[f64; 2]; 4] = corners_px
            .iter()
            .map(|p| [f64::from(p.x), f64::from(p.y)])
            .collect::<Vec<_>>()
            .try_into()
            .map_err(|_| MonotrackError::InvalidConfig {
                msg: format!("need 4 floor corners, got {}", corners_px.len()),
            })?;
        let size = [width_mm, depth_mm];
        let cal = match intrinsics {
            Some(k) => {
                let k = Intrinsics::new(k.fx, k.fy, k.cx, k.cy)?;
                calibrate_floor_extrinsics(&corners, size, &k)?
            }
            None => {
                if image_width == 0 || image_height == 0 {
                    return Err(MonotrackError::InvalidConfig {
                        msg: format!("image size {image_width}x{image_height} is empty"),
                    });
                }
                calibrate_floor(
                    &corners,
                    size,
                    [f64::from(image_width) / 2.0, f64::from(image_height) / 2.0],
                )?
            }
        };
        Ok(FloorCalibrationResult {
            camera: BodyCameraPose::from(&cal.camera),
            rms_px: cal.rms_px,
            flipped: cal.flipped,
        })
    })
}

/// One observed 2D joint, pixels (CONTRACT image convention). Joints not observed are left out.
#[derive(Debug, Clone, Copy, PartialEq, uniffi::Record)]
pub struct BodyJoint2d {
    /// Which joint.
    pub joint: BodyJoint,
    /// Position, pixels.
    pub position: Point2,
}

/// One fitted 3D joint, world frame, millimetres.
#[derive(Debug, Clone, Copy, PartialEq, uniffi::Record)]
pub struct BodyJoint3d {
    /// Which joint.
    pub joint: BodyJoint,
    /// Position, mm.
    pub position_mm: Vec3,
}

/// `BodyTracker` settings.
#[derive(Debug, Clone, Copy, PartialEq, uniffi::Record)]
pub struct BodyTrackerConfig {
    /// Frames over which the body's dimensions are estimated before being held (≥ 1). Until then
    /// frames are fitted with mean adult dimensions.
    pub dimension_frames: u32,
    /// How the joints are defined.
    pub convention: BodyConvention,
    /// Assume the lower foot touches the floor (standing, walking; false for jumps or sitting).
    pub assume_contact: bool,
    /// Strength of the learnt pose prior, px per standard deviation (≥ 0): about the error of the
    /// 2D joints. 5 suits keypoint detectors and annotations; exact synthetic joints want ≤ 1.
    pub prior_weight_px: f64,
    /// Refine each frame in the full 21-joint, 54-DoF model (clavicles, pelvis girdle, three-joint
    /// spine free): a little more accurate on HumanEva-I, for a longer pose fit (BENCHMARKS.md,
    /// "Body (CLFBA)").
    pub full_model: bool,
}

/// `BodyTrackerConfig` defaults: 5 dimension frames, HumanEva joints, floor contact, prior weight
/// 5 px, the reduced (27-DoF) model.
#[uniffi::export]
pub fn default_body_tracker_config() -> BodyTrackerConfig {
    BodyTrackerConfig {
        dimension_frames: 5,
        convention: BodyConvention::HumanEva,
        assume_contact: true,
        prior_weight_px: DEFAULT_PRIOR_WEIGHT_PX,
        full_model: false,
    }
}

/// One frame's body fit.
#[derive(Debug, Clone, PartialEq, uniffi::Record)]
pub struct BodyFitResult {
    /// The 15 joints, world frame (floor z = 0, z up), mm.
    pub joints: Vec<BodyJoint3d>,
    /// The body-part lengths used, mm (snake_case names as in the CLI's `dimensions_mm`).
    pub dimensions_mm: Vec<crate::types::NamedValue>,
    /// Whether `dimensions_mm` are this body's estimate (false: mean adult dimensions, still
    /// collecting frames).
    pub dimensions_estimated: bool,
    /// RMS reprojection error over the observed joints, pixels.
    pub reprojection_rms_px: f64,
    /// The foot assumed on the floor, if any.
    pub contact: Option<BodyJoint>,
    /// Time of the pose fit, µs.
    pub pose_us: u64,
    /// Time of the dimension estimation if it ran on this frame (else 0), µs.
    pub dimensions_us: u64,
}

struct BodyState {
    camera: BodyCamera,
    convention: Convention,
    dimension_frames: usize,
    fitter: BodyFitter,
    skeleton: Skeleton,
    estimated: bool,
    collected: Vec<Joints2d>,
    /// The last frame's pose: the next frame is refined from it (`BodyFitter::fit_tracked`).
    previous: Option<[f64; N_POSE]>,
}

/// Fits a body seen by one calibrated camera, frame after frame. Thread-safe (state behind a
/// mutex); one instance per person and camera.
#[derive(uniffi::Object)]
pub struct BodyTracker {
    state: Mutex<BodyState>,
}

impl BodyTracker {
    fn lock(&self) -> MutexGuard<'_, BodyState> {
        // A panic mid-fit leaves only a partly collected frame list: still usable.
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }
}

fn mean_skeleton(convention: Convention) -> Result<Skeleton, MonotrackError> {
    Ok(Skeleton::new(Dimensions::mean(convention), convention)?)
}

#[uniffi::export]
impl BodyTracker {
    /// A tracker for `camera` (from `calibrate_floor_camera` or known) with `config`.
    ///
    /// # Errors
    /// `InvalidConfig` for a camera whose rotation is not a rotation, bad intrinsics, or
    /// `dimension_frames` of 0.
    #[uniffi::constructor]
    pub fn new(
        camera: BodyCameraPose,
        config: BodyTrackerConfig,
    ) -> Result<Arc<Self>, MonotrackError> {
        guard(|| {
            if config.dimension_frames == 0 {
                return Err(MonotrackError::InvalidConfig {
                    msg: "dimension_frames must be at least 1".into(),
                });
            }
            if !(config.prior_weight_px.is_finite() && config.prior_weight_px >= 0.0) {
                return Err(MonotrackError::InvalidConfig {
                    msg: format!(
                        "prior_weight_px must be finite and >= 0, got {}",
                        config.prior_weight_px
                    ),
                });
            }
            let convention = Convention::from(config.convention);
            Ok(Arc::new(Self {
                state: Mutex::new(BodyState {
                    camera: BodyCamera::try_from(&camera)?,
                    convention,
                    dimension_frames: config.dimension_frames as usize,
                    fitter: BodyFitter::new(BodyFitConfig {
                        assume_contact: config.assume_contact,
                        prior_weight_px: config.prior_weight_px,
                        full_model: config.full_model,
                        ..BodyFitConfig::default()
                    }),
                    skeleton: mean_skeleton(convention)?,
                    estimated: false,
                    collected: Vec::with_capacity(config.dimension_frames as usize),
                    previous: None,
                }),
            }))
        })
    }

    /// Fits one frame's observed joints (at least the torso: pelvis or both hips, thorax or both
    /// shoulders). On the `dimension_frames`-th frame the dimensions are estimated over the frames
    /// so far (pose + dimensions, thesis Alg. 10) and held afterwards. Each frame is refined from
    /// the previous frame's pose, and fitted from scratch as well when that fit is poor (more
    /// accurate on HumanEva-I than every frame from scratch; BENCHMARKS.md, "Body (CLFBA)").
    ///
    /// # Errors
    /// `InvalidConfig` for a joint given twice, non-finite positions, or too few joints to place
    /// the torso.
    pub fn fit(&self, joints: Vec<BodyJoint2d>) -> Result<BodyFitResult, MonotrackError> {
        guard(|| {
            let mut obs = Joints2d {
                points: [[0.0; 2]; N_JOINTS],
                weights: [0.0; N_JOINTS],
            };
            for j in &joints {
                let i = Joint::from(j.joint).index();
                if obs.weights[i] > 0.0 {
                    return Err(MonotrackError::InvalidConfig {
                        msg: format!("joint {:?} given twice", j.joint),
                    });
                }
                obs.points[i] = [f64::from(j.position.x), f64::from(j.position.y)];
                obs.weights[i] = 1.0;
            }
            obs.validate()?;
            let mut s = self.lock();
            let mut dimensions_us = 0;
            if !s.estimated {
                s.collected.push(obs);
                if s.collected.len() >= s.dimension_frames {
                    let t = Instant::now();
                    let est = DimensionEstimator::default().estimate(
                        &s.fitter,
                        &s.collected,
                        &s.camera,
                        &Dimensions::mean(s.convention),
                        s.convention,
                    )?;
                    s.skeleton = Skeleton::new(est.dimensions, s.convention)?;
                    s.estimated = true;
                    s.collected.clear();
                    dimensions_us = t.elapsed().as_micros() as u64;
                }
            }
            let t = Instant::now();
            let fit = s
                .fitter
                .fit_tracked(&obs, &s.camera, &s.skeleton, s.previous.as_ref())?;
            s.previous = Some(fit.pose);
            let pose_us = t.elapsed().as_micros() as u64;
            Ok(BodyFitResult {
                joints: Joint::ALL
                    .iter()
                    .zip(&fit.joints)
                    .map(|(j, p)| BodyJoint3d {
                        joint: (*j).into(),
                        position_mm: Vec3 {
                            x: p.x,
                            y: p.y,
                            z: p.z,
                        },
                    })
                    .collect(),
                dimensions_mm: named(&dim::NAMES, &s.skeleton.dims.lengths),
                dimensions_estimated: s.estimated,
                reprojection_rms_px: fit.reprojection_rms_px,
                contact: fit.contact.map(BodyJoint::from),
                pose_us,
                dimensions_us,
            })
        })
    }

    /// Forgets the estimated dimensions and the last pose (a new person or a cut): the next frames
    /// estimate them again.
    pub fn reset(&self) {
        guard_infallible(|| {
            let mut s = self.lock();
            s.collected.clear();
            s.estimated = false;
            s.previous = None;
            if let Ok(sk) = mean_skeleton(s.convention) {
                s.skeleton = sk;
            }
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use monotrack_core::body::skeleton;

    /// A camera 3 m from the origin, 1.2 m up, looking horizontally along +y.
    fn camera() -> BodyCameraPose {
        BodyCameraPose {
            intrinsics: CameraIntrinsics {
                fx: 1000.0,
                fy: 1000.0,
                cx: 320.0,
                cy: 240.0,
            },
            // World x → camera x, world z (up) → camera −y, world y → camera z.
            rotation: vec![1.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 1.0, 0.0],
            translation_mm: Vec3 {
                x: 0.0,
                y: 1200.0,
                z: 3000.0,
            },
        }
    }

    #[test]
    fn joint_enums_round_trip_in_order() {
        for (i, j) in Joint::ALL.iter().enumerate() {
            let b = BodyJoint::from(*j);
            assert_eq!(Joint::from(b).index(), i);
        }
    }

    #[test]
    fn bad_inputs_are_typed_errors() {
        let cfg = default_body_tracker_config();
        assert!(matches!(
            BodyTracker::new(
                camera(),
                BodyTrackerConfig {
                    dimension_frames: 0,
                    ..cfg
                }
            ),
            Err(MonotrackError::InvalidConfig { .. })
        ));
        for w in [f64::NAN, -1.0, f64::INFINITY] {
            assert!(matches!(
                BodyTracker::new(
                    camera(),
                    BodyTrackerConfig {
                        prior_weight_px: w,
                        ..cfg
                    }
                ),
                Err(MonotrackError::InvalidConfig { .. })
            ));
        }
        let mut bad = camera();
        bad.rotation[0] = 2.0;
        assert!(matches!(
            BodyTracker::new(bad, cfg),
            Err(MonotrackError::InvalidConfig { .. })
        ));
        let mut nan = camera();
        nan.intrinsics.fx = f64::NAN;
        assert!(BodyTracker::new(nan, cfg).is_err());
        let t = BodyTracker::new(camera(), cfg).unwrap();
        let p = Point2 { x: 320.0, y: 240.0 };
        let twice = vec![
            BodyJoint2d {
                joint: BodyJoint::Pelvis,
                position: p,
            };
            2
        ];
        assert!(matches!(
            t.fit(twice),
            Err(MonotrackError::InvalidConfig { .. })
        ));
        assert!(t.fit(vec![]).is_err());
        let nan_joint = vec![BodyJoint2d {
            joint: BodyJoint::Head,
            position: Point2 {
                x: f32::NAN,
                y: 0.0,
            },
        }];
        assert!(t.fit(nan_joint).is_err());
        assert!(matches!(
            calibrate_floor_camera(vec![p; 3], 1000.0, 1000.0, 640, 480, None),
            Err(MonotrackError::InvalidConfig { .. })
        ));
        assert!(calibrate_floor_camera(vec![p; 4], 1000.0, 1000.0, 640, 480, None).is_err());
    }

    #[test]
    fn floor_corners_of_a_known_camera_give_it_back() {
        let cam = BodyCamera::try_from(&camera()).unwrap();
        let corners: Vec<Point2> = [
            [-1000.0, 1000.0],
            [1000.0, 1000.0],
            [1000.0, 3000.0],
            [-1000.0, 3000.0],
        ]
        .iter()
        .map(|c| {
            let p = cam.project(&Vector3::new(c[0], c[1], 0.0));
            Point2 {
                x: p[0] as f32,
                y: p[1] as f32,
            }
        })
        .collect();
        let cal = calibrate_floor_camera(corners, 2000.0, 2000.0, 640, 480, None).unwrap();
        assert!(cal.rms_px < 0.05, "{cal:?}");
        assert!((cal.camera.intrinsics.fx - 1000.0).abs() < 5.0, "{cal:?}");
        // The floor frame has its origin at corner 0, (−1000, 1000) in the test's world frame.
        let back = BodyCamera::try_from(&cal.camera).unwrap();
        let c = back.center();
        assert!((c.x - 1000.0).abs() < 20.0, "{c:?}");
        assert!((c.y - (-4000.0)).abs() < 20.0, "{c:?}");
        assert!((c.z - 1200.0).abs() < 20.0, "{c:?}");
    }
    /// A pose facing the camera (body forward = world −y) with the lower ankle on the floor.
    fn pose(skel: &Skeleton, arm: f64) -> [f64; skeleton::N_POSE] {
        use skeleton::{P_LARM, P_LLEG, P_RARM, P_RLEG, P_ROOT_POS, P_SPINE, log_so3};
        let mut p = [0.0; skeleton::N_POSE];
        let r0 = Matrix3::from_columns(&[
            Vector3::new(1.0, 0.0, 0.0),
            Vector3::new(0.0, 0.0, 1.0),
            Vector3::new(0.0, -1.0, 0.0),
        ]);
        p[0..3].copy_from_slice(log_so3(&r0).as_slice());
        p[P_ROOT_POS + 1] = 2000.0;
        p[P_SPINE] = 0.1;
        p[P_LARM..P_LARM + 4].copy_from_slice(&[-0.3, -1.2 + arm, 0.2, 0.6]);
        p[P_RARM..P_RARM + 4].copy_from_slice(&[0.2, 1.3 - arm, -0.1, 0.3]);
        p[P_LLEG..P_LLEG + 4].copy_from_slice(&[-0.35 + arm, 0.05, 0.0, 0.2]);
        p[P_RLEG..P_RLEG + 4].copy_from_slice(&[0.25, -0.05, 0.0, 0.5]);
        let mut x = [Vector3::zeros(); N_JOINTS];
        skel.forward(&p, &mut x);
        p[P_ROOT_POS + 2] = skel.ankle_height - x[10].z.min(x[13].z);
        p
    }

    #[test]
    fn a_sequence_gets_its_dimensions_then_poses() {
        sequence_case(false);
    }

    #[test]
    fn a_sequence_in_the_full_model_gets_its_dimensions_then_poses() {
        sequence_case(true);
    }

    fn sequence_case(full_model: bool) {
        let conv = Convention::HumanEva;
        let truth = Skeleton::new(Dimensions::mean(conv).scaled(1.1), conv).unwrap();
        let rec = camera();
        let cam = BodyCamera::try_from(&rec).unwrap();
        let t = BodyTracker::new(
            rec,
            BodyTrackerConfig {
                dimension_frames: 3,
                // Exact projections: a weak prior (the default expects keypoint-detector noise).
                prior_weight_px: 0.5,
                full_model,
                ..default_body_tracker_config()
            },
        )
        .unwrap();
        for k in 0..5 {
            let mut x = [Vector3::zeros(); N_JOINTS];
            truth.forward(&pose(&truth, 0.15 * k as f64), &mut x);
            let joints: Vec<BodyJoint2d> = Joint::ALL
                .iter()
                .map(|j| {
                    let p = cam.project(&x[j.index()]);
                    BodyJoint2d {
                        joint: (*j).into(),
                        position: Point2 {
                            x: p[0] as f32,
                            y: p[1] as f32,
                        },
                    }
                })
                .collect();
            let r = t.fit(joints).unwrap();
            assert_eq!(r.dimensions_estimated, k >= 2, "frame {k}");
            assert_eq!(r.dimensions_us > 0, k == 2, "frame {k}");
            assert_eq!(r.joints.len(), N_JOINTS);
            if k >= 2 {
                let err: f64 = r
                    .joints
                    .iter()
                    .map(|j| {
                        let p = x[Joint::from(j.joint).index()];
                        let d = Vector3::new(j.position_mm.x, j.position_mm.y, j.position_mm.z) - p;
                        d.norm()
                    })
                    .sum::<f64>()
                    / N_JOINTS as f64;
                eprintln!(
                    "frame {k}: mean joint error {err:.1} mm, rms {:.2} px",
                    r.reprojection_rms_px
                );
                assert!(err < 40.0, "frame {k}: mean joint error {err} mm");
                assert!(r.reprojection_rms_px < 1.0, "{r:?}");
                let back = r.dimensions_mm.iter().find(|d| d.name == "back").unwrap();
                let want = truth.dims.lengths[dim::BACK];
                assert!(
                    (back.value - want).abs() < 0.06 * want,
                    "back {} vs {want}",
                    back.value
                );
            }
        }
        t.reset();
        let mut x = [Vector3::zeros(); N_JOINTS];
        truth.forward(&pose(&truth, 0.0), &mut x);
        let joints: Vec<BodyJoint2d> = Joint::ALL
            .iter()
            .map(|j| {
                let p = cam.project(&x[j.index()]);
                BodyJoint2d {
                    joint: (*j).into(),
                    position: Point2 {
                        x: p[0] as f32,
                        y: p[1] as f32,
                    },
                }
            })
            .collect();
        assert!(!t.fit(joints).unwrap().dimensions_estimated);
    }
}

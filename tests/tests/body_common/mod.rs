//! Shared by the `body_*` tests: converting ../shared/data/body with `tests/scripts/body_data.py`
//! (numpy + h5py) into JSON under the cargo target dir, reading it, and 3D error helpers.
#![allow(dead_code)]

use monotrack_core::body::prior::fit_to_joints;
use monotrack_core::body::skeleton::{N_DIMS, N_POSE, dim};
use monotrack_core::body::{Convention, Dimensions, N_JOINTS, PosePrior, Skeleton};
use nalgebra::{Matrix3, Vector3};
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::process::Command;
use std::sync::Mutex;

/// HumanEva-I cameras: world → camera rotation and camera centre.
#[derive(Deserialize)]
pub struct HeCamera {
    pub rotation: [[f64; 3]; 3],
    pub center_mm: [f64; 3],
}

/// One HumanEva-I chunk seen by one camera.
#[derive(Deserialize)]
pub struct HeSequence {
    pub subject: String,
    pub action: String,
    pub camera: usize,
    pub frames: Vec<usize>,
    pub joints3d_mm: Vec<[[f64; 3]; N_JOINTS]>,
    pub joints2d: Vec<[[f64; 2]; N_JOINTS]>,
}

/// HumanEva-I Train, subsampled.
#[derive(Deserialize)]
pub struct HumanEva {
    pub cameras: std::collections::BTreeMap<String, Vec<HeCamera>>,
    pub sequences: Vec<HeSequence>,
}

impl HumanEva {
    /// Mean body-part lengths per subject ([`mean_lengths`] of the subject's mocap frames). Each
    /// chunk appears once per camera with the same 3D joints, so camera 0's copy alone counts.
    pub fn subject_lengths(&self) -> BTreeMap<String, [f64; N_DIMS]> {
        per_subject(self.cameras.keys(), |s| {
            self.sequences
                .iter()
                .filter(move |q| q.subject == s && q.camera == 0)
                .flat_map(|q| q.joints3d_mm.iter())
        })
    }
}

/// Human3.6M camera (Martinez et al.'s cameras.h5): X_cam = R (X − T).
#[derive(Deserialize)]
pub struct H36mCamera {
    pub rotation: [[f64; 3]; 3],
    pub center_mm: [f64; 3],
    pub f: [f64; 2],
    pub c: [f64; 2],
}

/// One Human3.6M action, mapped to the 15 joints.
#[derive(Deserialize)]
pub struct H36mSequence {
    pub subject: String,
    pub action: String,
    pub joints3d_mm: Vec<[[f64; 3]; N_JOINTS]>,
}

/// Human3.6M, subsampled.
#[derive(Deserialize)]
pub struct H36m {
    pub cameras: std::collections::BTreeMap<String, Vec<H36mCamera>>,
    pub sequences: Vec<H36mSequence>,
}

/// Runs the converter (once per test process; it skips up-to-date outputs) and returns the cache
/// folder. It needs python3 with numpy and h5py (test-all.sh installs them); without them the test
/// fails.
pub fn converted(test: &str) -> PathBuf {
    // The tests of one binary run in parallel and share the outputs: one conversion at a time.
    static DONE: Mutex<Option<PathBuf>> = Mutex::new(None);
    let mut done = DONE.lock().unwrap_or_else(|p| p.into_inner());
    if let Some(out) = done.as_ref() {
        return out.clone();
    }
    let shared = monotrack_tests::shared_data();
    let out = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("body-data");
    let script = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("scripts/body_data.py");
    let status = Command::new("python3")
        .arg(&script)
        .arg(&shared)
        .arg(&out)
        .status();
    match status {
        Ok(s) if s.success() => {
            *done = Some(out.clone());
            out
        }
        other => panic!(
            "{test}: {} failed ({other:?}); it needs python3 with numpy and h5py",
            script.display()
        ),
    }
}

pub fn load<T: for<'de> Deserialize<'de>>(dir: &std::path::Path, name: &str) -> T {
    let text = std::fs::read_to_string(dir.join(name)).unwrap();
    serde_json::from_str(&text).unwrap()
}

pub fn v3(p: &[f64; 3]) -> Vector3<f64> {
    Vector3::new(p[0], p[1], p[2])
}

pub fn m3(r: &[[f64; 3]; 3]) -> Matrix3<f64> {
    Matrix3::from_fn(|i, j| r[i][j])
}

/// `pred` aligned to `truth` by the similarity (rotation, translation, scale) minimising the squared
/// distances (Umeyama), as in PA-MPJPE.
pub fn procrustes(
    pred: &[Vector3<f64>; N_JOINTS],
    truth: &[Vector3<f64>; N_JOINTS],
) -> [Vector3<f64>; N_JOINTS] {
    let n = N_JOINTS as f64;
    let mp = pred.iter().sum::<Vector3<f64>>() / n;
    let mt = truth.iter().sum::<Vector3<f64>>() / n;
    let mut cov = Matrix3::zeros();
    let mut var = 0.0;
    for i in 0..N_JOINTS {
        cov += (truth[i] - mt) * (pred[i] - mp).transpose();
        var += (pred[i] - mp).norm_squared();
    }
    let svd = cov.svd(true, true);
    let (u, vt) = (svd.u.unwrap(), svd.v_t.unwrap());
    let d = (u * vt).determinant().signum();
    let s = Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d));
    let r = u * s * vt;
    let scale =
        (svd.singular_values[0] + svd.singular_values[1] + d * svd.singular_values[2]) / var;
    std::array::from_fn(|i| mt + r * (pred[i] - mp) * scale)
}

/// Joint groups for per-limb errors (thesis Table 5.3's rows).
pub const LIMB_GROUPS: [(&str, &[usize]); 6] = [
    ("torso", &[0, 1, 2, 5, 8, 11]),
    ("head", &[14]),
    ("upper arms (elbows)", &[3, 6]),
    ("forearms (wrists)", &[4, 7]),
    ("thighs (knees)", &[9, 12]),
    ("shins (ankles)", &[10, 13]),
];

/// Bones whose lengths are compared (pairs of joint indices) with their [`dim`] index.
pub const BONES: [(&str, usize, usize, usize); 12] = [
    ("back", 0, 1, 0),
    ("neck", 1, 14, 1),
    ("shoulder width", 2, 5, 2),
    ("hip width", 8, 11, 3),
    ("left upper arm", 2, 3, 4),
    ("right upper arm", 5, 6, 5),
    ("left forearm", 3, 4, 6),
    ("right forearm", 6, 7, 7),
    ("left thigh", 8, 9, 8),
    ("right thigh", 11, 12, 9),
    ("left shin", 9, 10, 10),
    ("right shin", 12, 13, 11),
];

impl H36m {
    /// Mean body-part lengths per subject ([`mean_lengths`] of all the subject's mocap frames).
    pub fn subject_lengths(&self) -> BTreeMap<String, [f64; N_DIMS]> {
        per_subject(self.cameras.keys(), |s| {
            self.sequences
                .iter()
                .filter(move |q| q.subject == s)
                .flat_map(|q| q.joints3d_mm.iter())
        })
    }
}

/// [`mean_lengths`] per subject of the frames `frames(subject)` yields.
fn per_subject<'a, I>(
    subjects: impl IntoIterator<Item = &'a String>,
    frames: impl Fn(&'a str) -> I,
) -> BTreeMap<String, [f64; N_DIMS]>
where
    I: Iterator<Item = &'a [[f64; 3]; N_JOINTS]>,
{
    subjects
        .into_iter()
        .map(|s| (s.clone(), mean_lengths(frames(s))))
        .collect()
}

/// Mean bone lengths (mm, [`dim`] order) of one subject's frames: a frame-weighted mean of each
/// bone's length over all of them (HumanEva's marker-based joints stretch by up to ±28 mm).
pub fn mean_lengths<'a>(
    frames: impl IntoIterator<Item = &'a [[f64; 3]; N_JOINTS]>,
) -> [f64; N_DIMS] {
    let mut sum = [0.0; N_DIMS];
    let mut n = 0.0;
    for f in frames {
        for (_, a, b, di) in BONES {
            sum[di] += (v3(&f[a]) - v3(&f[b])).norm();
        }
        n += 1.0;
    }
    sum.map(|s| s / n)
}

/// The mean body of the subjects `keep` accepts: per-subject lengths averaged over the subjects
/// (each subject counts once), left and right averaged; the way
/// `Convention::mean_lengths_mm` was made, before its rounding.
pub fn mean_body(
    per_subject: &BTreeMap<String, [f64; N_DIMS]>,
    keep: impl Fn(&str) -> bool,
) -> Dimensions {
    let chosen: Vec<_> = per_subject.iter().filter(|(s, _)| keep(s)).collect();
    assert!(!chosen.is_empty(), "no subjects for the mean body");
    let n = chosen.len() as f64;
    let mut lengths: [f64; N_DIMS] =
        std::array::from_fn(|i| chosen.iter().map(|(_, l)| l[i]).sum::<f64>() / n);
    for (l, r) in dim::LEFT_RIGHT {
        let m = 0.5 * (lengths[l] + lengths[r]);
        lengths[l] = m;
        lengths[r] = m;
    }
    Dimensions { lengths }
}

/// Asserts that the shipped table `Dimensions::mean(convention)` is the mean body of all the
/// subjects of `per_subject`, each length within `tol_mm` (the table is rounded to the millimetre).
pub fn assert_shipped_table(
    per_subject: &BTreeMap<String, [f64; N_DIMS]>,
    convention: monotrack_core::body::Convention,
    tol_mm: f64,
) {
    let all = mean_body(per_subject, |_| true);
    let shipped = Dimensions::mean(convention);
    for i in 0..N_DIMS {
        assert!(
            (all.lengths[i] - shipped.lengths[i]).abs() <= tol_mm,
            "{}: {convention:?} data mean {:.1} vs shipped {}",
            dim::NAMES[i],
            all.lengths[i],
            shipped.lengths[i]
        );
    }
}

/// Where the dimension search's starting proportions (its prior) come from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Prior {
    /// The shipped table, `Dimensions::mean(convention)`: made from every subject evaluated here,
    /// so an in-sample (optimistic) figure.
    Shipped,
    /// The mean body of the other subjects of the data set (leave one subject out): the honest
    /// figure for a subject the table has not seen.
    LeaveOneOut,
    /// Fixed lengths (e.g. another data set's proportions).
    Fixed(Dimensions),
}

impl Prior {
    /// The starting dimensions for `subject`.
    pub fn start(
        &self,
        subject: &str,
        per_subject: &BTreeMap<String, [f64; N_DIMS]>,
        convention: monotrack_core::body::Convention,
    ) -> Dimensions {
        match self {
            Prior::Shipped => Dimensions::mean(convention),
            Prior::LeaveOneOut => mean_body(per_subject, |s| s != subject),
            Prior::Fixed(d) => *d,
        }
    }
}

/// Left/right joint pairs of the 15-joint order (for mirroring).
const MIRROR_PAIRS: [(usize, usize); 6] = [(2, 5), (3, 6), (4, 7), (8, 11), (9, 12), (10, 13)];

impl H36m {
    /// Per subject, the pose of every frame and of its mirror image (x negated, left and right
    /// swapped: the prior should not prefer one side), fitted to the mocap joints with the
    /// sequence's own dimensions (`prior::fit_to_joints`). Also returns the RMS model-to-mocap
    /// joint distance over all of them, mm.
    pub fn poses_by_subject(&self) -> (BTreeMap<String, Vec<[f64; N_POSE]>>, f64) {
        let mut out: BTreeMap<String, Vec<[f64; N_POSE]>> = BTreeMap::new();
        let mut ms = 0.0;
        let mut n = 0.0;
        for seq in &self.sequences {
            let dims = Dimensions {
                lengths: mean_lengths(seq.joints3d_mm.iter()),
            };
            for mirror in [false, true] {
                let mut dims = dims;
                if mirror {
                    for (l, r) in dim::LEFT_RIGHT {
                        dims.lengths.swap(l, r);
                    }
                }
                let skel = Skeleton::new(dims, Convention::Human36M).unwrap();
                for f in &seq.joints3d_mm {
                    let mut x: [Vector3<f64>; N_JOINTS] = std::array::from_fn(|j| v3(&f[j]));
                    if mirror {
                        for p in &mut x {
                            p.x = -p.x;
                        }
                        for (a, b) in MIRROR_PAIRS {
                            x.swap(a, b);
                        }
                    }
                    let (p, rms) = fit_to_joints(&skel, &x).unwrap();
                    ms += rms * rms;
                    n += 1.0;
                    out.entry(seq.subject.clone()).or_default().push(p);
                }
            }
        }
        (out, (ms / f64::max(n, 1.0)).sqrt())
    }
}

/// The pose prior of the subjects `keep` accepts, from [`H36m::poses_by_subject`]'s poses
/// ([`POSE_PRIOR_MIN_STD`]); also the number of poses.
pub fn pose_prior(
    poses: &BTreeMap<String, Vec<[f64; N_POSE]>>,
    keep: impl Fn(&str) -> bool,
) -> (PosePrior, usize) {
    let all: Vec<[f64; N_POSE]> = poses
        .iter()
        .filter(|(s, _)| keep(s))
        .flat_map(|(_, p)| p.iter().copied())
        .collect();
    (
        PosePrior::from_poses(&all, POSE_PRIOR_MIN_STD).unwrap(),
        all.len(),
    )
}

/// Independent spread added to every parameter of the pose prior, radians (see
/// `PosePrior::from_poses`).
pub const POSE_PRIOR_MIN_STD: f64 = 0.05;

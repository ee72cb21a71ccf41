//! The deformable 3D face model: a mean shape ḡ of 68 vertices (millimetres, model frame of
//! [`crate::camera`]) paired one-to-one with the iBUG landmarks, 11 shape units S and 6 animation
//! units A, so that the deformed shape is g = ḡ + S·τsu + A·τau.
//!
//! The model is data (`core/models/face_model/face_model.json`, built by `build.py` beside it and
//! embedded here); each unit also lists the landmarks it influences, which MSBP's shape and
//! animation steps use as their landmark subsets.

pub mod bundle;

use crate::error::{Error, Result};
use nalgebra::{Matrix3, Vector3};
use serde::Deserialize;
use std::sync::OnceLock;

/// Number of landmark vertices (iBUG 68).
pub const N_LANDMARKS: usize = 68;
/// Number of shape units.
pub const N_SHAPE: usize = 11;
/// Number of animation units.
pub const N_ANIM: usize = 6;

/// Shape unit names, in the model's order (snake_case as in the CLI's JSON).
pub const SHAPE_UNIT_NAMES: [&str; N_SHAPE] = [
    "eyes_height",
    "eyes_separation_distance",
    "eyes_vertical_position",
    "eyes_width",
    "face_length",
    "face_roundness",
    "lip_thickness",
    "mouth_vertical_position",
    "mouth_width",
    "nose_width",
    "nose_z_extension",
];

/// Animation unit names, in the model's order.
pub const ANIM_UNIT_NAMES: [&str; N_ANIM] = [
    "open_mouth",
    "raise_left_outer_eyebrow",
    "raise_nose_bridge",
    "raise_right_outer_eyebrow",
    "smile",
    "stretch_lips",
];

const MODEL_FORMAT: &str = "monotrack-face-model";
const MODEL_VERSION: u32 = 1;
pub(crate) static BUILTIN_JSON: &[u8] = include_bytes!("../../models/face_model/face_model.json");

/// One deformation unit: a displacement per landmark vertex (mm at τ = 1) and the landmarks it moves.
#[derive(Debug, Clone)]
pub struct Unit {
    /// snake_case name.
    pub name: String,
    /// Displacement of each of the 68 vertices at τ = 1, mm.
    pub displacement: [Vector3<f64>; N_LANDMARKS],
    /// Indices of the vertices with a non-zero displacement.
    pub landmarks: Vec<usize>,
}

/// The deformable face model.
#[derive(Debug, Clone)]
pub struct FaceModel {
    mean: [Vector3<f64>; N_LANDMARKS],
    shape: Vec<Unit>,
    anim: Vec<Unit>,
    triangles: Vec<[u16; 3]>,
    shape_landmarks: Vec<usize>,
}

#[derive(Deserialize)]
struct RawUnit {
    name: String,
    landmarks: Vec<usize>,
    displacement: Vec<[f64; 3]>,
}

#[derive(Deserialize)]
struct RawModel {
    format: String,
    version: u32,
    mean: Vec<[f64; 3]>,
    shape_units: Vec<RawUnit>,
    animation_units: Vec<RawUnit>,
    #[serde(default)]
    triangles: Vec<[u16; 3]>,
}

fn to_points(v: &[[f64; 3]], what: &str) -> Result<[Vector3<f64>; N_LANDMARKS]> {
    if v.len() != N_LANDMARKS {
        return Err(Error::ModelLoad(format!(
            "{what}: expected {N_LANDMARKS} points, got {}",
            v.len()
        )));
    }
    let mut out = [Vector3::zeros(); N_LANDMARKS];
    for (o, p) in out.iter_mut().zip(v) {
        if !p.iter().all(|c| c.is_finite()) {
            return Err(Error::ModelLoad(format!("{what}: non-finite coordinate")));
        }
        *o = Vector3::new(p[0], p[1], p[2]);
    }
    Ok(out)
}

fn to_units(raw: Vec<RawUnit>, names: &[&str], kind: &str) -> Result<Vec<Unit>> {
    if raw.len() != names.len() {
        return Err(Error::ModelLoad(format!(
            "expected {} {kind} units, got {}",
            names.len(),
            raw.len()
        )));
    }
    raw.into_iter()
        .zip(names)
        .map(|(u, want)| {
            if u.name != *want {
                return Err(Error::ModelLoad(format!(
                    "{kind} unit '{}' where '{want}' was expected",
                    u.name
                )));
            }
            if u.landmarks.iter().any(|&i| i >= N_LANDMARKS) || u.landmarks.is_empty() {
                return Err(Error::ModelLoad(format!("unit {want}: bad landmark list")));
            }
            Ok(Unit {
                displacement: to_points(&u.displacement, want)?,
                name: u.name,
                landmarks: u.landmarks,
            })
        })
        .collect()
}

impl FaceModel {
    /// The model shipped with the SDK (parsed once, then shared).
    pub fn builtin() -> &'static FaceModel {
        static MODEL: OnceLock<FaceModel> = OnceLock::new();
        MODEL.get_or_init(|| {
            // The embedded file is checked by the `builtin_model_loads` test, so this cannot fail
            // in a released build.
            Self::from_json(BUILTIN_JSON).expect("embedded face model is valid")
        })
    }

    /// Parses a model file (the format written by `core/models/face_model/build.py`).
    ///
    /// # Errors
    /// [`Error::ModelLoad`] for malformed JSON, a wrong format/version, unit names or counts.
    pub fn from_json(bytes: &[u8]) -> Result<Self> {
        let raw: RawModel = serde_json::from_slice(bytes)
            .map_err(|e| Error::ModelLoad(format!("face model JSON: {e}")))?;
        if raw.format != MODEL_FORMAT || raw.version != MODEL_VERSION {
            return Err(Error::ModelLoad(format!(
                "face model format {} v{} is not {MODEL_FORMAT} v{MODEL_VERSION}",
                raw.format, raw.version
            )));
        }
        if raw
            .triangles
            .iter()
            .flatten()
            .any(|&i| usize::from(i) >= N_LANDMARKS)
        {
            return Err(Error::ModelLoad("triangle index out of range".into()));
        }
        let shape = to_units(raw.shape_units, &SHAPE_UNIT_NAMES, "shape")?;
        let mut shape_landmarks: Vec<usize> = shape
            .iter()
            .flat_map(|u| u.landmarks.iter().copied())
            .collect();
        shape_landmarks.sort_unstable();
        shape_landmarks.dedup();
        Ok(Self {
            mean: to_points(&raw.mean, "mean")?,
            shape,
            anim: to_units(raw.animation_units, &ANIM_UNIT_NAMES, "animation")?,
            triangles: raw.triangles,
            shape_landmarks,
        })
    }

    /// Mean shape ḡ.
    pub fn mean(&self) -> &[Vector3<f64>; N_LANDMARKS] {
        &self.mean
    }

    /// Shape units (S), in [`SHAPE_UNIT_NAMES`] order.
    pub fn shape_units(&self) -> &[Unit] {
        &self.shape
    }

    /// Animation units (A), in [`ANIM_UNIT_NAMES`] order.
    pub fn animation_units(&self) -> &[Unit] {
        &self.anim
    }

    /// Union of the landmarks any shape unit moves (MSBP step 2's pairs).
    pub fn shape_landmarks(&self) -> &[usize] {
        &self.shape_landmarks
    }

    /// Mesh triangles over the 68 vertices (for drawing).
    pub fn triangles(&self) -> &[[u16; 3]] {
        &self.triangles
    }

    /// g = ḡ + S·τsu + A·τau, into `out`.
    pub fn shape_into(
        &self,
        shape: &[f64; N_SHAPE],
        anim: &[f64; N_ANIM],
        out: &mut [Vector3<f64>; N_LANDMARKS],
    ) {
        *out = self.mean;
        for (u, &t) in self
            .shape
            .iter()
            .zip(shape)
            .chain(self.anim.iter().zip(anim))
        {
            if t != 0.0 {
                for &i in &u.landmarks {
                    out[i] += u.displacement[i] * t;
                }
            }
        }
    }

    /// The deformed model placed by pose (R, t): its 68 vertices in camera coordinates (mm), into
    /// `out` — what an AR overlay draws with [`Self::triangles`].
    pub fn posed_into(
        &self,
        shape: &[f64; N_SHAPE],
        anim: &[f64; N_ANIM],
        rotation: &Matrix3<f64>,
        translation: &Vector3<f64>,
        out: &mut [Vector3<f64>; N_LANDMARKS],
    ) {
        self.shape_into(shape, anim, out);
        for p in out.iter_mut() {
            *p = rotation * *p + translation;
        }
    }

    /// Projects the deformed model through pose (R, t) and intrinsics into `out` (pixels).
    pub fn project_into(
        &self,
        shape: &[f64; N_SHAPE],
        anim: &[f64; N_ANIM],
        rotation: &Matrix3<f64>,
        translation: &Vector3<f64>,
        camera: &crate::camera::Intrinsics,
        out: &mut [[f64; 2]; N_LANDMARKS],
    ) {
        let mut g = [Vector3::zeros(); N_LANDMARKS];
        self.shape_into(shape, anim, &mut g);
        for (o, p) in out.iter_mut().zip(&g) {
            let c = rotation * p + translation;
            let (u, v) = camera.project(c.x, c.y, c.z);
            *o = [u, v];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn builtin_model_loads() {
        let m = FaceModel::builtin();
        assert_eq!(m.shape_units().len(), N_SHAPE);
        assert_eq!(m.animation_units().len(), N_ANIM);
        assert!(!m.triangles().is_empty());
        // Outer eye corners ~91 mm apart, chin below the eyes, nose tip in front (model frame).
        let g = m.mean();
        let iod = (g[45] - g[36]).norm();
        assert!((85.0..100.0).contains(&iod), "{iod}");
        assert!(g[8].y > g[36].y && g[30].z < g[36].z);
        // Symmetric: point 0 mirrors point 16.
        assert!((g[0].x + g[16].x).abs() < 1e-6 && (g[0].y - g[16].y).abs() < 1e-6);
    }

    #[test]
    fn corrupt_model_is_a_typed_error() {
        assert!(matches!(
            FaceModel::from_json(b"{not json"),
            Err(Error::ModelLoad(_))
        ));
        let s = std::str::from_utf8(BUILTIN_JSON)
            .unwrap()
            .replace("\"mouth_width\"", "\"mouth_wide\"");
        assert!(matches!(
            FaceModel::from_json(s.as_bytes()),
            Err(Error::ModelLoad(_))
        ));
    }

    fn moved(u: &Unit) -> Vec<(usize, f64)> {
        (0..N_LANDMARKS)
            .map(|i| (i, u.displacement[i].norm()))
            .filter(|&(_, d)| d > 1e-9)
            .collect()
    }

    /// Each unit does what its name says and little else.
    #[test]
    fn units_are_semantic() {
        let m = FaceModel::builtin();
        let s = |n: &str| &m.shape_units()[SHAPE_UNIT_NAMES.iter().position(|x| *x == n).unwrap()];
        let a =
            |n: &str| &m.animation_units()[ANIM_UNIT_NAMES.iter().position(|x| *x == n).unwrap()];
        // +mouth width: corners apart, only mouth points move.
        let u = s("mouth_width");
        assert!(u.displacement[54].x > 3.0 && u.displacement[48].x < -3.0);
        assert!(moved(u).iter().all(|&(i, _)| (48..68).contains(&i)));
        // +eyes separation: eyes apart, only eye points.
        let u = s("eyes_separation_distance");
        assert!(u.displacement[45].x > 2.0 && u.displacement[36].x < -2.0);
        assert!(moved(u).iter().all(|&(i, _)| (36..48).contains(&i)));
        // +nose z extension: tip towards the camera (-z), only nose.
        let u = s("nose_z_extension");
        assert!(u.displacement[30].z < -4.0);
        assert!(moved(u).iter().all(|&(i, _)| (27..36).contains(&i)));
        // +face length: chin down, eyes fixed.
        let u = s("face_length");
        assert!(u.displacement[8].y > 5.0 && u.displacement[36].norm() == 0.0);
        // +open mouth: lower lip down, upper lip and eyes fixed.
        let u = a("open_mouth");
        assert!(u.displacement[57].y > 8.0 && u.displacement[51].norm() == 0.0);
        // raise left outer brow: subject's left = image right = +x brow (22-26), up (-y).
        let u = a("raise_left_outer_eyebrow");
        assert!(u.displacement[26].y < -5.0 && u.displacement[17].norm() == 0.0);
        let u = a("raise_right_outer_eyebrow");
        assert!(u.displacement[17].y < -5.0 && u.displacement[26].norm() == 0.0);
        // smile: corners up and out.
        let u = a("smile");
        assert!(u.displacement[54].y < -3.0 && u.displacement[54].x > 3.0);
        assert!(u.displacement[48].x < -3.0);
    }
}

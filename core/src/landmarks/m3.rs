//! The M3 detector: configuration (`m3.json`), network loading and the per-face pipeline of
//! `models/M3_IO.md` (level-1 crop → level 1 → zone patches → zone nets → merge into 68 points).

use super::filter::{Bilateral, equalize_hist};
use super::net::Net;
use super::warp::{Affine, sample};
use super::{BROW_GESTURES, FaceLandmarks, MOUTH_GESTURES, N_POINTS, YAW_CLASSES_DEG};
use crate::error::{Error, Result};
use crate::image::{GrayImage, Rect};
use serde::Deserialize;

/// The shipped weights, trained by `models/train/train_m3.py`.
const EMBEDDED_JSON: &[u8] = include_bytes!("../../models/m3/m3.json");
const EMBEDDED_LEVEL1: &[u8] = include_bytes!("../../models/m3/level1.onnx");
const EMBEDDED_BROWS: &[u8] = include_bytes!("../../models/m3/brows.onnx");
const EMBEDDED_EYE: &[u8] = include_bytes!("../../models/m3/eye.onnx");
const EMBEDDED_MOUTH: &[u8] = include_bytes!("../../models/m3/mouth.onnx");

/// Number of level-1 landmarks (`M3_IO.md`).
const N_LEVEL1: usize = 32;
/// Largest crop or patch side accepted from `m3.json`: far above any sensible network input, it
/// only stops a corrupt configuration from asking for huge buffers.
const MAX_INPUT_SIDE: usize = 1024;
/// Floor of a vector norm before normalising (the Python reference uses the same).
const NORM_EPS: f64 = 1e-9;

/// `level1` of `m3.json`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
pub struct Level1Config {
    /// ONNX file name (informational: the bytes are passed separately).
    pub file: String,
    /// Side of the square network input, pixels.
    pub input_size: usize,
    /// Crop side / face-box side.
    pub crop_scale: f64,
    /// Where the 32 level-1 points go in the 68.
    pub indices68: Vec<usize>,
    /// Yaw classes, degrees; must equal [`YAW_CLASSES_DEG`].
    pub yaw_classes_deg: Vec<i32>,
}

/// `bilateral` of a zone in `m3.json` (OpenCV `bilateralFilter` parameters).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
pub struct BilateralConfig {
    /// Diameter (≤ 0: from `sigma_space`).
    pub d: i32,
    /// Range sigma, grey levels.
    pub sigma_color: f64,
    /// Spatial sigma, pixels.
    pub sigma_space: f64,
}

/// One zone of `m3.json`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
pub struct ZoneConfig {
    /// ONNX file name (informational).
    pub file: String,
    /// Patch width, pixels.
    pub width: usize,
    /// Patch height, pixels.
    pub height: usize,
    /// The two reference landmarks (68 indices) of the similarity.
    pub ref68: [usize; 2],
    /// Their template positions in patch units.
    pub template: [[f64; 2]; 2],
    /// Bilateral filter, if any.
    #[serde(default)]
    pub bilateral: Option<BilateralConfig>,
    /// Histogram equalisation after the filter.
    #[serde(default)]
    pub equalize: bool,
    /// Where the zone's points go in the 68.
    pub indices68: Vec<usize>,
    /// Reference landmarks of the mirrored (left) eye.
    #[serde(default)]
    pub mirror_ref68: Option<[usize; 2]>,
    /// Where the mirrored eye's points go in the 68.
    #[serde(default)]
    pub mirror_indices68: Option<Vec<usize>>,
    /// Gesture names, in output order.
    #[serde(default)]
    pub gestures: Option<Vec<String>>,
    /// Whether the net outputs a gaze vector.
    #[serde(default)]
    pub gaze: bool,
}

/// `zones` of `m3.json`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
pub struct ZonesConfig {
    /// Both brows in one patch.
    pub brows: ZoneConfig,
    /// The subject's right eye; the left eye runs mirrored through the same net.
    pub eye: ZoneConfig,
    /// Mouth, inner lips included.
    pub mouth: ZoneConfig,
}

/// `m3.json`: everything the inference needs besides the weights (`models/M3_IO.md`).
#[derive(Debug, Clone, PartialEq, Deserialize)]
pub struct M3Config {
    /// Schema version (1).
    pub version: u32,
    /// Level-1 network.
    pub level1: Level1Config,
    /// Level-2 networks.
    pub zones: ZonesConfig,
}

fn bad(msg: String) -> Error {
    Error::ModelLoad(format!("m3.json: {msg}"))
}

fn check_side(what: &str, v: usize) -> Result<()> {
    if v == 0 || v > MAX_INPUT_SIDE {
        return Err(bad(format!("{what} = {v} outside 1..={MAX_INPUT_SIDE}")));
    }
    Ok(())
}

fn check_indices(what: &str, idx: &[usize], n: usize, covered: &mut [bool; N_POINTS]) -> Result<()> {
    if idx.len() != n {
        return Err(bad(format!("{what} has {} indices, expected {n}", idx.len())));
    }
    for &i in idx {
        *covered
            .get_mut(i)
            .ok_or_else(|| bad(format!("{what}: index {i} ≥ {N_POINTS}")))? = true;
    }
    Ok(())
}

impl ZoneConfig {
    fn validate(
        &self,
        name: &str,
        n_points: usize,
        gestures: Option<&[&str]>,
        covered: &mut [bool; N_POINTS],
    ) -> Result<()> {
        check_side(&format!("{name}.width"), self.width)?;
        check_side(&format!("{name}.height"), self.height)?;
        let [t0, t1] = self.template;
        if !t0.iter().chain(&t1).all(|v| v.is_finite()) || t0 == t1 {
            return Err(bad(format!("{name}.template must hold two distinct finite points")));
        }
        for r in self.ref68.iter().chain(self.mirror_ref68.iter().flatten()) {
            if *r >= N_POINTS {
                return Err(bad(format!("{name}: reference index {r} ≥ {N_POINTS}")));
            }
        }
        check_indices(&format!("{name}.indices68"), &self.indices68, n_points, covered)?;
        if let Some(b) = &self.bilateral {
            if !(b.sigma_color.is_finite() && b.sigma_space.is_finite()) || b.d > 31 {
                return Err(bad(format!("{name}.bilateral out of range: {b:?}")));
            }
        }
        match (gestures, &self.gestures) {
            (None, None) => {}
            (Some(want), Some(got)) if got.iter().map(String::as_str).eq(want.iter().copied()) => {
            }
            (want, got) => {
                return Err(bad(format!("{name}.gestures = {got:?}, expected {want:?}")));
            }
        }
        Ok(())
    }
}

impl M3Config {
    /// Parses and checks `m3.json`.
    ///
    /// # Errors
    /// [`Error::ModelLoad`] for malformed JSON or values that break the `M3_IO.md` contract
    /// (index counts, gesture order, uncovered points, sizes).
    pub fn from_json(bytes: &[u8]) -> Result<Self> {
        let cfg: Self = serde_json::from_slice(bytes).map_err(|e| bad(e.to_string()))?;
        cfg.validate()?;
        Ok(cfg)
    }

    fn validate(&self) -> Result<()> {
        if self.version != 1 {
            return Err(bad(format!("version {} (this build reads 1)", self.version)));
        }
        let l1 = &self.level1;
        check_side("level1.input_size", l1.input_size)?;
        if !(l1.crop_scale.is_finite() && l1.crop_scale > 0.0) {
            return Err(bad(format!("level1.crop_scale = {}", l1.crop_scale)));
        }
        if l1.yaw_classes_deg != YAW_CLASSES_DEG {
            return Err(bad(format!(
                "level1.yaw_classes_deg = {:?}, expected {YAW_CLASSES_DEG:?}",
                l1.yaw_classes_deg
            )));
        }
        let mut covered = [false; N_POINTS];
        check_indices("level1.indices68", &l1.indices68, N_LEVEL1, &mut covered)?;
        let z = &self.zones;
        z.brows
            .validate("brows", 10, Some(&BROW_GESTURES), &mut covered)?;
        z.mouth
            .validate("mouth", 20, Some(&MOUTH_GESTURES), &mut covered)?;
        z.eye.validate("eye", 6, None, &mut covered)?;
        let (Some(_), Some(mi)) = (&z.eye.mirror_ref68, &z.eye.mirror_indices68) else {
            return Err(bad("eye needs mirror_ref68 and mirror_indices68".into()));
        };
        check_indices("eye.mirror_indices68", mi, 6, &mut covered)?;
        if !z.eye.gaze || z.brows.gaze || z.mouth.gaze {
            return Err(bad("only the eye zone outputs gaze".into()));
        }
        if let Some(i) = covered.iter().position(|c| !c) {
            return Err(bad(format!("landmark {i} is produced by no network")));
        }
        Ok(())
    }
}

/// A level-2 zone at run time: its map parameters, network and patch buffers.
#[derive(Debug)]
struct Zone {
    width: usize,
    height: usize,
    /// Template positions in patch pixels.
    q: [[f64; 2]; 2],
    bilateral: Option<Bilateral>,
    equalize: bool,
    net: Net,
    patch: Vec<u8>,
    filtered: Vec<u8>,
}

impl Zone {
    fn new(name: &str, cfg: &ZoneConfig, bytes: &[u8], extra: (&str, usize)) -> Result<Self> {
        let (w, h) = (cfg.width, cfg.height);
        let net = Net::load(
            name,
            bytes,
            &[("patch", &[1, 1, h, w]), ("yaw", &[1, 5])],
            &["landmarks", extra.0],
        )?;
        let q = cfg.template.map(|t| [t[0] * w as f64, t[1] * h as f64]);
        let mut zone = Self {
            width: w,
            height: h,
            q,
            bilateral: cfg
                .bilateral
                .map(|b| Bilateral::new(b.d, b.sigma_color, b.sigma_space)),
            equalize: cfg.equalize,
            net,
            patch: Vec::with_capacity(w * h),
            filtered: vec![0; w * h],
        };
        zone.check_outputs(name, 2 * cfg.indices68.len(), extra.1)?;
        Ok(zone)
    }

    /// Runs the net once on zeros to check the output sizes (and warm the plan up).
    fn check_outputs(&mut self, name: &str, n_landmarks: usize, n_extra: usize) -> Result<()> {
        self.net.run()?;
        let (a, b) = (self.net.output(0)?.len(), self.net.output(1)?.len());
        if (a, b) != (n_landmarks, n_extra) {
            return Err(Error::ModelLoad(format!(
                "{name}: outputs of {a} and {b} values, expected {n_landmarks} and {n_extra}"
            )));
        }
        Ok(())
    }

    /// Samples, filters and runs the zone for the patch map `map`; outputs stay in the net.
    fn run(&mut self, image: &GrayImage, map: &Affine, yaw: &[f32; 5]) -> Result<()> {
        let (w, h) = (self.width, self.height);
        sample(image, map, w, h, &mut self.patch)?;
        if let Some(b) = &mut self.bilateral {
            b.apply(&self.patch, w, h, &mut self.filtered);
            // Both buffers are w·h long: swapping keeps the filtered patch in `patch` for free.
            std::mem::swap(&mut self.patch, &mut self.filtered);
        }
        if self.equalize {
            equalize_hist(&mut self.patch);
        }
        let src = &self.patch;
        self.net.fill_input(0, |x| to_unit(src, x))?;
        self.net.fill_input(1, |x| x.copy_from_slice(yaw))?;
        self.net.run()
    }
}

/// u8 pixels → float32 `pixel / 255` (`M3_IO.md`, network input).
fn to_unit(src: &[u8], dst: &mut [f32]) {
    for (d, &s) in dst.iter_mut().zip(src) {
        *d = f32::from(s) / 255.0;
    }
}

fn softmax<const N: usize>(logits: &[f32], out: &mut [f32; N]) {
    let m = logits.iter().copied().fold(f32::NEG_INFINITY, f32::max);
    let mut sum = 0.0;
    for (o, &l) in out.iter_mut().zip(logits) {
        *o = (l - m).exp();
        sum += *o;
    }
    for o in out.iter_mut() {
        *o /= sum;
    }
}

fn normalized(v: [f64; 3]) -> [f64; 3] {
    let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt().max(NORM_EPS);
    [v[0] / n, v[1] / n, v[2] / n]
}

/// The M3 landmark and gesture detector (thesis section 3.3). See the module docs.
#[derive(Debug)]
pub struct M3 {
    cfg: M3Config,
    level1: Net,
    brows: Zone,
    eye: Zone,
    mouth: Zone,
    crop: Vec<u8>,
    /// The merged 68 points of the face in progress, image pixels.
    pts: [[f64; 2]; N_POINTS],
    /// The level-1 points of the face in progress (zone references).
    ref_pts: [[f64; 2]; N_POINTS],
}

/// What level 1 gives besides its points.
struct Level1Out {
    yaw: [f32; 5],
    face_prob: f32,
}

impl M3 {
    /// The detector with the weights embedded in the library (`models/m3/`).
    ///
    /// # Errors
    /// [`Error::ModelLoad`] if the embedded models cannot be loaded (a build defect).
    pub fn new() -> Result<Self> {
        Self::from_bytes(
            EMBEDDED_JSON,
            EMBEDDED_LEVEL1,
            EMBEDDED_BROWS,
            EMBEDDED_EYE,
            EMBEDDED_MOUTH,
        )
    }

    /// The detector from other weights: `m3.json` and the four ONNX files (`models/M3_IO.md`).
    ///
    /// # Errors
    /// [`Error::ModelLoad`] for malformed JSON, a configuration that breaks the contract, ONNX
    /// bytes tract cannot load, or networks whose inputs/outputs do not match the contract.
    pub fn from_bytes(
        json: &[u8],
        level1: &[u8],
        brows: &[u8],
        eye: &[u8],
        mouth: &[u8],
    ) -> Result<Self> {
        let cfg = M3Config::from_json(json)?;
        let s = cfg.level1.input_size;
        let mut level1 = Net::load(
            "level1",
            level1,
            &[("image", &[1, 1, s, s])],
            &["landmarks", "yaw_logits", "face_logit"],
        )?;
        level1.run()?;
        let sizes = [
            level1.output(0)?.len(),
            level1.output(1)?.len(),
            level1.output(2)?.len(),
        ];
        if sizes != [2 * N_LEVEL1, 5, 1] {
            return Err(Error::ModelLoad(format!(
                "level1: outputs of {sizes:?} values, expected [64, 5, 1]"
            )));
        }
        let z = &cfg.zones;
        let brows = Zone::new("brows", &z.brows, brows, ("gesture_logits", 3))?;
        let eye = Zone::new("eye", &z.eye, eye, ("gaze", 3))?;
        let mouth = Zone::new("mouth", &z.mouth, mouth, ("gesture_logits", 4))?;
        Ok(Self {
            crop: Vec::with_capacity(s * s),
            cfg,
            level1,
            brows,
            eye,
            mouth,
            pts: [[0.0; 2]; N_POINTS],
            ref_pts: [[0.0; 2]; N_POINTS],
        })
    }

    /// The configuration in use.
    pub fn config(&self) -> &M3Config {
        &self.cfg
    }

    fn check_input(image: &GrayImage, face: &Rect) -> Result<()> {
        if image.width() == 0 || image.height() == 0 {
            return Err(Error::InvalidInput(format!(
                "empty image {}x{}",
                image.width(),
                image.height()
            )));
        }
        if !face.is_valid() {
            return Err(Error::InvalidInput(format!(
                "face box must be finite with positive size, got {face:?}"
            )));
        }
        Ok(())
    }

    /// Runs level 1 on the crop of `face` and writes its points into `self.pts`.
    fn run_level1(&mut self, image: &GrayImage, face: &Rect) -> Result<Level1Out> {
        Self::check_input(image, face)?;
        let l1 = &self.cfg.level1;
        let s = l1.input_size;
        let c = face.center();
        let side = f64::from(face.w.max(face.h));
        let map = Affine::square_crop(
            [f64::from(c[0]), f64::from(c[1])],
            l1.crop_scale * side,
            s,
        );
        sample(image, &map, s, s, &mut self.crop)?;
        let crop = &self.crop;
        self.level1.fill_input(0, |x| to_unit(crop, x))?;
        self.level1.run()?;
        let lm = self.level1.output(0)?;
        for (k, &i) in l1.indices68.iter().enumerate() {
            let p = [
                f64::from(lm[2 * k]) * s as f64,
                f64::from(lm[2 * k + 1]) * s as f64,
            ];
            self.pts[i] = map.apply(p);
        }
        let mut yaw = [0.0; 5];
        softmax(self.level1.output(1)?, &mut yaw);
        let logit = self.level1.output(2)?[0];
        Ok(Level1Out {
            yaw,
            face_prob: 1.0 / (1.0 + (-logit).exp()),
        })
    }

    /// Level 1 only: the probability that the crop of `face` holds a face (the tracker's check of
    /// its patch).
    ///
    /// # Errors
    /// [`Error::InvalidInput`] for an empty image or a non-finite / empty box;
    /// [`Error::Internal`] if a network fails to run.
    pub fn face_confidence(&mut self, image: &GrayImage, face: &Rect) -> Result<f32> {
        Ok(self.run_level1(image, face)?.face_prob)
    }

    /// The patch map of a zone from two reference points (image pixels).
    fn zone_map(zone: &Zone, p0: [f64; 2], p1: [f64; 2], mirror: bool) -> Result<Affine> {
        let [q0, q1] = zone.q;
        let (q0, q1) = if mirror {
            let w = zone.width as f64;
            ([w - q0[0], q0[1]], [w - q1[0], q1[1]])
        } else {
            (q0, q1)
        };
        let map = Affine::similarity(p0, p1, q0, q1).ok_or_else(|| {
            Error::Internal(format!("non-finite level-1 reference points {p0:?}, {p1:?}"))
        })?;
        Ok(if mirror {
            map.mirrored_x(zone.width as f64)
        } else {
            map
        })
    }

    /// Maps a zone net's landmarks (patch units) through `map` into `self.pts[indices]`.
    fn put_zone_points(pts: &mut [[f64; 2]; N_POINTS], zone: &Zone, map: &Affine, idx: &[usize]) -> Result<()> {
        let lm = zone.net.output(0)?;
        let (w, h) = (zone.width as f64, zone.height as f64);
        for (k, &i) in idx.iter().enumerate() {
            pts[i] = map.apply([f64::from(lm[2 * k]) * w, f64::from(lm[2 * k + 1]) * h]);
        }
        Ok(())
    }

    /// One eye through the eye net; returns its unit gaze in the camera frame.
    fn run_eye(&mut self, image: &GrayImage, yaw: &[f32; 5], mirror: bool) -> Result<[f64; 3]> {
        let cfg = &self.cfg.zones.eye;
        let (refs, idx) = if mirror {
            match (&cfg.mirror_ref68, &cfg.mirror_indices68) {
                (Some(r), Some(i)) => (*r, i.as_slice()),
                _ => return Err(Error::Internal("eye mirror configuration missing".into())),
            }
        } else {
            (cfg.ref68, cfg.indices68.as_slice())
        };
        let map = Self::zone_map(&self.eye, self.ref_pts[refs[0]], self.ref_pts[refs[1]], mirror)?;
        self.eye.run(image, &map, yaw)?;
        Self::put_zone_points(&mut self.pts, &self.eye, &map, idx)?;
        let g = self.eye.net.output(1)?;
        // Patch frame → camera frame: the patch axes as image unit vectors (for the mirrored eye
        // the u axis points image-left, which is the x negation of M3_IO.md).
        let xy = map.rotate_unit([f64::from(g[0]), f64::from(g[1])]);
        Ok(normalized([xy[0], xy[1], f64::from(g[2])]))
    }

    /// Landmarks, yaw, face confidence, gestures and gaze of the face in `face` (one call per
    /// face), written into `out`.
    ///
    /// # Errors
    /// [`Error::InvalidInput`] for an empty image or a non-finite / empty box;
    /// [`Error::Internal`] if a network fails to run or level 1 gives non-finite points.
    pub fn estimate(&mut self, image: &GrayImage, face: &Rect, out: &mut FaceLandmarks) -> Result<()> {
        let l1 = self.run_level1(image, face)?;
        let yaw = l1.yaw;
        // Zone reference points are level-1 points (M3_IO.md), never another zone's output.
        self.ref_pts = self.pts;

        let z = &self.cfg.zones;
        let (br, mr) = (z.brows.ref68, z.mouth.ref68);
        let map = Self::zone_map(&self.brows, self.ref_pts[br[0]], self.ref_pts[br[1]], false)?;
        self.brows.run(image, &map, &yaw)?;
        Self::put_zone_points(&mut self.pts, &self.brows, &map, &self.cfg.zones.brows.indices68)?;
        softmax(self.brows.net.output(1)?, &mut out.brows);

        let map = Self::zone_map(&self.mouth, self.ref_pts[mr[0]], self.ref_pts[mr[1]], false)?;
        self.mouth.run(image, &map, &yaw)?;
        Self::put_zone_points(&mut self.pts, &self.mouth, &map, &self.cfg.zones.mouth.indices68)?;
        softmax(self.mouth.net.output(1)?, &mut out.mouth);

        let right = self.run_eye(image, &yaw, false)?;
        let left = self.run_eye(image, &yaw, true)?;
        let both = normalized([left[0] + right[0], left[1] + right[1], left[2] + right[2]]);

        for (o, p) in out.points.iter_mut().zip(&self.pts) {
            *o = [p[0] as f32, p[1] as f32];
        }
        out.yaw_probs = yaw;
        out.face_prob = l1.face_prob;
        out.gaze_right = right.map(|v| v as f32);
        out.gaze_left = left.map(|v| v as f32);
        out.gaze_combined = both.map(|v| v as f32);
        Ok(())
    }
}

//! The M3 detector: configuration (`m3.json`), network loading and the per-face pipeline of
//! `models/M3_IO.md` (level-1 crop → level 1 → zone patches → zone nets → merge into 68 points).

use super::filter::{Bilateral, equalize_hist};
use super::prior::{ShapePrior, ShapePriorConfig};
use super::warp::{Affine, sample};
use super::{BROW_GESTURES, FaceLandmarks, MIRROR68, MOUTH_GESTURES, N_POINTS, YAW_CLASSES_DEG};
use crate::error::{Error, Result};
use crate::image::{GrayImage, Rect};
use crate::math::Libm;
use crate::metrics::outer_eye_distance;
use crate::nn::Net;
use serde::Deserialize;
use std::collections::BTreeMap;

/// The shipped weights and configuration, trained by `models/train/train_m3.py`, by file name
/// (the names `m3.json` refers to). A new zone network needs one line here.
pub const EMBEDDED_FILES: &[(&str, &[u8])] = &[
    ("m3.json", include_bytes!("../../models/m3/m3.json")),
    ("level1.onnx", include_bytes!("../../models/m3/level1.onnx")),
    ("brows.onnx", include_bytes!("../../models/m3/brows.onnx")),
    ("eye.onnx", include_bytes!("../../models/m3/eye.onnx")),
    ("mouth.onnx", include_bytes!("../../models/m3/mouth.onnx")),
    ("face.onnx", include_bytes!("../../models/m3/face.onnx")),
    ("nose.onnx", include_bytes!("../../models/m3/nose.onnx")),
    (
        "mouth_fine.onnx",
        include_bytes!("../../models/m3/mouth_fine.onnx"),
    ),
    (
        "shape_prior.bin",
        include_bytes!("../../models/m3/shape_prior.bin"),
    ),
];

/// The embedded file called `name` ([`EMBEDDED_FILES`]), if there is one.
pub fn embedded_file(name: &str) -> Option<&'static [u8]> {
    EMBEDDED_FILES
        .iter()
        .find(|(n, _)| *n == name)
        .map(|(_, b)| *b)
}

/// Number of level-1 landmarks (`M3_IO.md`).
const N_LEVEL1: usize = 32;

/// How far the 68-point box's top lies above the level-1 points' box, as a fraction of the latter's
/// height: the median over the faces68 training split's annotations (0.164; 10th–90th percentile
/// 0.03–0.22, with pitch and brow shape). [`M3::level1_box`] uses it.
pub const LEVEL1_BOX_TOP: f32 = 0.164;
/// Largest crop or patch side accepted from `m3.json`: far above any sensible network input, it
/// only stops a corrupt configuration from asking for huge buffers.
const MAX_INPUT_SIDE: usize = 1024;
/// Largest bilateral diameter accepted from `m3.json` (a corrupt value must not ask for a huge
/// kernel; the zones use 5).
const MAX_BILATERAL_D: i32 = 31;
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
    /// In mirror-average mode ([`M3::set_mirror_average`]), average the points with the net's run
    /// on the mirrored crop (`M3_IO.md`); yaw and the face probability stay the crop's.
    #[serde(default)]
    pub mirror_average: bool,
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
    /// Per point of `indices68`, the weight of level 1's estimate in the merged point (0: the
    /// zone's point alone). Only landmarks-only zones may blend, and only at level-1 points: the
    /// thesis' zones win in their zones (`M3_IO.md`).
    #[serde(default)]
    pub level1_weight: Option<Vec<f64>>,
    /// Per point of `indices68`, the weight of the point as it stood before this zone ran (level
    /// 1's or an earlier zone's) in the merged point. Landmarks-only zones only, not together
    /// with `level1_weight` (`M3_IO.md`).
    #[serde(default)]
    pub prior_weight: Option<Vec<f64>>,
    /// Where the reference points come from (default: level 1's, with the eye zone's corners).
    #[serde(default)]
    pub refs: RefSource,
    /// In mirror-average mode ([`M3::set_mirror_average`]), average the points and gesture
    /// probabilities with the net's run on the mirrored patch (`M3_IO.md`). Not the eye zone,
    /// which is mirrored per side already.
    #[serde(default)]
    pub mirror_average: bool,
}

/// The points a zone's references are read from (`refs` in `m3.json`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum RefSource {
    /// Level 1's points, with the eye zone's refined corners.
    #[default]
    Level1,
    /// The merged 68 points as they stand when the zone runs (after the zones before it).
    Merged,
}

/// `m3.json`: everything the inference needs besides the weights (`models/M3_IO.md`).
#[derive(Debug, Clone, PartialEq, Deserialize)]
pub struct M3Config {
    /// Schema version (1).
    pub version: u32,
    /// Level-1 network.
    pub level1: Level1Config,
    /// Level-2 networks by zone name. `brows` (brow gestures), `eye` (gaze; the left eye runs
    /// mirrored) and `mouth` (mouth gestures) are required; further zones (e.g. `face`) give
    /// landmarks only.
    pub zones: BTreeMap<String, ZoneConfig>,
    /// Added to the x of every output point, in units of the distance between the output's outer
    /// eye corners (points 36 and 45); 0 when absent. The annotations' systematic x offset, which
    /// the nets cannot learn from mirrored training faces (`models/M3_IO.md`).
    #[serde(default)]
    pub x_offset_iod: f64,
    /// The per-zone regressions from the other points that the merged points move towards, after
    /// the offset; none when absent (`models/M3_IO.md`).
    #[serde(default)]
    pub shape_prior: Option<ShapePriorConfig>,
}

/// Largest `x_offset_iod` accepted from `m3.json` (the shipped value is below 0.01): a larger one
/// is a corrupt or mistaken configuration, not a label convention.
const MAX_X_OFFSET_IOD: f64 = 0.05;

fn bad(msg: String) -> Error {
    Error::ModelLoad(format!("m3.json: {msg}"))
}

fn check_side(what: &str, v: usize) -> Result<()> {
    if v == 0 || v > MAX_INPUT_SIDE {
        return Err(bad(format!("{what} = {v} outside 1..={MAX_INPUT_SIDE}")));
    }
    Ok(())
}

fn check_indices(
    what: &str,
    idx: &[usize],
    n: usize,
    covered: &mut [bool; N_POINTS],
) -> Result<()> {
    if idx.len() != n {
        return Err(bad(format!(
            "{what} has {} indices, expected {n}",
            idx.len()
        )));
    }
    for &i in idx {
        *covered
            .get_mut(i)
            .ok_or_else(|| bad(format!("{what}: index {i} ≥ {N_POINTS}")))? = true;
    }
    Ok(())
}

/// What a zone's outputs mean to [`FaceLandmarks`] besides its points.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum ZoneKind {
    /// Brow gesture logits ([`BROW_GESTURES`]).
    Brows,
    /// Mouth gesture logits ([`MOUTH_GESTURES`]).
    Mouth,
    /// Gaze; run twice, the left eye mirrored.
    Eye,
    /// Landmarks only (e.g. the `face` zone refining jaw and nose).
    Plain,
}

impl ZoneKind {
    fn of(name: &str) -> Self {
        match name {
            "brows" => Self::Brows,
            "mouth" => Self::Mouth,
            "eye" => Self::Eye,
            _ => Self::Plain,
        }
    }

    /// Required landmark count and gesture names of the thesis' zones.
    fn contract(self) -> (Option<usize>, Option<&'static [&'static str]>) {
        match self {
            Self::Brows => (Some(10), Some(&BROW_GESTURES)),
            Self::Mouth => (Some(20), Some(&MOUTH_GESTURES)),
            Self::Eye => (Some(6), None),
            Self::Plain => (None, None),
        }
    }
}

/// The points that exist when a zone runs, in run order (`M3_IO.md`).
struct Given {
    /// Level 1's points: what a `"refs": "level1"` zone may reference (the eye zone's corners,
    /// which replace level 1's, are level-1 points) and `level1_weight` may blend with.
    level1: [bool; N_POINTS],
    /// Points given by level 1 or a zone that runs earlier: what a `"refs": "merged"` zone may
    /// reference and `prior_weight` may blend with.
    merged: [bool; N_POINTS],
}

impl ZoneConfig {
    /// Checks the zone against the contract; `given` = what exists before it runs (in run order),
    /// updated with this zone's points.
    fn validate(&self, name: &str, given: &mut Given) -> Result<()> {
        let kind = ZoneKind::of(name);
        check_side(&format!("{name}.width"), self.width)?;
        check_side(&format!("{name}.height"), self.height)?;
        let [t0, t1] = self.template;
        if !t0.iter().chain(&t1).all(|v| v.is_finite()) || t0 == t1 {
            return Err(bad(format!(
                "{name}.template must hold two distinct finite points"
            )));
        }
        if kind == ZoneKind::Eye && self.mirror_average {
            return Err(bad(format!(
                "{name}.mirror_average: the eye zone runs mirrored per side already"
            )));
        }
        if kind == ZoneKind::Eye && self.refs != RefSource::Level1 {
            return Err(bad(format!(
                "{name}.refs: the eye zone reads level 1's corners"
            )));
        }
        let (available, refs) = match self.refs {
            RefSource::Level1 => (&given.level1, "level1"),
            RefSource::Merged => (&given.merged, "merged"),
        };
        for &r in self.ref68.iter().chain(self.mirror_ref68.iter().flatten()) {
            if !available.get(r).copied().unwrap_or(false) {
                return Err(bad(format!(
                    "{name}: reference point {r} is not given before the zone runs \
                     (refs {refs:?})"
                )));
            }
        }
        let (n_points, gestures) = kind.contract();
        let n = n_points.unwrap_or(self.indices68.len().max(1));
        // Checked before this zone's points join `given`: its prior is what ran before it.
        self.check_blend(name, kind, given)?;
        check_indices(
            &format!("{name}.indices68"),
            &self.indices68,
            n,
            &mut given.merged,
        )?;
        if self.mirror_average {
            flip_partners(&format!("{name}.mirror_average"), &self.indices68)?;
        }
        if let Some(b) = &self.bilateral
            && (!(b.sigma_color.is_finite() && b.sigma_space.is_finite()) || b.d > MAX_BILATERAL_D)
        {
            return Err(bad(format!("{name}.bilateral out of range: {b:?}")));
        }
        let got = self.gestures.as_deref().filter(|g| !g.is_empty());
        let same = match (gestures, got) {
            (None, None) => true,
            (Some(want), Some(got)) => got.iter().map(String::as_str).eq(want.iter().copied()),
            _ => false,
        };
        if !same {
            return Err(bad(format!(
                "{name}.gestures = {got:?}, expected {gestures:?}"
            )));
        }
        if self.gaze != (kind == ZoneKind::Eye) {
            return Err(bad(format!(
                "{name}.gaze = {}: only the eye gives gaze",
                self.gaze
            )));
        }
        match (kind, &self.mirror_ref68, &self.mirror_indices68) {
            (ZoneKind::Eye, Some(_), Some(mi)) => check_indices(
                &format!("{name}.mirror_indices68"),
                mi,
                n,
                &mut given.merged,
            ),
            (ZoneKind::Eye, _, _) => Err(bad(format!(
                "{name} needs mirror_ref68 and mirror_indices68"
            ))),
            (_, None, None) => Ok(()),
            _ => Err(bad(format!("{name}: only the eye zone is mirrored"))),
        }
    }

    /// `level1_weight` / `prior_weight`: one weight in 0..=1 per point of a landmarks-only zone,
    /// not both, and > 0 only where the other estimate exists before the zone runs.
    fn check_blend(&self, name: &str, kind: ZoneKind, given: &Given) -> Result<()> {
        let (field, w, exists) = match (&self.level1_weight, &self.prior_weight) {
            (None, None) => return Ok(()),
            (Some(w), None) => ("level1_weight", w, &given.level1),
            (None, Some(w)) => ("prior_weight", w, &given.merged),
            (Some(_), Some(_)) => {
                return Err(bad(format!(
                    "{name}: level1_weight and prior_weight together"
                )));
            }
        };
        if kind != ZoneKind::Plain || w.len() != self.indices68.len() {
            return Err(bad(format!(
                "{name}.{field}: {} weights for {} points (landmarks-only zones only)",
                w.len(),
                self.indices68.len()
            )));
        }
        for (&wk, &i) in w.iter().zip(&self.indices68) {
            if !(0.0..=1.0).contains(&wk) || (wk > 0.0 && !exists.get(i).copied().unwrap_or(false))
            {
                return Err(bad(format!(
                    "{name}.{field} of point {i} = {wk}: must be in 0..=1, and 0 where there \
                     is no point to blend with"
                )));
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
    /// (index counts, gesture order, missing zones, uncovered points, sizes).
    pub fn from_json(bytes: &[u8]) -> Result<Self> {
        let cfg: Self = serde_json::from_slice(bytes).map_err(|e| bad(e.to_string()))?;
        cfg.validate()?;
        Ok(cfg)
    }

    fn validate(&self) -> Result<()> {
        if self.version != 1 {
            return Err(bad(format!(
                "version {} (this build reads 1)",
                self.version
            )));
        }
        if !(self.x_offset_iod.is_finite() && self.x_offset_iod.abs() <= MAX_X_OFFSET_IOD) {
            return Err(bad(format!(
                "x_offset_iod = {} (|value| ≤ {MAX_X_OFFSET_IOD})",
                self.x_offset_iod
            )));
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
        let mut level1 = [false; N_POINTS];
        check_indices("level1.indices68", &l1.indices68, N_LEVEL1, &mut level1)?;
        if l1.mirror_average {
            flip_partners("level1.mirror_average", &l1.indices68)?;
        }
        for required in ["brows", "eye", "mouth"] {
            if !self.zones.contains_key(required) {
                return Err(bad(format!("zone {required:?} missing")));
            }
        }
        let mut given = Given {
            level1,
            merged: level1,
        };
        for (name, z) in self.run_order() {
            z.validate(name, &mut given)?;
        }
        if let Some(i) = given.merged.iter().position(|c| !c) {
            return Err(bad(format!("landmark {i} is produced by no network")));
        }
        if let Some(p) = &self.shape_prior {
            p.validate()?;
        }
        Ok(())
    }
}

impl M3Config {
    /// The zones in the order they run: the eye first, then the others by name (`M3_IO.md`).
    fn run_order(&self) -> impl Iterator<Item = (&String, &ZoneConfig)> {
        let eye = self.zones.iter().filter(|(n, _)| n.as_str() == "eye");
        eye.chain(self.zones.iter().filter(|(n, _)| n.as_str() != "eye"))
    }
}

/// A level-2 zone at run time: its configuration, network and patch buffers.
#[derive(Debug)]
struct Zone {
    kind: ZoneKind,
    width: usize,
    height: usize,
    ref68: [usize; 2],
    indices68: Vec<usize>,
    /// The mirrored eye's references and indices.
    mirror: Option<([usize; 2], Vec<usize>)>,
    /// Template positions in patch pixels.
    q: [[f64; 2]; 2],
    /// `(68 index, level-1 weight)` of the points blended with level 1's.
    level1_blend: Vec<(usize, f64)>,
    /// `(68 index, prior weight)` of the points blended with their value before the zone ran.
    prior_blend: Vec<(usize, f64)>,
    /// References from the merged points instead of level 1's (`"refs": "merged"`).
    merged_refs: bool,
    bilateral: Option<Bilateral>,
    equalize: bool,
    net: Net,
    patch: Vec<u8>,
    filtered: Vec<u8>,
    /// With `mirror_average`: per output point, the mirrored run's point that estimates it.
    flip: Option<Vec<usize>>,
    /// The last run's points, net units, `(x, y)` interleaved (averaged with the mirrored run's
    /// under `flip`).
    lm: Vec<f64>,
    /// The last run's gesture probabilities (averaged likewise), if the zone has gestures.
    gestures: Vec<f32>,
    /// The mirrored run's gesture probabilities.
    gestures_flipped: Vec<f32>,
}

impl Zone {
    fn new(name: &str, cfg: &ZoneConfig, bytes: &[u8]) -> Result<Self> {
        let kind = ZoneKind::of(name);
        let (w, h) = (cfg.width, cfg.height);
        let n_gestures = cfg.gestures.as_ref().map_or(0, Vec::len);
        let mut outputs = vec!["landmarks"];
        let mut sizes = vec![2 * cfg.indices68.len()];
        if n_gestures > 0 {
            outputs.push("gesture_logits");
            sizes.push(n_gestures);
        }
        if cfg.gaze {
            outputs.push("gaze");
            sizes.push(3);
        }
        // One patch per run, the eyes too: tract gathers a batch of one lazily inside its matrix
        // products but a batch of two into an im2col buffer first, which was slower than two
        // runs of one (`profile_net` on the eye net).
        let mut net = Net::load(
            name,
            bytes,
            &[("patch", &[1, 1, h, w]), ("yaw", &[1, 5])],
            &outputs,
        )?;
        check_outputs(name, &mut net, &sizes)?;
        Ok(Self {
            kind,
            width: w,
            height: h,
            ref68: cfg.ref68,
            indices68: cfg.indices68.clone(),
            mirror: cfg.mirror_ref68.zip(cfg.mirror_indices68.clone()),
            q: cfg.template.map(|t| [t[0] * w as f64, t[1] * h as f64]),
            level1_blend: blend_pairs(&cfg.indices68, cfg.level1_weight.as_deref()),
            prior_blend: blend_pairs(&cfg.indices68, cfg.prior_weight.as_deref()),
            merged_refs: cfg.refs == RefSource::Merged,
            bilateral: cfg
                .bilateral
                .map(|b| Bilateral::new(b.d, b.sigma_color, b.sigma_space)),
            equalize: cfg.equalize,
            net,
            patch: Vec::with_capacity(w * h),
            filtered: vec![0; w * h],
            flip: cfg
                .mirror_average
                .then(|| flip_partners(name, &cfg.indices68))
                .transpose()?,
            lm: vec![0.0; 2 * cfg.indices68.len()],
            gestures: vec![0.0; n_gestures],
            gestures_flipped: vec![0.0; n_gestures],
        })
    }

    /// The patch map from the two reference points (image pixels), `M3_IO.md`.
    fn map(&self, p0: [f64; 2], p1: [f64; 2], mirror: bool) -> Result<Affine> {
        let [q0, q1] = self.q;
        let w = self.width as f64;
        let (q0, q1) = if mirror {
            ([w - q0[0], q0[1]], [w - q1[0], q1[1]])
        } else {
            (q0, q1)
        };
        let map = Affine::similarity(p0, p1, q0, q1).ok_or_else(|| {
            Error::Internal(format!(
                "non-finite level-1 reference points {p0:?}, {p1:?}"
            ))
        })?;
        Ok(if mirror { map.mirrored_x(w) } else { map })
    }

    /// Samples and filters the patch of `map` into the network input.
    fn prepare(&mut self, image: &GrayImage, map: &Affine) -> Result<()> {
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
        self.net.fill_input(0, |x| to_unit(src, x))
    }

    /// Runs the network on the prepared patch with `yaw` and keeps its points and gesture
    /// probabilities; with `mirror` and the zone's `mirror_average` also on the mirrored patch
    /// with the yaw classes reversed, and averages (`M3_IO.md`).
    fn run(&mut self, yaw: &[f32; 5], mirror: bool) -> Result<()> {
        self.net.fill_input(1, |x| x.copy_from_slice(yaw))?;
        self.net.run()?;
        read_points(self.net.output(0)?, &mut self.lm);
        let has_gestures = !self.gestures.is_empty();
        if has_gestures {
            softmax(self.net.output(1)?, &mut self.gestures);
        }
        let Some(partner) = self.flip.as_ref().filter(|_| mirror) else {
            return Ok(());
        };
        let (src, w) = (&self.patch, self.width);
        self.net.fill_input(0, |x| to_unit_mirrored(src, w, x))?;
        self.net.fill_input(1, |x| {
            for (d, &s) in x.iter_mut().zip(yaw.iter().rev()) {
                *d = s;
            }
        })?;
        self.net.run()?;
        average_flipped(&mut self.lm, self.net.output(0)?, partner);
        if has_gestures {
            softmax(self.net.output(1)?, &mut self.gestures_flipped);
            for (g, &f) in self.gestures.iter_mut().zip(&self.gestures_flipped) {
                *g = 0.5 * (*g + f);
            }
        }
        Ok(())
    }

    /// Writes the points of the last run through `map` into `pts[indices]` (the mirrored eye's
    /// indices when `mirrored`).
    fn write_points(&self, map: &Affine, mirrored: bool, pts: &mut [[f64; 2]; N_POINTS]) {
        let idx = match (&self.mirror, mirrored) {
            (Some((_, mi)), true) => mi,
            _ => &self.indices68,
        };
        let lm = &self.lm;
        let (wf, hf) = (self.width as f64, self.height as f64);
        for (k, &i) in idx.iter().enumerate() {
            pts[i] = map.apply([lm[2 * k] * wf, lm[2 * k + 1] * hf]);
        }
    }

    /// A single-patch zone: samples, filters and runs it for the patch map `map` and writes its
    /// points. The other outputs stay in the net.
    fn run_one(
        &mut self,
        image: &GrayImage,
        map: &Affine,
        yaw: &[f32; 5],
        mirror: bool,
        pts: &mut [[f64; 2]; N_POINTS],
    ) -> Result<()> {
        self.prepare(image, map)?;
        self.run(yaw, mirror)?;
        self.write_points(map, false, pts);
        Ok(())
    }

    /// Both eyes, the right eye then the left eye mirrored, one run each; returns their unit gaze
    /// vectors in the camera frame, right then left.
    fn run_eyes(
        &mut self,
        image: &GrayImage,
        refs: &[[f64; 2]; N_POINTS],
        yaw: &[f32; 5],
        pts: &mut [[f64; 2]; N_POINTS],
    ) -> Result<[[f64; 3]; 2]> {
        let mirror_ref = match &self.mirror {
            Some((r, _)) => *r,
            None => return Err(Error::Internal("eye zone without its mirror".into())),
        };
        let maps = [
            self.map(refs[self.ref68[0]], refs[self.ref68[1]], false)?,
            self.map(refs[mirror_ref[0]], refs[mirror_ref[1]], true)?,
        ];
        let mut gaze = [[0.0; 3]; 2];
        for (slot, map) in maps.iter().enumerate() {
            self.prepare(image, map)?;
            self.run(yaw, false)?;
            self.write_points(map, slot == 1, pts);
            let g = &self.net.output(1)?[..3];
            // Patch frame → camera frame: the patch axes as image unit vectors. For the mirrored
            // eye the u axis points the other way, which is M3_IO.md's "gaze x negated".
            let xy = map.rotate_unit([f64::from(g[0]), f64::from(g[1])]);
            gaze[slot] = normalized([xy[0], xy[1], f64::from(g[2])]);
        }
        Ok(gaze)
    }
}

/// Runs `net` once on its zero inputs to check its output sizes (and warm its plan up).
fn check_outputs(name: &str, net: &mut Net, sizes: &[usize]) -> Result<()> {
    net.run()?;
    for (k, &want) in sizes.iter().enumerate() {
        let got = net.output(k)?.len();
        if got != want {
            return Err(Error::ModelLoad(format!(
                "{name}: output {k} has {got} values, expected {want}"
            )));
        }
    }
    Ok(())
}

/// u8 pixels → float32 `pixel / 255` (`M3_IO.md`, network input).
fn to_unit(src: &[u8], dst: &mut [f32]) {
    for (d, &s) in dst.iter_mut().zip(src) {
        *d = f32::from(s) / 255.0;
    }
}

/// As [`to_unit`], of the image of rows `width` long mirrored left–right.
fn to_unit_mirrored(src: &[u8], width: usize, dst: &mut [f32]) {
    for (d, s) in dst.chunks_exact_mut(width).zip(src.chunks_exact(width)) {
        for (d, &s) in d.iter_mut().zip(s.iter().rev()) {
            *d = f32::from(s) / 255.0;
        }
    }
}

/// Softmax of `logits` into `out` (as many values as `out` holds).
fn softmax(logits: &[f32], out: &mut [f32]) {
    let m = logits.iter().copied().fold(f32::NEG_INFINITY, f32::max);
    let mut sum = 0.0;
    for (o, &l) in out.iter_mut().zip(logits) {
        *o = (l - m).mexp();
        sum += *o;
    }
    for o in out.iter_mut() {
        *o /= sum;
    }
}

fn normalized(v: [f64; 3]) -> [f64; 3] {
    let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
        .sqrt()
        .max(NORM_EPS);
    [v[0] / n, v[1] / n, v[2] / n]
}

/// For each point of `indices` (68 indices, all < [`N_POINTS`]), the position in `indices` of its
/// mirror image ([`MIRROR68`]): where a net's run on the mirrored input gives that point.
///
/// # Errors
/// [`Error::ModelLoad`] if a point's mirror image is not among `indices`.
fn flip_partners(what: &str, indices: &[usize]) -> Result<Vec<usize>> {
    indices
        .iter()
        .map(|&i| {
            let m = MIRROR68[i];
            indices.iter().position(|&j| j == m).ok_or_else(|| {
                bad(format!(
                    "{what}: the mirror image {m} of point {i} is not among the net's points"
                ))
            })
        })
        .collect()
}

/// The last run's points, net units, `(x, y)` interleaved: the first `lm.len()` values of `out`.
fn read_points(out: &[f32], lm: &mut [f64]) {
    for (d, &s) in lm.iter_mut().zip(out) {
        *d = f64::from(s);
    }
}

/// Averages `lm` (points of the input, net units) with `flipped` (the same net's points for the
/// mirrored input), un-mirrored: x ↦ 1 − x, and point k's estimate is the mirrored run's point
/// `partner[k]` (`M3_IO.md`).
fn average_flipped(lm: &mut [f64], flipped: &[f32], partner: &[usize]) {
    for (k, &j) in partner.iter().enumerate() {
        lm[2 * k] = 0.5 * (lm[2 * k] + (1.0 - f64::from(flipped[2 * j])));
        lm[2 * k + 1] = 0.5 * (lm[2 * k + 1] + f64::from(flipped[2 * j + 1]));
    }
}

/// `(68 index, weight)` for the points of `indices` with a weight above 0.
fn blend_pairs(indices: &[usize], weights: Option<&[f64]>) -> Vec<(usize, f64)> {
    weights
        .iter()
        .flat_map(|w| indices.iter().copied().zip(w.iter().copied()))
        .filter(|&(_, w)| w > 0.0)
        .collect()
}

/// `(1 − w) · a + w · b`.
fn lerp(a: [f64; 2], b: [f64; 2], w: f64) -> [f64; 2] {
    [(1.0 - w) * a[0] + w * b[0], (1.0 - w) * a[1] + w * b[1]]
}

/// The M3 landmark and gesture detector (thesis section 3.3). See the module docs.
#[derive(Debug)]
pub struct M3 {
    cfg: M3Config,
    level1: Net,
    /// With level 1's `mirror_average`: per level-1 point, the mirrored run's point that
    /// estimates it.
    level1_flip: Option<Vec<usize>>,
    /// Mirror-average mode ([`M3::set_mirror_average`]).
    mirror_average: bool,
    /// Level 1's points of the last run, crop units, `(x, y)` interleaved.
    level1_lm: Vec<f64>,
    zones: Vec<Zone>,
    crop: Vec<u8>,
    /// The merged 68 points of the face in progress, image pixels.
    pts: [[f64; 2]; N_POINTS],
    /// The zone references of the face in progress: level 1's points, then the eye corners.
    ref_pts: [[f64; 2]; N_POINTS],
    /// Level 1's points of the face in progress (for the zones that blend with them).
    level1_pts: [[f64; 2]; N_POINTS],
    /// The merged points before the running zone (for `prior_weight`).
    prior_pts: [[f64; 2]; N_POINTS],
    /// `shape_prior` of `m3.json`.
    prior: Option<ShapePrior>,
}

/// What level 1 gives besides its points.
struct Level1Out {
    yaw: [f32; 5],
    face_prob: f32,
}

impl M3 {
    /// The detector with the weights embedded in the library ([`EMBEDDED_FILES`], `models/m3/`).
    ///
    /// # Errors
    /// [`Error::ModelLoad`] if the embedded models cannot be loaded (a build defect).
    pub fn new() -> Result<Self> {
        let json = embedded_file("m3.json")
            .ok_or_else(|| Error::ModelLoad("m3.json not embedded".into()))?;
        Self::from_bytes(json, EMBEDDED_FILES)
    }

    /// M3 from other weights: `m3.json` and the network files it names, given as
    /// (file name, ONNX bytes) pairs (`models/M3_IO.md`).
    ///
    /// # Errors
    /// [`Error::ModelLoad`] for malformed JSON, a configuration that breaks the contract, a file
    /// it names that is not given, ONNX bytes tract cannot load, or networks whose inputs/outputs
    /// do not match the contract.
    pub fn from_bytes(json: &[u8], files: &[(&str, &[u8])]) -> Result<Self> {
        let cfg = M3Config::from_json(json)?;
        let file = |name: &str| {
            files
                .iter()
                .find(|(n, _)| *n == name)
                .map(|(_, b)| *b)
                .ok_or_else(|| Error::ModelLoad(format!("model file {name:?} not given")))
        };
        let s = cfg.level1.input_size;
        let mut level1 = Net::load(
            "level1",
            file(&cfg.level1.file)?,
            &[("image", &[1, 1, s, s])],
            &["landmarks", "yaw_logits", "face_logit"],
        )?;
        check_outputs("level1", &mut level1, &[2 * N_LEVEL1, 5, 1])?;
        // The order `validate` checked the references in (the eye first: its corners are the
        // other zones' references).
        let zones = cfg
            .run_order()
            .map(|(name, z)| Zone::new(name, z, file(&z.file)?))
            .collect::<Result<Vec<_>>>()?;
        let prior = cfg
            .shape_prior
            .as_ref()
            .map(|p| ShapePrior::new(p, file(&p.file)?))
            .transpose()?;
        let level1_flip = cfg
            .level1
            .mirror_average
            .then(|| flip_partners("level1", &cfg.level1.indices68))
            .transpose()?;
        Ok(Self {
            crop: Vec::with_capacity(s * s),
            level1_flip,
            mirror_average: false,
            level1_lm: vec![0.0; 2 * N_LEVEL1],
            prior,
            cfg,
            level1,
            zones,
            pts: [[0.0; 2]; N_POINTS],
            ref_pts: [[0.0; 2]; N_POINTS],
            level1_pts: [[0.0; 2]; N_POINTS],
            prior_pts: [[0.0; 2]; N_POINTS],
        })
    }

    /// The configuration in use.
    pub fn config(&self) -> &M3Config {
        &self.cfg
    }

    /// Mirror-average mode on or off (off when built). On, level 1 and every zone whose
    /// `mirror_average` is set in `m3.json` also run on their mirrored input, and each such net's
    /// points (and gesture probabilities) are the average of both runs (`M3_IO.md`): more accurate
    /// and slower, as those nets run twice (`models/MODEL_CARD.md` has both modes' figures).
    pub fn set_mirror_average(&mut self, on: bool) {
        self.mirror_average = on;
    }

    /// Whether mirror-average mode is on ([`M3::set_mirror_average`]).
    pub fn mirror_average(&self) -> bool {
        self.mirror_average
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

    /// Runs level 1 on the crop of `face` and, with `points`, writes its points into `self.pts`
    /// (under `mirror_average` averaged with the mirrored crop's run, which the face probability
    /// alone does not need).
    ///
    /// `roll` (radians, image y down) turns the crop so that a face turned by it stands upright.
    /// The crop keeps the box's side: the tight box of a face's points grows little as the face
    /// turns (the outline is round), and shrinking the crop by the `|cos| + |sin|` a turned square
    /// grows by cost level 1 more than it saved (the astronaut turned by ±40° read worse shrunk
    /// than not).
    fn run_level1(
        &mut self,
        image: &GrayImage,
        face: &Rect,
        roll: f32,
        points: bool,
    ) -> Result<Level1Out> {
        Self::check_input(image, face)?;
        if !roll.is_finite() {
            return Err(Error::InvalidInput(format!(
                "roll must be finite, got {roll}"
            )));
        }
        let l1 = &self.cfg.level1;
        let s = l1.input_size;
        let c = face.center();
        let side = f64::from(face.w.max(face.h));
        let map = Affine::turned_square_crop(
            [f64::from(c[0]), f64::from(c[1])],
            l1.crop_scale * side,
            s,
            f64::from(roll),
        );
        sample(image, &map, s, s, &mut self.crop)?;
        let crop = &self.crop;
        self.level1.fill_input(0, |x| to_unit(crop, x))?;
        self.level1.run()?;
        let mut yaw = [0.0; 5];
        softmax(self.level1.output(1)?, &mut yaw);
        let logit = self.level1.output(2)?[0];
        if points {
            read_points(self.level1.output(0)?, &mut self.level1_lm);
            if let Some(partner) = self.level1_flip.as_ref().filter(|_| self.mirror_average) {
                self.level1
                    .fill_input(0, |x| to_unit_mirrored(crop, s, x))?;
                self.level1.run()?;
                average_flipped(&mut self.level1_lm, self.level1.output(0)?, partner);
            }
            let lm = &self.level1_lm;
            for (k, &i) in l1.indices68.iter().enumerate() {
                self.pts[i] = map.apply([lm[2 * k] * s as f64, lm[2 * k + 1] * s as f64]);
            }
        }
        Ok(Level1Out {
            yaw,
            face_prob: 1.0 / (1.0 + (-logit).mexp()),
        })
    }

    /// Level 1 only: the probability that the crop of `face` holds a face (the tracker's check of
    /// its patch).
    ///
    /// # Errors
    /// [`Error::InvalidInput`] for an empty image or a non-finite / empty box;
    /// [`Error::Internal`] if the network fails to run.
    pub fn face_confidence(&mut self, image: &GrayImage, face: &Rect) -> Result<f32> {
        Ok(self.run_level1(image, face, 0.0, false)?.face_prob)
    }

    /// Level 1 alone on `face`: writes its points (at their 68-point indices), the yaw
    /// probabilities and the face probability into `out` and returns the face probability. The
    /// tracker checks a window with it and then, if the window holds a face, finishes the same
    /// face with [`M3::refine`] instead of running level 1 twice.
    ///
    /// # Errors
    /// As [`M3::face_confidence`].
    pub fn level1(
        &mut self,
        image: &GrayImage,
        face: &Rect,
        out: &mut FaceLandmarks,
    ) -> Result<f32> {
        self.level1_turned(image, face, 0.0, out)
    }

    /// [`M3::level1`] on a crop turned by `roll` (radians, image y down; the eye line's angle of
    /// the face expected in `face`): level 1 was trained on faces within about ±25° of upright, so
    /// a tracker that knows its face's roll reads the face upright at any roll. The points come
    /// back in image coordinates; `roll = 0` is [`M3::level1`].
    ///
    /// # Errors
    /// As [`M3::face_confidence`], and [`Error::InvalidInput`] for a non-finite `roll`.
    pub fn level1_turned(
        &mut self,
        image: &GrayImage,
        face: &Rect,
        roll: f32,
        out: &mut FaceLandmarks,
    ) -> Result<f32> {
        let l1 = self.run_level1(image, face, roll, true)?;
        for &i in &self.cfg.level1.indices68 {
            out.points[i] = [self.pts[i][0] as f32, self.pts[i][1] as f32];
        }
        out.yaw_probs = l1.yaw;
        out.face_prob = l1.face_prob;
        Ok(l1.face_prob)
    }

    /// The face's box in the M3 convention (the tight box of the 68 landmarks), estimated from the
    /// level-1 points [`M3::level1`] left in `out`: their tight box, raised at the top by
    /// [`LEVEL1_BOX_TOP`] of its height for the brows level 1 does not give. `None` when a point is
    /// not finite or the box is empty. The detection cascade (`crate::track`) checks a detection
    /// again on this box: the detector's boxes of small faces are off by enough to cost the
    /// face check and the IoU (`models/train/RESEARCH_LOG.md`, "Face detector").
    pub fn level1_box(&self, out: &FaceLandmarks) -> Option<Rect> {
        let (mut x0, mut y0) = (f32::INFINITY, f32::INFINITY);
        let (mut x1, mut y1) = (f32::NEG_INFINITY, f32::NEG_INFINITY);
        for &i in &self.cfg.level1.indices68 {
            let [x, y] = out.points[i];
            if !(x.is_finite() && y.is_finite()) {
                return None;
            }
            x0 = x0.min(x);
            y0 = y0.min(y);
            x1 = x1.max(x);
            y1 = y1.max(y);
        }
        let h = y1 - y0;
        let rect = Rect::new(
            x0,
            y0 - LEVEL1_BOX_TOP * h,
            x1 - x0,
            h * (1.0 + LEVEL1_BOX_TOP),
        );
        rect.is_valid().then_some(rect)
    }

    /// Level 2 on a face whose level-1 outputs are in `out` (from [`M3::level1`] on the same
    /// image): the zone landmarks replace level 1's in their zones, and the gestures and gaze are
    /// filled in.
    ///
    /// # Errors
    /// [`Error::InvalidInput`] for an empty image or non-finite level-1 points in `out`;
    /// [`Error::Internal`] if a network fails to run.
    pub fn refine(&mut self, image: &GrayImage, out: &mut FaceLandmarks) -> Result<()> {
        if image.width() == 0 || image.height() == 0 {
            return Err(Error::InvalidInput(format!(
                "empty image {}x{}",
                image.width(),
                image.height()
            )));
        }
        if let Some(i) = self.non_finite_level1_point(out) {
            return Err(Error::InvalidInput(format!(
                "level-1 point {i} is not finite: {:?}",
                out.points[i]
            )));
        }
        for &i in &self.cfg.level1.indices68 {
            let p = out.points[i];
            self.pts[i] = [f64::from(p[0]), f64::from(p[1])];
        }
        let yaw = out.yaw_probs;
        // Zone references are level 1's points, except the eye zone's own references (the eye
        // corners), which its output replaces: it runs first (M3_IO.md). A `"refs": "merged"`
        // zone reads the merged points instead.
        self.ref_pts = self.pts;
        self.level1_pts = self.pts;
        for zone in &mut self.zones {
            if zone.kind == ZoneKind::Eye {
                let [right, left] = zone.run_eyes(image, &self.ref_pts, &yaw, &mut self.pts)?;
                let both = normalized([left[0] + right[0], left[1] + right[1], left[2] + right[2]]);
                out.gaze_right = right.map(|v| v as f32);
                out.gaze_left = left.map(|v| v as f32);
                out.gaze_combined = both.map(|v| v as f32);
                for &i in zone
                    .ref68
                    .iter()
                    .chain(zone.mirror.iter().flat_map(|(r, _)| r))
                {
                    self.ref_pts[i] = self.pts[i];
                }
                continue;
            }
            let refs = if zone.merged_refs {
                &self.pts
            } else {
                &self.ref_pts
            };
            let map = zone.map(refs[zone.ref68[0]], refs[zone.ref68[1]], false)?;
            if !zone.prior_blend.is_empty() {
                self.prior_pts = self.pts;
            }
            zone.run_one(image, &map, &yaw, self.mirror_average, &mut self.pts)?;
            for &(i, w) in &zone.level1_blend {
                self.pts[i] = lerp(self.pts[i], self.level1_pts[i], w);
            }
            for &(i, w) in &zone.prior_blend {
                self.pts[i] = lerp(self.pts[i], self.prior_pts[i], w);
            }
            match zone.kind {
                ZoneKind::Brows => out.brows.copy_from_slice(&zone.gestures),
                ZoneKind::Mouth => out.mouth.copy_from_slice(&zone.gestures),
                ZoneKind::Eye | ZoneKind::Plain => {}
            }
        }
        let dx = self.cfg.x_offset_iod * outer_eye_distance(&self.pts);
        for p in &mut self.pts {
            p[0] += dx;
        }
        // After the offset: the regressions were fitted on points that carry it.
        if let Some(prior) = &mut self.prior {
            prior.apply(&mut self.pts);
        }
        for (o, p) in out.points.iter_mut().zip(&self.pts) {
            *o = [p[0] as f32, p[1] as f32];
        }
        Ok(())
    }

    /// Landmarks, yaw, face confidence, gestures and gaze of the face in `face` (one call per
    /// face), written into `out`: [`M3::level1`] then [`M3::refine`].
    ///
    /// # Errors
    /// [`Error::InvalidInput`] for an empty image or a non-finite / empty box;
    /// [`Error::Internal`] if a network fails to run or level 1 gives non-finite points.
    pub fn estimate(
        &mut self,
        image: &GrayImage,
        face: &Rect,
        out: &mut FaceLandmarks,
    ) -> Result<()> {
        self.level1(image, face, out)?;
        // Here a non-finite point is the network's fault, not the caller's.
        if let Some(i) = self.non_finite_level1_point(out) {
            return Err(Error::Internal(format!(
                "level 1 gave a non-finite point {i}"
            )));
        }
        self.refine(image, out)
    }

    /// The first level-1 point of `out` that is not finite, if any.
    fn non_finite_level1_point(&self, out: &FaceLandmarks) -> Option<usize> {
        self.cfg.level1.indices68.iter().copied().find(|&i| {
            let p = out.points[i];
            !(p[0].is_finite() && p[1].is_finite())
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::Value;

    fn embedded(name: &str) -> &'static [u8] {
        embedded_file(name).unwrap()
    }

    fn json_with(edit: impl FnOnce(&mut Value)) -> Vec<u8> {
        let mut v: Value = serde_json::from_slice(embedded("m3.json")).unwrap();
        edit(&mut v);
        serde_json::to_vec(&v).unwrap()
    }

    fn image() -> GrayImage {
        let (w, h) = (160, 120);
        let data = (0..w * h)
            .map(|i| (((i % w) * 3 + (i / w) * 2 + (i * 31) % 17) % 256) as u8)
            .collect();
        GrayImage::from_vec(w, h, data).unwrap()
    }

    #[test]
    fn mirror68_is_an_involution_within_each_zone() {
        for (i, &m) in MIRROR68.iter().enumerate() {
            assert_eq!(MIRROR68[m], i);
        }
        for zone in [0..17, 17..27, 27..36, 36..48, 48..60, 60..68] {
            assert!(
                zone.clone().all(|i| zone.contains(&MIRROR68[i])),
                "{zone:?}"
            );
        }
        // The nose ridge lies on the symmetry line.
        assert_eq!(&MIRROR68[27..31], &[27, 28, 29, 30]);
    }

    #[test]
    fn flip_partners_pair_each_point_with_its_mirror_image() {
        assert_eq!(flip_partners("t", &[0, 16, 8]).unwrap(), vec![1, 0, 2]);
        assert_eq!(flip_partners("t", &[27, 36, 45]).unwrap(), vec![0, 2, 1]);
        assert!(matches!(
            flip_partners("t", &[0, 1]),
            Err(Error::ModelLoad(_))
        ));
        // Un-mirroring: the mirrored run's point 1 (x 0.3) is point 0's estimate at x 0.7.
        let mut lm = [0.6, 0.5, 0.2, 0.4];
        average_flipped(&mut lm, &[0.9, 0.3, 0.3, 0.7], &[1, 0]);
        for (got, want) in lm.iter().zip([0.65, 0.6, 0.15, 0.35]) {
            assert!((got - want).abs() < 1e-6, "{lm:?}");
        }
    }

    #[test]
    fn mirror_average_makes_level_1_symmetric_on_a_symmetric_crop() {
        // Rows symmetric about x = 80 and a box centred there whose crop maps pixels one to one
        // (crop side = 1.3 · box side = 64): the crop is its own mirror image, so averaging its
        // points with the mirrored run's puts each point and its mirror image symmetric about
        // x = 80 — exactly, up to rounding. Without averaging the net alone is not symmetric.
        let (w, h) = (160, 120);
        let data = (0..w * h)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                let d = if x < w / 2 { w / 2 - 1 - x } else { x - w / 2 };
                ((d * 7 + y * 3 + (d * y) % 23) % 256) as u8
            })
            .collect();
        let img = GrayImage::from_vec(w, h, data).unwrap();
        let side = 64.0 / 1.3;
        let face = Rect::new(80.0 - side / 2.0, 30.0, side, side);
        let mut m3 = M3::new().unwrap();
        let mut out = FaceLandmarks::default();
        let asymmetry = |m3: &mut M3, out: &mut FaceLandmarks| {
            m3.level1(&img, &face, out).unwrap();
            let l1 = m3.config().level1.indices68.clone();
            l1.iter()
                .map(|&i| {
                    let (p, q) = (out.points[i], out.points[MIRROR68[i]]);
                    (p[0] + q[0] - 160.0).abs().max((p[1] - q[1]).abs())
                })
                .fold(0.0, f32::max)
        };
        assert!(!m3.mirror_average());
        let plain = asymmetry(&mut m3, &mut out);
        m3.set_mirror_average(true);
        let averaged = asymmetry(&mut m3, &mut out);
        assert!(averaged < 1e-3, "{averaged} px");
        assert!(plain > 0.05, "{plain} px");
    }

    #[test]
    fn mirror_average_mode_changes_the_marked_nets_only() {
        // `estimate_in_mode` runs without the shape prior, which would move every zone's points
        // with any other's.
        let off = estimate_in_mode(&|_| {}, false);
        let on = estimate_in_mode(&|_| {}, true);
        assert_ne!(off.points, on.points);
        assert_eq!(off.yaw_probs, on.yaw_probs);
        assert_eq!(off.face_prob, on.face_prob);
        assert_ne!(off.mouth, on.mouth);
        // With no net marked, the mode changes nothing.
        let unmarked = |v: &mut Value| {
            v["level1"]["mirror_average"] = false.into();
            for z in v["zones"].as_object_mut().unwrap().values_mut() {
                z["mirror_average"] = false.into();
            }
        };
        assert_eq!(estimate_in_mode(&unmarked, true), off);
        // Only the mouth marked: level 1's points stay, so the eyes (from level 1's corners)
        // stay too; the mouth's points and gestures move.
        let mouth_only = |v: &mut Value| {
            unmarked(v);
            v["zones"]["mouth"]["mirror_average"] = true.into();
        };
        let m = estimate_in_mode(&mouth_only, true);
        assert_eq!(&m.points[36..48], &off.points[36..48]);
        assert_ne!(&m.points[48..60], &off.points[48..60]);
        assert_ne!(m.mouth, off.mouth);
        assert_eq!(m.brows, off.brows);
    }

    #[test]
    fn m3_is_send() {
        fn send<T: Send>() {}
        send::<M3>();
    }

    #[test]
    fn embedded_models_load_and_give_finite_consistent_outputs() {
        let mut m3 = M3::new().unwrap();
        let img = image();
        let face = Rect::new(40.0, 20.0, 70.0, 80.0);
        let mut a = FaceLandmarks::default();
        m3.estimate(&img, &face, &mut a).unwrap();
        assert!(a.points.iter().flatten().all(|v| v.is_finite()));
        for p in [&a.yaw_probs[..], &a.mouth[..], &a.brows[..]] {
            assert!((p.iter().sum::<f32>() - 1.0).abs() < 1e-4);
        }
        for g in [a.gaze_left, a.gaze_right, a.gaze_combined] {
            let n = g.iter().map(|v| v * v).sum::<f32>().sqrt();
            assert!((n - 1.0).abs() < 1e-4, "{g:?}");
        }
        assert!((0.0..=1.0).contains(&a.face_prob));
        // A call on another box in between changes nothing: no state leaks between faces.
        let mut b = FaceLandmarks::default();
        m3.estimate(&img, &Rect::new(0.0, 0.0, 30.0, 30.0), &mut b)
            .unwrap();
        m3.estimate(&img, &face, &mut b).unwrap();
        assert_eq!(a, b);
        let conf = m3.face_confidence(&img, &face).unwrap();
        assert_eq!(conf, a.face_prob);
    }

    #[test]
    fn level1_box_bounds_the_level1_points_and_adds_the_brows() {
        let mut m3 = M3::new().unwrap();
        let img = image();
        let mut lm = FaceLandmarks::default();
        m3.level1(&img, &test_face(), &mut lm).unwrap();
        let b = m3.level1_box(&lm).unwrap();
        let idx = &m3.cfg.level1.indices68;
        let ys = idx.iter().map(|&i| lm.points[i][1]);
        let (top, bottom) = ys.fold((f32::MAX, f32::MIN), |(a, c), y| (a.min(y), c.max(y)));
        for &i in idx {
            let [x, y] = lm.points[i];
            assert!(x >= b.x - 1e-3 && x <= b.x + b.w + 1e-3, "{i}");
            assert!(y >= b.y && y <= b.y + b.h + 1e-3, "{i}");
        }
        let h = bottom - top;
        assert!((top - b.y - LEVEL1_BOX_TOP * h).abs() < 1e-3);
        assert!((b.y + b.h - bottom).abs() < 1e-3);
        lm.points[idx[3]][0] = f32::NAN;
        assert_eq!(m3.level1_box(&lm), None);
    }

    #[test]
    fn level1_weight_blends_the_face_zone_with_level_1() {
        let run = |weight: Option<f64>| {
            estimate_with(&|v| {
                // Without the nose zone, which would replace the face zone's nose points.
                v["zones"].as_object_mut().unwrap().remove("nose");
                let n = v["zones"]["face"]["indices68"].as_array().unwrap().len();
                v["zones"]["face"]["level1_weight"] = match weight {
                    Some(w) => serde_json::json!(vec![w; n]),
                    None => Value::Null,
                };
            })
        };
        let idx = M3Config::from_json(embedded("m3.json")).unwrap().zones["face"]
            .indices68
            .clone();
        let l1 = level1_of_test_face();
        let zone = run(Some(0.0));
        let half = run(Some(0.5));
        let full = run(Some(1.0));
        let none = run(None);
        assert_eq!(none.points, zone.points);
        for i in 0..N_POINTS {
            let (z, h, f) = (zone.points[i], half.points[i], full.points[i]);
            if idx.contains(&i) {
                assert_eq!(f, l1.points[i], "{i}");
                for c in 0..2 {
                    assert!((h[c] - 0.5 * (z[c] + f[c])).abs() < 1e-3, "{i}: {h:?}");
                }
            } else {
                assert_eq!((h, f), (z, z), "{i}: only the face zone's points blend");
            }
        }
    }

    /// The face box the blend tests run on.
    fn test_face() -> Rect {
        Rect::new(40.0, 20.0, 70.0, 80.0)
    }

    /// The test face's landmarks with the shipped weights and `m3.json` edited by `edit`, its
    /// label offset 0 and its shape prior off unless the edit sets them, so that points compare
    /// with level 1's and the zones' own.
    fn estimate_with(edit: &dyn Fn(&mut Value)) -> FaceLandmarks {
        estimate_in_mode(edit, false)
    }

    /// [`estimate_with`] with mirror-average mode `on` or off.
    fn estimate_in_mode(edit: &dyn Fn(&mut Value), on: bool) -> FaceLandmarks {
        let json = json_with(|v| {
            v["x_offset_iod"] = serde_json::json!(0.0);
            v.as_object_mut().unwrap().remove("shape_prior");
            edit(v);
        });
        let mut m3 = M3::from_bytes(&json, EMBEDDED_FILES).unwrap();
        m3.set_mirror_average(on);
        let mut out = FaceLandmarks::default();
        m3.estimate(&image(), &test_face(), &mut out).unwrap();
        out
    }

    /// Level 1 alone on the test face.
    fn level1_of_test_face() -> FaceLandmarks {
        let mut l1 = FaceLandmarks::default();
        M3::new()
            .unwrap()
            .level1(&image(), &test_face(), &mut l1)
            .unwrap();
        l1
    }

    #[test]
    fn x_offset_moves_every_point_along_x_by_its_share_of_the_eye_corner_distance() {
        let base = estimate_with(&|v| v["x_offset_iod"] = serde_json::json!(0.0));
        let absent = estimate_with(&|v| {
            v.as_object_mut().unwrap().remove("x_offset_iod");
        });
        assert_eq!(absent.points, base.points);
        let moved = estimate_with(&|v| v["x_offset_iod"] = serde_json::json!(0.04));
        let iod = outer_eye_distance(&base.points.map(|p| p.map(f64::from)));
        assert!(iod > 5.0, "{iod}");
        for (m, p) in moved.points.iter().zip(&base.points) {
            assert!(
                (f64::from(m[0] - p[0]) - 0.04 * iod).abs() < 1e-3,
                "{m:?} {p:?}"
            );
            assert_eq!(m[1], p[1]);
        }
        assert_eq!(moved.mouth, base.mouth);
        assert_eq!(moved.gaze_combined, base.gaze_combined);
    }

    #[test]
    fn the_shape_prior_moves_the_points_of_its_zones_and_nothing_else() {
        let off = estimate_with(&|_| {});
        let raw: Value = serde_json::from_slice(embedded("m3.json")).unwrap();
        // The shipped prior with its first `keep` zones (their matrices lead the file), all
        // weights set to `weight` (`None`: as shipped).
        let with = |keep: usize, weight: Option<f64>| {
            let mut sp = raw["shape_prior"].clone();
            let zones = sp["zones"].as_array_mut().unwrap();
            zones.truncate(keep);
            let mut floats = 0;
            for z in zones.iter_mut() {
                let n = z["indices68"].as_array().unwrap().len();
                floats += (2 * (N_POINTS - n) + 1) * 2 * n;
                if let Some(w) = weight {
                    z["weight"] = serde_json::json!(w);
                    if z.get("normal_weight").is_some() {
                        z["normal_weight"] = serde_json::json!(w);
                    }
                }
            }
            let json = json_with(|v| {
                v["x_offset_iod"] = serde_json::json!(0.0);
                v["shape_prior"] = sp.clone();
            });
            let bin = &embedded("shape_prior.bin")[..4 * floats];
            let files: Vec<(&str, &[u8])> = EMBEDDED_FILES
                .iter()
                .map(|&(n, b)| (n, if n == "shape_prior.bin" { bin } else { b }))
                .collect();
            let mut m3 = M3::from_bytes(&json, &files).unwrap();
            let mut out = FaceLandmarks::default();
            m3.estimate(&image(), &test_face(), &mut out).unwrap();
            out
        };
        let all = raw["shape_prior"]["zones"].as_array().unwrap().len();
        assert_eq!(with(all, Some(0.0)).points, off.points);
        let iod = outer_eye_distance(&off.points.map(|p| p.map(f64::from)));
        // The first zone alone (the jaw, 0–16) moves its points and no other.
        assert_eq!(
            raw["shape_prior"]["zones"][0]["indices68"],
            serde_json::json!((0..17).collect::<Vec<_>>())
        );
        let jaw = with(1, None);
        for i in 0..N_POINTS {
            let (a, b) = (jaw.points[i], off.points[i]);
            if i < 17 {
                assert_ne!(a, b, "{i}");
                // A correction, not a replacement: under a tenth of the eye-corner distance.
                assert!(
                    f64::from((a[0] - b[0]).mhypot(a[1] - b[1])) < 0.1 * iod,
                    "{i}"
                );
            } else {
                assert_eq!(a, b, "{i}");
            }
        }
        let on = with(all, None);
        let moved = (0..N_POINTS)
            .filter(|&i| on.points[i] != off.points[i])
            .count();
        assert!(moved > N_POINTS / 2, "{moved} points moved");
        assert_eq!(
            (on.mouth, on.brows, on.gaze_combined),
            (off.mouth, off.brows, off.gaze_combined)
        );
    }

    #[test]
    fn a_later_zone_replaces_an_earlier_zones_points() {
        let run = estimate_with;
        let nose: Vec<usize> = (27..36).collect();
        let shipped = run(&|_| {});
        // The nose zone at full level-1 weight gives level 1's nose whatever the face zone says.
        let l1 = level1_of_test_face();
        let all_l1 =
            run(&|v| v["zones"]["nose"]["level1_weight"] = serde_json::json!(vec![1.0; 9]));
        let face_zero = run(&|v| {
            v["zones"]["nose"]["level1_weight"] = serde_json::json!(vec![1.0; 9]);
            v["zones"]["face"]["level1_weight"] = serde_json::json!(vec![0.0; 26]);
        });
        let no_nose = run(&|v| {
            v["zones"].as_object_mut().unwrap().remove("nose");
        });
        for i in 0..N_POINTS {
            if nose.contains(&i) {
                assert_eq!(all_l1.points[i], l1.points[i], "{i}");
                assert_eq!(face_zero.points[i], l1.points[i], "{i}");
                assert_ne!(
                    no_nose.points[i], shipped.points[i],
                    "{i}: the nose zone's point"
                );
            } else {
                assert_eq!(no_nose.points[i], shipped.points[i], "{i}");
            }
        }
        // Jaw points still come from the face zone's blend.
        assert_ne!(face_zero.points[8], all_l1.points[8]);
    }

    #[test]
    fn prior_weight_blends_with_the_earlier_zones_points_from_merged_refs() {
        let run = estimate_with;
        let weights = |w: f64| serde_json::json!(vec![w; 20]);
        let shipped = run(&|_| {});
        let w = shipped_prior_weight();
        let without = run(&|v| {
            v["zones"].as_object_mut().unwrap().remove("mouth_fine");
        });
        let all_prior = run(&|v| v["zones"]["mouth_fine"]["prior_weight"] = weights(1.0));
        let alone = run(&|v| v["zones"]["mouth_fine"]["prior_weight"] = Value::Null);
        let level1_refs = run(&|v| {
            v["zones"]["mouth_fine"]["prior_weight"] = Value::Null;
            v["zones"]["mouth_fine"]["refs"] = "level1".into();
        });
        for i in 0..N_POINTS {
            if (48..68).contains(&i) {
                assert_eq!(all_prior.points[i], without.points[i], "{i}");
                assert_ne!(alone.points[i], without.points[i], "{i}");
                for c in 0..2 {
                    let want =
                        (1.0 - w) * alone.points[i][c] as f64 + w * without.points[i][c] as f64;
                    assert!((f64::from(shipped.points[i][c]) - want).abs() < 1e-3, "{i}");
                }
                // Level 1's mouth corners are not the mouth zone's: another patch.
                assert_ne!(level1_refs.points[i], alone.points[i], "{i}");
            } else {
                assert_eq!(shipped.points[i], without.points[i], "{i}");
            }
        }
        // Gestures come from the mouth zone alone.
        assert_eq!(shipped.mouth, without.mouth);
    }

    /// The shipped `mouth_fine` blend (one weight for all its points).
    fn shipped_prior_weight() -> f64 {
        let cfg = M3Config::from_json(embedded("m3.json")).unwrap();
        let w = cfg.zones["mouth_fine"].prior_weight.clone().unwrap();
        assert!(w.iter().all(|&x| x == w[0]) && w[0] > 0.0 && w[0] < 1.0);
        w[0]
    }

    #[test]
    fn bad_inputs_are_invalid_input() {
        let mut m3 = M3::new().unwrap();
        let img = image();
        let mut out = FaceLandmarks::default();
        for face in [
            Rect::new(f32::NAN, 0.0, 10.0, 10.0),
            Rect::new(0.0, 0.0, 0.0, 10.0),
            Rect::new(0.0, 0.0, 10.0, f32::INFINITY),
            Rect::new(0.0, 0.0, -5.0, 10.0),
        ] {
            assert!(matches!(
                m3.estimate(&img, &face, &mut out),
                Err(Error::InvalidInput(_))
            ));
        }
        assert!(matches!(
            m3.face_confidence(&GrayImage::new(0, 0), &Rect::new(0.0, 0.0, 5.0, 5.0)),
            Err(Error::InvalidInput(_))
        ));
    }

    #[test]
    fn broken_models_are_model_load_errors() {
        let load = |json: &[u8], files: &[(&str, &[u8])]| M3::from_bytes(json, files);
        let good = embedded("m3.json");
        let corrupt: &[u8] = b"\x08\x07not an onnx model";
        let mut files: Vec<(&str, &[u8])> = EMBEDDED_FILES.to_vec();
        assert!(load(good, &files).is_ok());
        for bad_json in [
            b"{not json".to_vec(),
            json_with(|v| v["version"] = 2.into()),
            json_with(|v| v["x_offset_iod"] = serde_json::json!(0.2)),
            json_with(|v| v["x_offset_iod"] = serde_json::json!("0.01")),
            json_with(|v| v["level1"]["indices68"] = serde_json::json!([0, 1, 2])),
            json_with(|v| {
                v["zones"]["mouth"]["gestures"] =
                    serde_json::json!(["kiss", "smile", "frown", "neutral"])
            }),
            json_with(|v| {
                v["zones"].as_object_mut().unwrap().remove("brows");
            }),
            json_with(|v| v["zones"]["eye"]["width"] = 0.into()),
            json_with(|v| v["zones"]["eye"]["mirror_ref68"] = Value::Null),
            json_with(|v| {
                v["zones"]["mouth"]["template"] = serde_json::json!([[0.5, 0.5], [0.5, 0.5]])
            }),
            // Blending with level 1: not in a thesis zone, one weight per point, 0..=1, and
            // only where level 1 has a point.
            json_with(|v| v["zones"]["mouth"]["level1_weight"] = serde_json::json!(vec![0.5; 20])),
            json_with(|v| v["zones"]["face"]["level1_weight"] = serde_json::json!(vec![0.5; 3])),
            json_with(|v| v["zones"]["face"]["level1_weight"] = serde_json::json!(vec![1.5; 26])),
            json_with(|v| v["zones"]["face"]["level1_weight"] = serde_json::json!(vec![-0.1; 26])),
            json_with(|v| {
                // Point 49 (level 1 gives none) in the face zone, blended with level 1.
                v["zones"]["face"]["indices68"][0] = 49.into();
                v["zones"]["face"]["level1_weight"] = serde_json::json!(vec![0.5; 26]);
            }),
            // Blending with the prior point: not with level1_weight, not in a thesis zone, and
            // only where a point exists before the zone runs (49 comes from the later mouth).
            json_with(|v| v["zones"]["face"]["prior_weight"] = serde_json::json!(vec![0.5; 26])),
            json_with(|v| v["zones"]["mouth"]["prior_weight"] = serde_json::json!(vec![0.5; 20])),
            json_with(|v| {
                v["zones"]["face"]["indices68"][0] = 49.into();
                v["zones"]["face"]["level1_weight"] = Value::Null;
                v["zones"]["face"]["prior_weight"] = serde_json::json!(vec![0.5; 26]);
            }),
            json_with(|v| v["zones"]["mouth_fine"]["refs"] = "everything".into()),
            json_with(|v| v["shape_prior"]["zones"][0]["weight"] = serde_json::json!(2.0)),
            json_with(|v| v["shape_prior"]["zones"][1]["indices68"][0] = 0.into()),
            json_with(|v| v["shape_prior"]["file"] = "missing.bin".into()),
            // References must exist when the zone runs: the eye reads level 1's corners; a
            // level-1 zone cannot reference a zone's point; a merged zone not a later zone's.
            json_with(|v| v["zones"]["eye"]["refs"] = "merged".into()),
            json_with(|v| v["zones"]["mouth"]["ref68"] = serde_json::json!([49, 8])),
            json_with(|v| {
                v["zones"]["mouth_fine"]["refs"] = "level1".into();
                v["zones"]["mouth_fine"]["ref68"] = serde_json::json!([51, 54]);
            }),
            json_with(|v| {
                v["zones"]["face"]["refs"] = "merged".into();
                v["zones"]["face"]["ref68"] = serde_json::json!([49, 36]);
            }),
            // Mirror averaging: not the eye (mirrored per side already), and only for a net
            // whose points include each one's mirror image (the face zone without point 16).
            json_with(|v| v["zones"]["eye"]["mirror_average"] = true.into()),
            json_with(|v| {
                v["zones"]["face"]["indices68"][16] = 49.into();
                v["zones"]["face"]["level1_weight"] = Value::Null;
                v["zones"]["face"]["mirror_average"] = true.into();
            }),
        ] {
            assert!(
                matches!(load(&bad_json, &files), Err(Error::ModelLoad(_))),
                "{}",
                String::from_utf8_lossy(&bad_json)
            );
        }
        for i in 1..files.len() {
            let saved = files[i].1;
            files[i].1 = corrupt;
            assert!(matches!(load(good, &files), Err(Error::ModelLoad(_))));
            files[i].1 = &saved[..saved.len() / 2];
            assert!(matches!(load(good, &files), Err(Error::ModelLoad(_))));
            files[i].1 = saved;
        }
        // A zone net in the level-1 slot: wrong input names.
        files[1].1 = embedded("mouth.onnx");
        assert!(matches!(load(good, &files), Err(Error::ModelLoad(_))));
        files.remove(1);
        assert!(matches!(load(good, &files), Err(Error::ModelLoad(_))));
    }
}

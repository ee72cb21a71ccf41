//! The SDK's own face detector: a tiny single-shot CNN on a downscaled luma frame.
//!
//! The network (`models/detector/detector.onnx`, trained by `models/train/detector/train.py` on
//! the faces68 training split; see `models/MODEL_CARD.md`) is fully convolutional: it takes the
//! frame shrunk by area averaging so that a face of [`DetectorConfig::min_face_px`] becomes
//! [`NET_MIN_FACE_PX`] pixels, and returns "centre heatmap" heads at the strides `detector.json`
//! lists (8, 16, 32 and 64 for the shipped network; checked at load). Each head cell holds a face
//! logit, the face centre's offset from the cell anchor (`stride · (i + 0.5)`, in cells) and
//! `log(w / stride)`, `log(h / stride)`. Decoding keeps 3×3 local maxima of the logits above the
//! score threshold and merges heads by greedy NMS.
//!
//! Boxes follow the M3 convention (`models/M3_IO.md`): the tight bounding box of the 68 landmarks,
//! in image pixels (pixel (i, j) covers `[i, i+1)×[j, j+1)`).
//!
//! The network runs in the engine (`crate::nn`, a fully convolutional network planned once per
//! input shape and reused: a video has one shape); this module shrinks the frame into its input
//! and decodes its heads.

mod resample;

use crate::image::{GrayImage, Rect};
use crate::math::Libm;
use crate::nn::FullyConvNet;
use crate::{Error, Result};
use resample::AreaResampler;
use serde::{Deserialize, Serialize};

/// The network, embedded (≈ 216 KB: float16 weight storage, float32 compute).
pub(crate) static MODEL_ONNX: &[u8] = include_bytes!("../../models/detector/detector.onnx");
/// The network's description written by the training script (strides, minimum face size).
pub(crate) static MODEL_JSON: &str = include_str!("../../models/detector/detector.json");

/// Face size (max side of the tight landmark box, network pixels) the network was trained to find
/// reliably: training samples faces from 7 px up, heads start at 6 px (`train.py`, `SIZE_RANGE`,
/// `LEVEL_RANGES`); 10 px leaves a margin. Checked against `detector.json` at load.
pub const NET_MIN_FACE_PX: f32 = 10.0;

/// The head [`FaceDetector::score_window`] reads.
const WINDOW_STRIDE: usize = 16;

/// Channels per head cell: face logit, dx, dy, log w, log h.
const HEAD_CHANNELS: usize = 5;

/// When the min-face network input's long side exceeds this, its largest faces outgrow the trained
/// sizes (training samples faces up to 150 px, `train.py` `SIZE_RANGE`), so the frame is also run
/// with its long side at [`SECOND_PASS_LONG_SIDE_PX`] (`train.py` `PYRAMID_TRIGGER`, same value).
const PYRAMID_TRIGGER_PX: f32 = 200.0;
/// Long side of the coarse second pass (`train.py` `SECOND_PASS_LONG_SIDE`).
const SECOND_PASS_LONG_SIDE_PX: f32 = 128.0;

/// Network input side of [`FaceDetector::score_window`]'s patch.
const WINDOW_INPUT: usize = 64;
/// Face size (network pixels) inside the window patch: inside the stride-16 head's trained range
/// (22–56 px, `train.py` `LEVEL_RANGES`) and away from its edges.
const WINDOW_FACE_PX: f32 = 36.0;

/// Detector settings. Serde defaults are the documented defaults below.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct DetectorConfig {
    /// Minimum face probability of a detection, 0..1. Default 0.7: the lowest threshold (0.05 steps)
    /// that keeps the detector's own false positives under 0.05 per image on the faces68
    /// validation split at the default min face (`models/train/detector/eval_peers.py`;
    /// `models/MODEL_CARD.md`). The SDK's pipelines run it lower and let M3's face check decide
    /// (`crate::track::TrackerConfig::min_detection_score`), which finds more faces at fewer false
    /// positives.
    pub score_threshold: f32,
    /// Greedy NMS: a detection overlapping a better one by more than this IoU is dropped. Default
    /// 0.4: the heads' size ranges overlap, so one face can fire on two heads with boxes differing
    /// by ~15 %, well above 0.4 IoU, while distinct faces in a crowd rarely overlap that much.
    pub nms_iou: f32,
    /// Smallest face to find (max side of the tight landmark box, image pixels). Sets the
    /// downscale: the frame is shrunk by `NET_MIN_FACE_PX / min_face_px` (never enlarged). Default
    /// 24 px: a 640×480 frame runs at 267×200 plus the 128×96 second pass, well within the
    /// detector's time budget (16 px runs at 400×300; BENCHMARKS.md, "Face detector"); faces within
    /// ~1.5× of the minimum (10–16 network pixels) are the ones the network misses most, and 19 of
    /// the 128 faces68 validation faces are 17–39 px (`models/train/RESEARCH_LOG.md`, "Face
    /// detector").
    pub min_face_px: f32,
    /// At most this many detections are returned (best first).
    pub max_faces: usize,
}

impl Default for DetectorConfig {
    fn default() -> Self {
        Self {
            score_threshold: 0.7,
            nms_iou: 0.4,
            min_face_px: 24.0,
            max_faces: 32,
        }
    }
}

impl DetectorConfig {
    /// Checks every field's range.
    ///
    /// # Errors
    /// [`Error::InvalidConfig`] naming the first field out of range.
    pub fn validate(&self) -> Result<()> {
        if !(self.score_threshold > 0.0 && self.score_threshold < 1.0) {
            return Err(Error::InvalidConfig(format!(
                "score_threshold must be in (0, 1), got {}",
                self.score_threshold
            )));
        }
        if !(self.nms_iou > 0.0 && self.nms_iou <= 1.0) {
            return Err(Error::InvalidConfig(format!(
                "nms_iou must be in (0, 1], got {}",
                self.nms_iou
            )));
        }
        if !(self.min_face_px.is_finite() && self.min_face_px >= 1.0) {
            return Err(Error::InvalidConfig(format!(
                "min_face_px must be finite and >= 1, got {}",
                self.min_face_px
            )));
        }
        if self.max_faces == 0 {
            return Err(Error::InvalidConfig("max_faces must be >= 1".into()));
        }
        Ok(())
    }

    /// Image → network scale factor (≤ 1).
    fn scale(&self) -> f32 {
        (NET_MIN_FACE_PX / self.min_face_px).min(1.0)
    }
}

/// One detected face.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Detection {
    /// Tight landmark box (M3 convention), image pixels.
    pub rect: Rect,
    /// Face probability, 0..1.
    pub score: f32,
}

/// The fields of `detector.json` the decoder depends on.
#[derive(Deserialize)]
struct ModelDesc {
    strides: Vec<usize>,
    net_min_face_px: f32,
}

/// The face detector. Not `Clone`: it owns the network's plans; create one per thread.
pub struct FaceDetector {
    config: DetectorConfig,
    /// The network (`crate::nn`), planned per input shape.
    net: FullyConvNet,
    /// Strides of the network's heads, in network pixels, in the order of its outputs.
    strides: Vec<usize>,
    /// Index of the [`WINDOW_STRIDE`] head among the outputs.
    window_head: usize,
    resampler: AreaResampler,
    candidates: Vec<Detection>,
}

impl std::fmt::Debug for FaceDetector {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FaceDetector")
            .field("config", &self.config)
            .field("plans", &self.net.plans())
            .finish_non_exhaustive()
    }
}

impl FaceDetector {
    /// Loads the embedded network with the default [`DetectorConfig`].
    ///
    /// # Errors
    /// [`Error::ModelLoad`] when the embedded model cannot be parsed (a build defect).
    pub fn new() -> Result<Self> {
        Self::with_config(DetectorConfig::default())
    }

    /// Loads the embedded network with `config`.
    ///
    /// # Errors
    /// [`Error::InvalidConfig`] for an out-of-range config; [`Error::ModelLoad`] when the embedded
    /// model or its description do not parse or disagree with this decoder.
    pub fn with_config(config: DetectorConfig) -> Result<Self> {
        Self::from_bytes(config, MODEL_JSON.as_bytes(), MODEL_ONNX)
    }

    /// A detector over other weights: `detector.json` (its description) and `detector.onnx`
    /// (a model bundle's), with `config`.
    ///
    /// # Errors
    /// As [`Self::with_config`], for the given bytes.
    pub fn from_bytes(config: DetectorConfig, json: &[u8], onnx: &[u8]) -> Result<Self> {
        config.validate()?;
        let desc: ModelDesc = serde_json::from_slice(json)
            .map_err(|e| Error::ModelLoad(format!("detector.json: {e}")))?;
        let window_head = check_desc(&desc)?;
        let net = FullyConvNet::load("detector.onnx", onnx, [WINDOW_INPUT, WINDOW_INPUT])?;
        Ok(Self {
            config,
            net,
            strides: desc.strides,
            window_head,
            resampler: AreaResampler::default(),
            candidates: Vec::new(),
        })
    }

    /// The current settings.
    pub fn config(&self) -> &DetectorConfig {
        &self.config
    }

    /// Replaces the settings (plans are kept: they depend only on the input shape).
    ///
    /// # Errors
    /// [`Error::InvalidConfig`] for an out-of-range config (the old one stays).
    pub fn set_config(&mut self, config: DetectorConfig) -> Result<()> {
        config.validate()?;
        self.config = config;
        Ok(())
    }

    /// Detects faces in `image`, best first, into `out` (cleared first). No face is an empty list.
    ///
    /// # Errors
    /// [`Error::InvalidFrame`] for an empty image; [`Error::ModelLoad`] / [`Error::Internal`] if
    /// the network cannot be planned or run for this size.
    pub fn detect(&mut self, image: &GrayImage, out: &mut Vec<Detection>) -> Result<()> {
        out.clear();
        let (w, h) = (image.width(), image.height());
        if w == 0 || h == 0 || image.data().len() != w * h {
            return Err(Error::InvalidFrame(format!(
                "empty or inconsistent image {w}x{h}"
            )));
        }
        self.candidates.clear();
        let s = self.config.scale();
        let long = w.max(h) as f32;
        self.run_pass(image, s)?;
        if long * s > PYRAMID_TRIGGER_PX {
            let s2 = SECOND_PASS_LONG_SIDE_PX / long;
            if s2 < s {
                self.run_pass(image, s2)?;
            }
        }
        nms(
            &mut self.candidates,
            self.config.nms_iou,
            self.config.max_faces,
            out,
        );
        Ok(())
    }

    /// Runs the network on `image` shrunk by `s` and appends decoded candidates.
    fn run_pass(&mut self, image: &GrayImage, s: f32) -> Result<()> {
        let (w, h) = (image.width(), image.height());
        // Network input: the shrunk frame, unpadded, so the stride grid covers exactly the frame.
        let cw = ((w as f32 * s).round() as usize).max(1);
        let ch = ((h as f32 * s).round() as usize).max(1);
        let (rx, ry) = (w as f32 / cw as f32, h as f32 / ch as f32);
        self.resampler.xs.build(w, 0.0, rx, cw);
        self.resampler.ys.build(h, 0.0, ry, ch);
        let resampler = &mut self.resampler;
        self.net
            .run(ch, cw, |buf| resampler.run(image, buf, cw, ch, cw))?;
        let logit_thr = logit(self.config.score_threshold);
        for (k, &stride) in self.strides.iter().enumerate() {
            let (data, gh, gw) = self.net.output(k, HEAD_CHANNELS)?;
            decode_head(
                data,
                gh,
                gw,
                stride as f32,
                logit_thr,
                [rx, ry],
                [cw as f32, ch as f32],
                &mut self.candidates,
            );
        }
        Ok(())
    }

    /// Face probability of one window: the network run on a small patch (64×64) around `rect`
    /// scaled so the face has the size its stride-16 head knows best, reading the heatmap at the
    /// patch centre. Cheap (one small fixed-size plan). As a tracked-window validator it is far
    /// weaker than M3 level 1's face probability, which the tracker uses: at any threshold it
    /// passes fewer faces and more shifted or background windows on the faces68 validation split
    /// (`models/train/detector/eval_window.py`; `models/MODEL_CARD.md`, "Face check"). No
    /// threshold is recommended for it.
    ///
    /// # Errors
    /// [`Error::InvalidFrame`] for an empty image, [`Error::InvalidInput`] for a non-finite or empty
    /// `rect`; network failures as in [`FaceDetector::detect`].
    pub fn score_window(&mut self, image: &GrayImage, rect: Rect) -> Result<f32> {
        let (w, h) = (image.width(), image.height());
        if w == 0 || h == 0 || image.data().len() != w * h {
            return Err(Error::InvalidFrame(format!(
                "empty or inconsistent image {w}x{h}"
            )));
        }
        if !rect.is_valid() {
            return Err(Error::InvalidInput(format!("invalid window {rect:?}")));
        }
        let side = rect.w.max(rect.h);
        let [cx, cy] = rect.center();
        let n = WINDOW_INPUT;
        let ratio = side / WINDOW_FACE_PX;
        let half = 0.5 * n as f32 * ratio;
        self.resampler.xs.build(w, cx - half, ratio, n);
        self.resampler.ys.build(h, cy - half, ratio, n);
        let resampler = &mut self.resampler;
        self.net
            .run(n, n, |buf| resampler.run(image, buf, n, n, n))?;
        // Stride-16 head: the patch centre (32, 32) lies between cells 1 and 2 on each axis.
        let (data, gh, gw) = self.net.output(self.window_head, HEAD_CHANNELS)?;
        if gh < 3 || gw < 3 {
            return Err(Error::Internal(format!("detector head of {gh}x{gw} cells")));
        }
        let mut best = f32::NEG_INFINITY;
        for y in 1..3 {
            for x in 1..3 {
                best = best.max(data[y * gw + x]);
            }
        }
        debug_assert!(gh * gw * HEAD_CHANNELS == data.len());
        Ok(sigmoid(best))
    }
}

/// Checks the network description against what this decoder supports and returns the index of
/// the [`WINDOW_STRIDE`] head.
fn check_desc(desc: &ModelDesc) -> Result<usize> {
    let bad = |why: &str| {
        Error::ModelLoad(format!(
            "detector.json (strides {:?}, net_min_face_px {}): {why}",
            desc.strides, desc.net_min_face_px
        ))
    };
    if desc.net_min_face_px != NET_MIN_FACE_PX {
        return Err(bad("net_min_face_px disagrees with the decoder"));
    }
    // Increasing powers of two from 2 to 128 also bound the head count (at most 7); an empty list
    // has no stride-16 head.
    if !desc
        .strides
        .iter()
        .all(|&s| s.is_power_of_two() && (2..=128).contains(&s))
        || !desc.strides.windows(2).all(|p| p[0] < p[1])
    {
        return Err(bad(
            "strides must be increasing powers of two from 2 to 128",
        ));
    }
    desc.strides
        .iter()
        .position(|&s| s == WINDOW_STRIDE)
        .ok_or_else(|| bad("no stride-16 head (score_window reads it)"))
}

#[inline]
fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + (-x).mexp())
}

#[inline]
fn logit(p: f32) -> f32 {
    (p / (1.0 - p)).mln()
}

/// Appends the detections of one head (`[5, gh, gw]` row-major) whose logit is at least `logit_thr`
/// and a 3×3 local maximum. `scale` maps network pixels to image pixels; `content` is the network
/// input size (centres outside it are dropped).
#[allow(clippy::too_many_arguments)]
fn decode_head(
    data: &[f32],
    gh: usize,
    gw: usize,
    stride: f32,
    logit_thr: f32,
    scale: [f32; 2],
    content: [f32; 2],
    out: &mut Vec<Detection>,
) {
    let plane = gh * gw;
    if data.len() < HEAD_CHANNELS * plane {
        return;
    }
    let heat = &data[..plane];
    for y in 0..gh {
        for x in 0..gw {
            let v = heat[y * gw + x];
            if v < logit_thr {
                continue;
            }
            let mut is_max = true;
            'nb: for ny in y.saturating_sub(1)..(y + 2).min(gh) {
                for nx in x.saturating_sub(1)..(x + 2).min(gw) {
                    if heat[ny * gw + nx] > v {
                        is_max = false;
                        break 'nb;
                    }
                }
            }
            if !is_max {
                continue;
            }
            let i = y * gw + x;
            let cx = (x as f32 + data[plane + i] + 0.5) * stride;
            let cy = (y as f32 + data[2 * plane + i] + 0.5) * stride;
            let bw = data[3 * plane + i].clamp(-10.0, 10.0).mexp() * stride;
            let bh = data[4 * plane + i].clamp(-10.0, 10.0).mexp() * stride;
            if !(cx >= 0.0 && cx < content[0] && cy >= 0.0 && cy < content[1]) {
                continue;
            }
            out.push(Detection {
                rect: Rect::new(
                    (cx - 0.5 * bw) * scale[0],
                    (cy - 0.5 * bh) * scale[1],
                    bw * scale[0],
                    bh * scale[1],
                ),
                score: sigmoid(v),
            });
        }
    }
}

/// Greedy NMS: sorts `cands` by score and moves the survivors (at most `max_out`) into `out`.
fn nms(cands: &mut [Detection], iou_thr: f32, max_out: usize, out: &mut Vec<Detection>) {
    cands.sort_unstable_by(|a, b| b.score.total_cmp(&a.score));
    for c in cands.iter() {
        if out.len() >= max_out {
            break;
        }
        if out.iter().all(|k| k.rect.iou(&c.rect) <= iou_thr) {
            out.push(*c);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn det(x: f32, y: f32, s: f32, score: f32) -> Detection {
        Detection {
            rect: Rect::new(x, y, s, s),
            score,
        }
    }

    #[test]
    fn nms_keeps_best_of_overlapping_and_distinct_faces() {
        let mut c = vec![
            det(0.0, 0.0, 10.0, 0.6),
            det(1.0, 1.0, 10.0, 0.9),
            det(50.0, 50.0, 10.0, 0.7),
            det(2.0, 0.0, 10.0, 0.8),
        ];
        let mut out = Vec::new();
        nms(&mut c, 0.4, 10, &mut out);
        assert_eq!(out.len(), 2);
        assert_eq!(out[0].score, 0.9);
        assert_eq!(out[1].score, 0.7);
        out.clear();
        nms(&mut c, 0.4, 1, &mut out);
        assert_eq!(out.len(), 1);
    }

    /// `models/train/detector/train.py` writes ReLUs in the form tract fuses (`onnx_tract.py`); a
    /// re-export without that pass still loads and gives the same boxes, so only this catches it.
    #[test]
    fn shipped_detector_has_fusable_relus() {
        let ops = crate::nn::onnx_op_types(MODEL_ONNX);
        assert!(!ops.iter().any(|o| o == "Relu"), "a Relu node");
        assert!(ops.iter().any(|o| o == "LeakyRelu"), "no LeakyRelu");
    }

    #[test]
    fn shipped_face_models_fit_the_size_budget() {
        // The budget for all face models together: 1.5 MB of weights (the ONNX files and the
        // shape prior's matrices; m3.json and detector.json are configuration).
        let m3: usize = crate::landmarks::EMBEDDED_FILES
            .iter()
            .filter(|(name, _)| name.ends_with(".onnx") || name.ends_with(".bin"))
            .map(|(_, b)| b.len())
            .sum();
        let total = m3 + MODEL_ONNX.len();
        assert!(total <= 1_500_000, "{total} bytes of face networks");
    }

    #[test]
    fn model_description_is_checked() {
        let desc = |strides: &[usize], m: f32| ModelDesc {
            strides: strides.to_vec(),
            net_min_face_px: m,
        };
        assert_eq!(
            check_desc(&desc(&[4, 8, 16, 32, 64], NET_MIN_FACE_PX)).ok(),
            Some(2)
        );
        assert_eq!(
            check_desc(&desc(&[8, 16, 32, 64], NET_MIN_FACE_PX)).ok(),
            Some(1)
        );
        for bad in [
            desc(&[8, 16, 32, 64], NET_MIN_FACE_PX + 1.0),
            desc(&[], NET_MIN_FACE_PX),
            desc(&[8, 32, 64], NET_MIN_FACE_PX),
            desc(&[16, 8], NET_MIN_FACE_PX),
            desc(&[12, 16], NET_MIN_FACE_PX),
            desc(&[1, 16], NET_MIN_FACE_PX),
            desc(&[16, 256], NET_MIN_FACE_PX),
            desc(&[2, 4, 8, 16, 32, 64, 128, 128], NET_MIN_FACE_PX),
        ] {
            assert!(
                matches!(check_desc(&bad), Err(Error::ModelLoad(_))),
                "{:?}",
                bad.strides
            );
        }
        let shipped: ModelDesc = serde_json::from_str(MODEL_JSON).unwrap();
        assert!(check_desc(&shipped).is_ok());
    }

    #[test]
    fn decode_head_maps_cells_offsets_and_sizes() {
        // 2×3 grid, stride 8; one peak at (x=1, y=1) with offsets (0.25, -0.5), w = 2 cells,
        // h = 3 cells; a weaker neighbour that is not a local maximum.
        let (gh, gw) = (2, 3);
        let plane = gh * gw;
        let mut d = vec![-10.0f32; 5 * plane];
        let i = gw + 1;
        d[i] = 2.0;
        d[i - 1] = 1.0;
        d[plane + i] = 0.25;
        d[2 * plane + i] = -0.5;
        d[3 * plane + i] = 2.0f32.mln();
        d[4 * plane + i] = 3.0f32.mln();
        let mut out = Vec::new();
        decode_head(&d, gh, gw, 8.0, 0.0, [2.0, 2.0], [24.0, 16.0], &mut out);
        assert_eq!(out.len(), 1);
        let r = out[0].rect;
        // Centre (1 + 0.25 + 0.5)·8 = 14, (1 − 0.5 + 0.5)·8 = 8 → image ×2 = (28, 16).
        let c = r.center();
        assert!(
            (c[0] - 28.0).abs() < 1e-4 && (c[1] - 16.0).abs() < 1e-4,
            "{c:?}"
        );
        assert!(
            (r.w - 32.0).abs() < 1e-3 && (r.h - 48.0).abs() < 1e-3,
            "{r:?}"
        );
        assert!((out[0].score - sigmoid(2.0)).abs() < 1e-6);
        // Above threshold: nothing.
        out.clear();
        decode_head(&d, gh, gw, 8.0, 3.0, [1.0, 1.0], [24.0, 16.0], &mut out);
        assert!(out.is_empty());
    }

    #[test]
    fn logit_inverts_sigmoid() {
        for p in [0.1f32, 0.5, 0.73] {
            assert!((sigmoid(logit(p)) - p).abs() < 1e-6);
        }
    }

    #[test]
    fn bad_input_is_a_typed_error() {
        let mut d = FaceDetector::new().unwrap();
        let mut out = vec![Detection::default()];
        assert!(matches!(
            d.detect(&GrayImage::new(0, 0), &mut out),
            Err(Error::InvalidFrame(_))
        ));
        assert!(out.is_empty());
        assert!(matches!(
            d.detect(&GrayImage::new(0, 10), &mut out),
            Err(Error::InvalidFrame(_))
        ));
        let img = GrayImage::new(32, 32);
        assert!(matches!(
            d.score_window(&img, Rect::new(0.0, 0.0, 0.0, 5.0)),
            Err(Error::InvalidInput(_))
        ));
        assert!(matches!(
            d.score_window(&img, Rect::new(f32::NAN, 0.0, 5.0, 5.0)),
            Err(Error::InvalidInput(_))
        ));
        for bad in [
            DetectorConfig {
                score_threshold: 1.0,
                ..Default::default()
            },
            DetectorConfig {
                nms_iou: 0.0,
                ..Default::default()
            },
            DetectorConfig {
                min_face_px: f32::NAN,
                ..Default::default()
            },
            DetectorConfig {
                max_faces: 0,
                ..Default::default()
            },
        ] {
            assert!(matches!(
                FaceDetector::with_config(bad),
                Err(Error::InvalidConfig(_))
            ));
            assert!(matches!(d.set_config(bad), Err(Error::InvalidConfig(_))));
        }
    }

    #[test]
    fn tiny_and_blank_images_give_no_faces() {
        let mut d = FaceDetector::new().unwrap();
        let mut out = Vec::new();
        for (w, h) in [(1, 1), (3, 2), (640, 480)] {
            d.detect(&GrayImage::new(w, h), &mut out).unwrap();
            assert!(out.is_empty(), "{w}x{h}: {out:?}");
        }
    }

    #[test]
    fn config_round_trips_through_json_with_defaults() {
        let c: DetectorConfig = serde_json::from_str(r#"{"min_face_px": 20}"#).unwrap();
        assert_eq!(c.min_face_px, 20.0);
        assert_eq!(c.score_threshold, DetectorConfig::default().score_threshold);
        let s = serde_json::to_string(&c).unwrap();
        assert_eq!(serde_json::from_str::<DetectorConfig>(&s).unwrap(), c);
    }
}

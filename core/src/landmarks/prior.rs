//! The shape prior of `models/M3_IO.md`: per zone, a linear regression that predicts the zone's
//! points from every other merged point, and a blend that moves the zone's points towards it. The
//! nets see one patch each; the regression brings in what the rest of the face says about where a
//! zone's points lie (the jaw's points along its contour above all, where a patch is ambiguous).
//!
//! The frame: the outer eye corners (points 36 and 45) of the input points go to (−1, 0) and
//! (1, 0) — translation, rotation and scale removed. Every zone reads the same input points.

use super::N_POINTS;
use super::warp::Affine;
use crate::error::{Error, Result};
use crate::math::Libm;
use serde::Deserialize;

/// The frame's reference points: the outer eye corners, and where the frame puts them.
const FRAME: [usize; 2] = [36, 45];
const FRAME_AT: [[f64; 2]; 2] = [[-1.0, 0.0], [1.0, 0.0]];

/// `shape_prior` of `m3.json`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
pub struct ShapePriorConfig {
    /// The regression matrices (float32 little-endian, zone after zone, each
    /// `(2·(68 − n) + 1) × 2n` row-major for a zone of n points).
    pub file: String,
    /// The zones, in the order their matrices are stored.
    pub zones: Vec<PriorZoneConfig>,
}

/// One zone of `shape_prior`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
pub struct PriorZoneConfig {
    /// A label for messages (informational).
    #[serde(default)]
    pub name: String,
    /// The zone's points; the regression reads every other point, ascending.
    pub indices68: Vec<usize>,
    /// Share of the move towards the regression, 0..=1; along the zone when `normal_weight` is
    /// given, the whole move otherwise.
    pub weight: f64,
    /// Share of the move across the zone (the zone's points are then an open contour in index
    /// order), 0..=1.
    #[serde(default)]
    pub normal_weight: Option<f64>,
}

fn bad(msg: String) -> Error {
    Error::ModelLoad(format!("m3.json: shape_prior: {msg}"))
}

impl ShapePriorConfig {
    /// Checks indices, weights and that zones do not overlap.
    pub(super) fn validate(&self) -> Result<()> {
        let mut taken = [false; N_POINTS];
        for z in &self.zones {
            let what = if z.name.is_empty() { "zone" } else { &z.name };
            let min = if z.normal_weight.is_some() { 2 } else { 1 };
            if z.indices68.len() < min || z.indices68.len() >= N_POINTS {
                return Err(bad(format!(
                    "{what}: {} points (a zone needs {min}..{N_POINTS})",
                    z.indices68.len()
                )));
            }
            for &i in &z.indices68 {
                if i >= N_POINTS || std::mem::replace(&mut taken[i], true) {
                    return Err(bad(format!(
                        "{what}: point {i} out of range or in two zones"
                    )));
                }
            }
            for w in std::iter::once(z.weight).chain(z.normal_weight) {
                if !(0.0..=1.0).contains(&w) {
                    return Err(bad(format!("{what}: weight {w} outside 0..=1")));
                }
            }
        }
        Ok(())
    }
}

/// A zone at run time.
#[derive(Debug, Clone)]
struct PriorZone {
    indices: Vec<usize>,
    /// The points the regression reads (all but `indices`, ascending).
    inputs: Vec<usize>,
    weight: f64,
    normal_weight: Option<f64>,
    /// `(2·inputs + 1) × 2·indices`, row-major.
    matrix: Vec<f32>,
}

/// The shape prior with its matrices and reused buffers.
#[derive(Debug, Clone)]
pub(super) struct ShapePrior {
    zones: Vec<PriorZone>,
    features: Vec<f64>,
    output: Vec<f64>,
}

impl ShapePrior {
    /// The prior of a validated `cfg` with the bytes of its `file`.
    ///
    /// # Errors
    /// [`Error::ModelLoad`] if the byte count is not the one the zones need or a number is not
    /// finite.
    pub(super) fn new(cfg: &ShapePriorConfig, bytes: &[u8]) -> Result<Self> {
        let sizes: Vec<(usize, usize)> = cfg
            .zones
            .iter()
            .map(|z| {
                (
                    2 * (N_POINTS - z.indices68.len()) + 1,
                    2 * z.indices68.len(),
                )
            })
            .collect();
        let need: usize = sizes.iter().map(|(r, c)| r * c).sum();
        if bytes.len() != 4 * need {
            return Err(bad(format!(
                "{}: {} bytes, the zones need {} float32 numbers ({} bytes)",
                cfg.file,
                bytes.len(),
                need,
                4 * need
            )));
        }
        let mut numbers = bytes
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]));
        let mut zones = Vec::with_capacity(cfg.zones.len());
        for (z, &(rows, cols)) in cfg.zones.iter().zip(&sizes) {
            let matrix: Vec<f32> = numbers.by_ref().take(rows * cols).collect();
            if matrix.iter().any(|v| !v.is_finite()) {
                return Err(bad(format!("{}: a non-finite number", cfg.file)));
            }
            let inputs = (0..N_POINTS).filter(|i| !z.indices68.contains(i)).collect();
            zones.push(PriorZone {
                indices: z.indices68.clone(),
                inputs,
                weight: z.weight,
                normal_weight: z.normal_weight,
                matrix,
            });
        }
        let rows = sizes.iter().map(|s| s.0).max().unwrap_or(0);
        let cols = sizes.iter().map(|s| s.1).max().unwrap_or(0);
        Ok(Self {
            zones,
            features: vec![0.0; rows],
            output: vec![0.0; cols],
        })
    }

    crate::kernels::cpu::with_avx2_copy! {
        /// Moves each zone's points of `pts` towards its regression. Points whose eye corners
        /// coincide (no frame) or that are not finite are left as they are.
        pub(super) fn apply / apply_avx2 (&mut self, pts: &mut [[f64; 2]; N_POINTS]) => apply_body
    }

    #[inline(always)]
    fn apply_body(&mut self, pts: &mut [[f64; 2]; N_POINTS]) {
        let input = *pts;
        if !input.iter().flatten().all(|v| v.is_finite()) {
            return;
        }
        // Image → frame and frame → image: the similarities between the eye corners and
        // (−1, 0), (1, 0); none when the corners coincide.
        let (a, b) = (input[FRAME[0]], input[FRAME[1]]);
        let (Some(to_frame), Some(to_image)) = (
            Affine::similarity(FRAME_AT[0], FRAME_AT[1], a, b),
            Affine::similarity(a, b, FRAME_AT[0], FRAME_AT[1]),
        ) else {
            return;
        };
        for z in &self.zones {
            let rows = 2 * z.inputs.len() + 1;
            let cols = 2 * z.indices.len();
            let features = &mut self.features[..rows];
            for (f, &i) in features.chunks_exact_mut(2).zip(&z.inputs) {
                f.copy_from_slice(&to_frame.apply(input[i]));
            }
            features[rows - 1] = 1.0;
            let output = &mut self.output[..cols];
            regress(features, &z.matrix, output);
            for (k, &i) in z.indices.iter().enumerate() {
                let r = to_image.apply([output[2 * k], output[2 * k + 1]]);
                let d = [r[0] - input[i][0], r[1] - input[i][1]];
                let step = match z.normal_weight {
                    None => [z.weight * d[0], z.weight * d[1]],
                    Some(wn) => {
                        let t = tangent(&input, &z.indices, k);
                        let along = d[0] * t[0] + d[1] * t[1];
                        let (a, c) = (
                            [along * t[0], along * t[1]],
                            [d[0] - along * t[0], d[1] - along * t[1]],
                        );
                        [z.weight * a[0] + wn * c[0], z.weight * a[1] + wn * c[1]]
                    }
                };
                pts[i] = [input[i][0] + step[0], input[i][1] + step[1]];
            }
        }
    }
}

/// `output = featuresᵀ · matrix` (`matrix` row-major, rows of `output.len()` values), each
/// output summed from the first feature on. Blocks of outputs with their sums held in registers
/// over the features: summing into `output` feature by feature loaded and stored it per feature,
/// which made the prior a needless part of `m3_per_face`'s time.
#[inline(always)]
fn regress(features: &[f64], matrix: &[f32], output: &mut [f64]) {
    let cols = output.len();
    let mut c0 = 0;
    // Sixteen outputs are four independent chains of four-lane sums (eight were two, and their
    // additions waited on each other's latency); the block length is known to the compiler (a
    // block cut at the end of the row made it keep the sums in memory behind masked moves).
    while cols - c0 >= 16 {
        regress_block::<16>(features, matrix, cols, c0, &mut output[c0..c0 + 16]);
        c0 += 16;
    }
    if cols - c0 >= 8 {
        regress_block::<8>(features, matrix, cols, c0, &mut output[c0..c0 + 8]);
        c0 += 8;
    }
    for c in c0..cols {
        output[c] = features
            .iter()
            .zip(matrix.chunks_exact(cols))
            .fold(0.0, |a, (&f, row)| a + f * f64::from(row[c]));
    }
}

/// Outputs `c0..c0 + N` of [`regress`] (rows of `cols` values) into `out`.
#[inline(always)]
fn regress_block<const N: usize>(
    features: &[f64],
    matrix: &[f32],
    cols: usize,
    c0: usize,
    out: &mut [f64],
) {
    let mut acc = [0f64; N];
    for (&f, row) in features.iter().zip(matrix.chunks_exact(cols)) {
        let m: &[f32; N] = row[c0..c0 + N].try_into().expect("a block");
        for (a, &m) in acc.iter_mut().zip(m) {
            *a += f * f64::from(m);
        }
    }
    out.copy_from_slice(&acc);
}

/// Unit tangent of the open contour `indices` at its `k`-th point (central difference inside,
/// one-sided at the ends, as `numpy.gradient`); zero where the neighbours coincide.
fn tangent(pts: &[[f64; 2]; N_POINTS], indices: &[usize], k: usize) -> [f64; 2] {
    let n = indices.len();
    let (a, b) = match k {
        0 => (indices[0], indices[1]),
        _ if k == n - 1 => (indices[n - 2], indices[n - 1]),
        _ => (indices[k - 1], indices[k + 1]),
    };
    let t = [pts[b][0] - pts[a][0], pts[b][1] - pts[a][1]];
    let len = t[0].mhypot(t[1]);
    if len > 0.0 {
        [t[0] / len, t[1] / len]
    } else {
        [0.0, 0.0]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A prior whose regressions ignore the other points: the intercept row alone, giving the
    /// zone's points at `targets` in the frame.
    fn constant_prior(
        zones: &[(&[usize], f64, Option<f64>)],
        targets: &[&[[f32; 2]]],
    ) -> ShapePrior {
        let cfg = ShapePriorConfig {
            file: "p.bin".into(),
            zones: zones
                .iter()
                .map(|&(idx, weight, normal_weight)| PriorZoneConfig {
                    name: String::new(),
                    indices68: idx.to_vec(),
                    weight,
                    normal_weight,
                })
                .collect(),
        };
        cfg.validate().unwrap();
        let mut bytes = Vec::new();
        for (&(idx, ..), t) in zones.iter().zip(targets) {
            let rows = 2 * (N_POINTS - idx.len()) + 1;
            let mut m = vec![0f32; rows * 2 * idx.len()];
            let last = (rows - 1) * 2 * idx.len();
            for (k, p) in t.iter().enumerate() {
                m[last + 2 * k] = p[0];
                m[last + 2 * k + 1] = p[1];
            }
            bytes.extend(m.iter().flat_map(|v| v.to_le_bytes()));
        }
        ShapePrior::new(&cfg, &bytes).unwrap()
    }

    /// A face rotated by 90° (eye corners one above the other), so the frame's rotation matters.
    fn face() -> [[f64; 2]; N_POINTS] {
        let mut pts = [[0.0; 2]; N_POINTS];
        for (i, p) in pts.iter_mut().enumerate() {
            *p = [50.0 + i as f64, 80.0 + (i * i % 17) as f64];
        }
        pts[36] = [100.0, 200.0];
        pts[45] = [100.0, 260.0];
        pts
    }

    #[test]
    fn the_frame_maps_the_eye_corners_to_minus_one_and_one() {
        // Frame (0, 1) is the eye-corner line's normal, turned +90° from 36 → 45 (image y down).
        let mut prior = constant_prior(
            &[(&[0, 1, 2], 1.0, None)],
            &[&[[-1.0, 0.0], [1.0, 0.0], [0.0, 1.0]]],
        );
        let mut pts = face();
        prior.apply(&mut pts);
        let close =
            |a: [f64; 2], b: [f64; 2]| (a[0] - b[0]).abs() < 1e-9 && (a[1] - b[1]).abs() < 1e-9;
        assert!(close(pts[0], [100.0, 200.0]), "{:?}", pts[0]);
        assert!(close(pts[1], [100.0, 260.0]), "{:?}", pts[1]);
        assert!(close(pts[2], [70.0, 230.0]), "{:?}", pts[2]);
        assert_eq!(pts[3..], face()[3..]);
    }

    #[test]
    fn weight_is_the_share_of_the_move() {
        for w in [0.0, 0.25, 1.0] {
            let mut prior = constant_prior(&[(&[5], w, None)], &[&[[0.0, 0.0]]]);
            let mut pts = face();
            prior.apply(&mut pts);
            let (a, centre) = (face()[5], [100.0, 230.0]);
            let want = [a[0] + w * (centre[0] - a[0]), a[1] + w * (centre[1] - a[1])];
            assert!((pts[5][0] - want[0]).abs() < 1e-9 && (pts[5][1] - want[1]).abs() < 1e-9);
        }
    }

    #[test]
    fn a_contour_moves_along_itself_by_weight_and_across_by_normal_weight() {
        let idx: Vec<usize> = (0..5).collect();
        let target = [[0.0f32, 0.5]; 5];
        let mut pts = face();
        for (k, &i) in idx.iter().enumerate() {
            pts[i] = [10.0 * k as f64, 3.0 * (k * k) as f64];
        }
        for (wt, wn) in [(1.0, 0.0), (0.0, 1.0), (0.5, 0.2)] {
            let mut prior = constant_prior(&[(&idx, wt, Some(wn))], &[&target]);
            let mut moved = pts;
            prior.apply(&mut moved);
            let r = [100.0 - 0.5 * 30.0, 230.0];
            for (k, &i) in idx.iter().enumerate() {
                let t = tangent(&pts, &idx, k);
                let d = [r[0] - pts[i][0], r[1] - pts[i][1]];
                let step = [moved[i][0] - pts[i][0], moved[i][1] - pts[i][1]];
                let (along, across) = (
                    |v: [f64; 2]| v[0] * t[0] + v[1] * t[1],
                    |v: [f64; 2]| -v[0] * t[1] + v[1] * t[0],
                );
                assert!((along(step) - wt * along(d)).abs() < 1e-9, "{k} {wt} {wn}");
                assert!(
                    (across(step) - wn * across(d)).abs() < 1e-9,
                    "{k} {wt} {wn}"
                );
            }
        }
    }

    /// The regression in blocks of outputs gives the bits of the product summed feature by
    /// feature, and the AVX2 copy of the prior the bits of the baseline one (on the shipped
    /// prior's matrices).
    #[test]
    fn the_regression_keeps_the_order_of_its_sums() {
        let value = |i: usize| ((i * 7919 % 1009) as f64 / 1009.0 - 0.5) * 3.0;
        for cols in [1, 7, 8, 9, 20, 34, 40] {
            let rows = 103;
            let features: Vec<f64> = (0..rows).map(value).collect();
            let matrix: Vec<f32> = (0..rows * cols).map(|i| value(i + 17) as f32).collect();
            let mut got = vec![f64::NAN; cols];
            regress(&features, &matrix, &mut got);
            let mut want = vec![0f64; cols];
            for (&f, row) in features.iter().zip(matrix.chunks_exact(cols)) {
                for (o, &m) in want.iter_mut().zip(row) {
                    *o += f * f64::from(m);
                }
            }
            assert!(
                got.iter()
                    .zip(&want)
                    .all(|(a, b)| a.to_bits() == b.to_bits()),
                "{cols} outputs"
            );
        }
        let json: serde_json::Value = serde_json::from_slice(
            crate::landmarks::embedded_file("m3.json").expect("m3.json embedded"),
        )
        .unwrap();
        let cfg: ShapePriorConfig = serde_json::from_value(json["shape_prior"].clone()).unwrap();
        let bytes = crate::landmarks::embedded_file(&cfg.file).expect("the prior's matrices");
        let mut prior = ShapePrior::new(&cfg, bytes).unwrap();
        let mut base = prior.clone();
        let (mut a, mut b) = (face(), face());
        prior.apply(&mut a);
        base.apply_body(&mut b);
        assert_ne!(a, face(), "the prior moved nothing");
        assert!(
            a.iter()
                .flatten()
                .zip(b.iter().flatten())
                .all(|(x, y)| x.to_bits() == y.to_bits()),
            "the AVX2 copy and the baseline differ"
        );
    }

    #[test]
    fn coinciding_eye_corners_leave_the_points_alone() {
        let mut prior = constant_prior(&[(&[0], 1.0, None)], &[&[[0.0, 0.0]]]);
        let mut pts = face();
        pts[45] = pts[36];
        let before = pts;
        prior.apply(&mut pts);
        assert_eq!(pts, before);
    }

    #[test]
    fn bad_configurations_and_bytes_are_model_load_errors() {
        let zone = |idx: Vec<usize>, weight, normal_weight| PriorZoneConfig {
            name: "z".into(),
            indices68: idx,
            weight,
            normal_weight,
        };
        let cfg = |zones| ShapePriorConfig {
            file: "p.bin".into(),
            zones,
        };
        for c in [
            cfg(vec![zone(vec![0, 1], 1.5, None)]),
            cfg(vec![zone(vec![0, 1], 0.5, Some(-0.1))]),
            cfg(vec![zone(vec![0], 0.5, Some(0.1))]),
            cfg(vec![zone(vec![0, 68], 0.5, None)]),
            cfg(vec![
                zone(vec![0, 1], 0.5, None),
                zone(vec![1, 2], 0.5, None),
            ]),
            cfg(vec![zone((0..68).collect(), 0.5, None)]),
            cfg(vec![zone(vec![], 0.5, None)]),
        ] {
            assert!(matches!(c.validate(), Err(Error::ModelLoad(_))), "{c:?}");
        }
        let good = cfg(vec![zone(vec![0, 1], 0.5, None)]);
        good.validate().unwrap();
        let need = (2 * 66 + 1) * 4;
        for bytes in [vec![0u8; 4 * need - 4], vec![0u8; 4 * need + 4], Vec::new()] {
            assert!(matches!(
                ShapePrior::new(&good, &bytes),
                Err(Error::ModelLoad(_))
            ));
        }
        let mut nan = vec![0u8; 4 * need];
        nan[8..12].copy_from_slice(&f32::NAN.to_le_bytes());
        assert!(matches!(
            ShapePrior::new(&good, &nan),
            Err(Error::ModelLoad(_))
        ));
        assert!(ShapePrior::new(&good, &vec![0u8; 4 * need]).is_ok());
    }
}

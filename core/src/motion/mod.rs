//! Sports motion analysis (thesis 6.2): score a trial motion against a reference and say what to
//! fix. Input: two sequences of the 15 body joints in 3D (`body-fit`, `BodyTracker`, any mocap),
//! millimetres, one pose per frame at `MotionConfig::fps`.
//!
//! 1. Retarget both onto one skeleton (the reference's median segment lengths, each bone's
//!    direction kept, the pelvis at the origin) so people of different sizes compare.
//! 2. Savitzky–Golay filtering of every trajectory, with its smoothed first derivative.
//! 3. Global alignment: joint positions (minus their means) as pure quaternions, the forward
//!    quaternionic cross-covariance over time shifts, the shift at its largest norm. Local
//!    alignment: dynamic time warping of the most energetic limb end (wrists, ankles), the
//!    reference whole and the trial open at both ends, after the shift.
//! 4. Features per joint ([`Feature`]): flexion, abduction, linear and angular velocity.
//! 5. Phases annotated on the reference carry over through the correspondences; each weighted
//!    feature's similarity in a phase is a 1-D SSIM over temporal neighbourhoods (amplitude,
//!    contrast, structure weighted 0.5 / 0.4 / 0.1); a phase scores the weighted sum of its
//!    features' similarities (its nominal score: the sum of their weights), the whole the ratio of
//!    all phases' scores to their nominal scores.

mod features;
mod filter;
#[cfg(test)]
mod tests;

use crate::body::{JOINT_NAMES, Joint, N_JOINTS, PARENTS};
use crate::error::{Error, Result};
pub use features::Feature;
use serde::Deserialize;

/// One pose: the 15 joints ([`Joint`] order), millimetres.
pub type Pose3 = [[f64; 3]; N_JOINTS];

/// Settings of a comparison.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotionConfig {
    /// Frames per second of both sequences (velocities are per second).
    pub fps: f64,
    /// Savitzky–Golay window, frames (odd, ≥ 3).
    pub sg_window: usize,
    /// Savitzky–Golay polynomial order (< window).
    pub sg_order: usize,
    /// SSIM neighbourhood, frames.
    pub ssim_window: usize,
    /// SSIM exponents of the amplitude, contrast and structure terms.
    pub ssim_weights: [f64; 3],
}

impl Default for MotionConfig {
    fn default() -> Self {
        Self {
            fps: 30.0,
            // About a third of a second at 30 fps: smooths tracking jitter, keeps a swing's shape.
            sg_window: 9,
            sg_order: 3,
            ssim_window: 9,
            ssim_weights: [0.5, 0.4, 0.1],
        }
    }
}

impl MotionConfig {
    fn validate(&self) -> Result<()> {
        let ok = self.fps.is_finite()
            && self.fps > 0.0
            && self.sg_window >= 3
            && self.sg_window % 2 == 1
            && self.sg_order < self.sg_window
            && self.ssim_window >= 2
            && self.ssim_weights.iter().all(|w| w.is_finite() && *w >= 0.0);
        if ok {
            Ok(())
        } else {
            Err(Error::InvalidConfig(format!(
                "motion config out of range: {self:?}"
            )))
        }
    }
}

/// A phase of the reference motion, frames inclusive.
#[derive(Debug, Clone, PartialEq, Deserialize)]
pub struct Phase {
    /// Its name ("back-swing").
    pub name: String,
    /// First frame of the reference.
    pub start_frame: usize,
    /// Last frame of the reference.
    pub end_frame: usize,
}

/// One weighted feature of a phase (thesis Table 6.2).
#[derive(Debug, Clone, PartialEq)]
pub struct FeatureWeight {
    /// The phase's name.
    pub phase: String,
    /// The joint.
    pub joint: Joint,
    /// The feature.
    pub feature: Feature,
    /// Its weight (> 0).
    pub weight: f64,
}

/// What defines a score: the reference's phases and the weighted features.
#[derive(Debug, Clone, PartialEq)]
pub struct Weights {
    /// Phases, in order.
    pub phases: Vec<Phase>,
    /// Weighted features.
    pub features: Vec<FeatureWeight>,
}

impl Weights {
    /// Parses the CLI's `W.json`: `{"phases": [{"name", "start_frame", "end_frame"}], "features":
    /// [{"phase", "joint", "feature", "weight"}]}`.
    ///
    /// # Errors
    /// [`Error::InvalidConfig`] naming the field: malformed JSON, an unknown joint, feature or
    /// phase, a feature the joint does not have, a weight that is not finite and positive, a
    /// repeated phase or an empty list.
    pub fn from_json(bytes: &[u8]) -> Result<Self> {
        #[derive(Deserialize)]
        struct Raw {
            phases: Vec<Phase>,
            features: Vec<RawFeature>,
        }
        #[derive(Deserialize)]
        struct RawFeature {
            phase: String,
            joint: String,
            feature: String,
            weight: f64,
        }
        let raw: Raw = serde_json::from_slice(bytes)
            .map_err(|e| Error::InvalidConfig(format!("weights JSON: {e}")))?;
        let mut features = Vec::with_capacity(raw.features.len());
        for (i, f) in raw.features.into_iter().enumerate() {
            let at = |what: String| Error::InvalidConfig(format!("weights: features[{i}]: {what}"));
            let joint = Joint::from_name(&f.joint).ok_or_else(|| {
                at(format!(
                    "unknown joint {:?} (one of {JOINT_NAMES:?})",
                    f.joint
                ))
            })?;
            let feature = Feature::from_name(&f.feature).ok_or_else(|| {
                at(format!(
                    "unknown feature {:?} (flexion, abduction, linear_velocity, angular_velocity, linear_acceleration)",
                    f.feature
                ))
            })?;
            features.push(FeatureWeight {
                phase: f.phase,
                joint,
                feature,
                weight: f.weight,
            });
        }
        let w = Self {
            phases: raw.phases,
            features,
        };
        w.validate(None)?;
        Ok(w)
    }

    /// Checks the weights, and the phases against a reference of `frames` frames when given.
    ///
    /// # Errors
    /// As [`Self::from_json`]; a phase outside the reference.
    pub fn validate(&self, frames: Option<usize>) -> Result<()> {
        let bad = |what: String| Err(Error::InvalidConfig(format!("weights: {what}")));
        if self.phases.is_empty() {
            return bad("no phases".into());
        }
        if self.features.is_empty() {
            return bad("no features".into());
        }
        for (i, p) in self.phases.iter().enumerate() {
            if self.phases[..i].iter().any(|q| q.name == p.name) {
                return bad(format!("phase {:?} given twice", p.name));
            }
            if p.start_frame > p.end_frame {
                return bad(format!(
                    "phase {:?}: start_frame {} after end_frame {}",
                    p.name, p.start_frame, p.end_frame
                ));
            }
            if let Some(n) = frames
                && p.end_frame >= n
            {
                return bad(format!(
                    "phase {:?} ends at frame {}, the reference has {n} frames",
                    p.name, p.end_frame
                ));
            }
        }
        for (i, f) in self.features.iter().enumerate() {
            if !self.phases.iter().any(|p| p.name == f.phase) {
                return bad(format!("features[{i}]: no phase named {:?}", f.phase));
            }
            if !(f.weight.is_finite() && f.weight > 0.0) {
                return bad(format!(
                    "features[{i}]: weight {} must be finite and > 0",
                    f.weight
                ));
            }
            if !f.feature.defined_for(f.joint) {
                return bad(format!(
                    "features[{i}]: {} has no {} (flexion: thorax, shoulders, elbows, hips, knees; abduction: shoulders, hips)",
                    f.joint.name(),
                    f.feature.name()
                ));
            }
        }
        Ok(())
    }
}

/// A phase's result.
#[derive(Debug, Clone, PartialEq)]
pub struct PhaseScore {
    /// The phase.
    pub name: String,
    /// Weighted sum of its features' similarities.
    pub score: f64,
    /// Its largest possible score: the sum of its features' weights.
    pub nominal: f64,
}

/// One weighted feature's result, with the series it compared (for plots).
#[derive(Debug, Clone, PartialEq)]
pub struct FeatureScore {
    /// The phase.
    pub phase: String,
    /// The joint.
    pub joint: Joint,
    /// The feature.
    pub feature: Feature,
    /// Similarity 0..1 (1-D SSIM over the phase).
    pub score: f64,
    /// Its weight.
    pub weight: f64,
    /// The reference's values over the whole reference, one per frame.
    pub reference: Vec<f64>,
    /// The trial's values carried onto the reference's frames by the alignment.
    pub trial: Vec<f64>,
}

/// The lowest-scoring phase and, in it, the lowest-scoring feature: what to fix.
#[derive(Debug, Clone, PartialEq)]
pub struct Worst {
    /// The phase.
    pub phase: String,
    /// The joint.
    pub joint: Joint,
    /// The feature.
    pub feature: Feature,
    /// Its similarity.
    pub score: f64,
}

/// The comparison of a trial with a reference.
#[derive(Debug, Clone, PartialEq)]
pub struct MotionReport {
    /// All phases' scores over their nominal scores, 0..1.
    pub overall: f64,
    /// Per phase, in the weights' order.
    pub phases: Vec<PhaseScore>,
    /// Per weighted feature, in the weights' order.
    pub features: Vec<FeatureScore>,
    /// What to fix.
    pub worst: Worst,
    /// Global alignment: trial frame = reference frame + shift.
    pub shift: i64,
    /// Dense correspondences (reference frame, trial frame), in order.
    pub path: Vec<(usize, usize)>,
}

impl MotionReport {
    /// The coach's summary: the score, the phases, and what to fix, in words.
    pub fn summary(&self) -> String {
        let mut s = format!("Overall {:.0} % of the reference.\n", 100.0 * self.overall);
        for p in &self.phases {
            s += &format!(
                "  {}: {:.2} of {:.2} ({:.0} %)\n",
                p.name,
                p.score,
                p.nominal,
                100.0 * p.score / p.nominal
            );
        }
        let w = &self.worst;
        s += &format!(
            "To fix: {} {} in {} (similarity {:.2}).\n",
            joint_words(w.joint),
            w.feature.words(),
            w.phase,
            w.score
        );
        s += &format!(
            "Aligned with a shift of {} frames; {} corresponding frames.\n",
            self.shift,
            self.path.len()
        );
        s
    }
}

/// "right elbow" for `relbow`.
pub fn joint_words(j: Joint) -> &'static str {
    [
        "pelvis",
        "thorax",
        "left shoulder",
        "left elbow",
        "left wrist",
        "right shoulder",
        "right elbow",
        "right wrist",
        "left hip",
        "left knee",
        "left ankle",
        "right hip",
        "right knee",
        "right ankle",
        "head",
    ][j.index()]
}

/// Retargets `seq` onto the bone lengths `lengths` (per joint: the length of the bone from its
/// parent), each bone's direction kept, the pelvis at the origin.
fn retarget(seq: &[Pose3], lengths: &[f64; N_JOINTS]) -> Vec<Pose3> {
    seq.iter()
        .map(|p| {
            let mut out = [[0.0; 3]; N_JOINTS];
            // PARENTS lists every parent before its children.
            for j in 1..N_JOINTS {
                let par = PARENTS[j];
                let d = sub(&p[j], &p[par]);
                let n = norm(&d);
                let dir = if n > 1e-9 {
                    scale(&d, 1.0 / n)
                } else {
                    [0.0; 3]
                };
                out[j] = add(&out[par], &scale(&dir, lengths[j]));
            }
            out
        })
        .collect()
}

/// Median bone lengths of a sequence.
fn bone_lengths(seq: &[Pose3]) -> [f64; N_JOINTS] {
    let mut out = [0.0; N_JOINTS];
    for j in 1..N_JOINTS {
        let mut v: Vec<f64> = seq
            .iter()
            .map(|p| norm(&sub(&p[j], &p[PARENTS[j]])))
            .collect();
        v.sort_by(f64::total_cmp);
        out[j] = v[v.len() / 2];
    }
    out
}

pub(crate) fn sub(a: &[f64; 3], b: &[f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
pub(crate) fn add(a: &[f64; 3], b: &[f64; 3]) -> [f64; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}
pub(crate) fn scale(a: &[f64; 3], k: f64) -> [f64; 3] {
    [a[0] * k, a[1] * k, a[2] * k]
}
pub(crate) fn dot(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
pub(crate) fn norm(a: &[f64; 3]) -> f64 {
    dot(a, a).sqrt()
}

/// The shift s (trial frame = reference frame + s) maximising the norm of the forward
/// quaternionic cross-covariance of the mean-removed joint positions (pure quaternions), over
/// shifts that leave at least half of the shorter sequence overlapping.
fn global_shift(r: &[Pose3], t: &[Pose3]) -> i64 {
    let centred = |s: &[Pose3]| -> Vec<Pose3> {
        let mut mean = [[0.0; 3]; N_JOINTS];
        for p in s {
            for j in 0..N_JOINTS {
                mean[j] = add(&mean[j], &p[j]);
            }
        }
        let k = 1.0 / s.len() as f64;
        s.iter()
            .map(|p| std::array::from_fn(|j| sub(&p[j], &scale(&mean[j], k))))
            .collect()
    };
    let (r, t) = (centred(r), centred(t));
    let (n, m) = (r.len() as i64, t.len() as i64);
    let min_overlap = (n.min(m) / 2).max(1);
    let mut best = (f64::NEG_INFINITY, 0i64);
    for s in -(n - 1)..m {
        let lo = 0.max(-s);
        let hi = n.min(m - s);
        if hi - lo < min_overlap {
            continue;
        }
        // Σ p ⊗ conj(q) for pure quaternions p, q: real part p·q, vector part −p×q… summed.
        let mut q = [0.0f64; 4];
        for i in lo..hi {
            let (a, b) = (&r[i as usize], &t[(i + s) as usize]);
            for j in 0..N_JOINTS {
                let (p, w) = (a[j], b[j]);
                q[0] += dot(&p, &w);
                q[1] -= p[1] * w[2] - p[2] * w[1];
                q[2] -= p[2] * w[0] - p[0] * w[2];
                q[3] -= p[0] * w[1] - p[1] * w[0];
            }
        }
        // The real part is the positions' covariance; a negative one is anti-correlation.
        let score = q[0].signum() * q.iter().map(|v| v * v).sum::<f64>().sqrt() / (hi - lo) as f64;
        if score > best.0 {
            best = (score, s);
        }
    }
    best.1
}

/// Dynamic time warping of `a` (reference, matched whole) against `b` (trial, open at both ends):
/// the dense path (i, j) minimising the summed distance.
fn dtw(a: &[[f64; 3]], b: &[[f64; 3]]) -> Vec<(usize, usize)> {
    let (n, m) = (a.len(), b.len());
    let mut cost = vec![f64::INFINITY; n * m];
    let d = |i: usize, j: usize| norm(&sub(&a[i], &b[j]));
    // Open beginning: the reference's first frame may match any trial frame.
    for (j, c) in cost[..m].iter_mut().enumerate() {
        *c = d(0, j);
    }
    for i in 1..n {
        for j in 0..m {
            let mut best = cost[(i - 1) * m + j];
            if j > 0 {
                best = best.min(cost[(i - 1) * m + j - 1]).min(cost[i * m + j - 1]);
            }
            cost[i * m + j] = best + d(i, j);
        }
    }
    // Open end: the cheapest cell of the last reference frame.
    let mut j = (0..m)
        .min_by(|&x, &y| cost[(n - 1) * m + x].total_cmp(&cost[(n - 1) * m + y]))
        .unwrap_or(0);
    let mut i = n - 1;
    let mut path = vec![(i, j)];
    while i > 0 {
        let up = cost[(i - 1) * m + j];
        let diag = if j > 0 {
            cost[(i - 1) * m + j - 1]
        } else {
            f64::INFINITY
        };
        let left = if j > 0 {
            cost[i * m + j - 1]
        } else {
            f64::INFINITY
        };
        if diag <= up && diag <= left {
            i -= 1;
            j -= 1;
        } else if up <= left {
            i -= 1;
        } else {
            j -= 1;
        }
        path.push((i, j));
    }
    path.reverse();
    path
}

/// The limb end (wrists, ankles) with the most kinetic energy in `v` (velocities).
fn most_energetic(v: &[Pose3]) -> usize {
    [Joint::LWrist, Joint::RWrist, Joint::LAnkle, Joint::RAnkle]
        .iter()
        .map(|j| j.index())
        .max_by(|&a, &b| {
            let e = |j: usize| v.iter().map(|p| dot(&p[j], &p[j])).sum::<f64>();
            e(a).total_cmp(&e(b))
        })
        .unwrap_or(Joint::RWrist.index())
}

fn check_sequence(name: &str, seq: &[Pose3], min: usize) -> Result<()> {
    if seq.len() < min {
        return Err(Error::InvalidInput(format!(
            "{name}: {} frames, at least {min} needed",
            seq.len()
        )));
    }
    if let Some(f) = seq
        .iter()
        .position(|p| p.iter().flatten().any(|v| !v.is_finite()))
    {
        return Err(Error::InvalidInput(format!(
            "{name}: frame {f} has a non-finite joint"
        )));
    }
    Ok(())
}

/// Compares `trial` with `reference` (see the module docs).
///
/// # Errors
/// [`Error::InvalidInput`] for a sequence shorter than the filter window or with non-finite
/// joints; [`Error::InvalidConfig`] for weights that fail [`Weights::validate`] against the
/// reference or a bad `config`.
pub fn compare(
    reference: &[Pose3],
    trial: &[Pose3],
    weights: &Weights,
    config: &MotionConfig,
) -> Result<MotionReport> {
    config.validate()?;
    check_sequence("reference", reference, config.sg_window)?;
    check_sequence("trial", trial, config.sg_window)?;
    weights.validate(Some(reference.len()))?;
    let lengths = bone_lengths(reference);
    let sg = filter::SavitzkyGolay::new(config.sg_window, config.sg_order);
    let prepare = |seq: &[Pose3]| {
        let pos = sg.smooth_poses(&retarget(seq, &lengths), 0);
        let vel = sg.smooth_poses(&pos, 1);
        (pos, vel)
    };
    let (rp, rv) = prepare(reference);
    let (tp, tv) = prepare(trial);
    let shift = global_shift(&rp, &tp);
    let limb = most_energetic(&rv);
    // Each trajectory about its own mean: a limb held differently (a bent elbow moves the wrist)
    // still times the same, and timing is what the path is for.
    let about_mean = |v: Vec<[f64; 3]>| -> Vec<[f64; 3]> {
        let k = 1.0 / v.len().max(1) as f64;
        let m = v.iter().fold([0.0; 3], |acc, p| add(&acc, p));
        v.iter().map(|p| sub(p, &scale(&m, k))).collect()
    };
    let a = about_mean(rp.iter().map(|p| p[limb]).collect());
    // The trial from the shift on, so frames before the reference's start are not matched.
    let start = shift.max(0) as usize;
    let b = about_mean(
        tp[start.min(tp.len() - 1)..]
            .iter()
            .map(|p| p[limb])
            .collect(),
    );
    let path: Vec<(usize, usize)> = dtw(&a, &b)
        .into_iter()
        .map(|(i, j)| (i, j + start))
        .collect();
    // Each reference frame's trial frames, averaged.
    let mut matched: Vec<Vec<usize>> = vec![Vec::new(); rp.len()];
    for &(i, j) in &path {
        matched[i].push(j);
    }
    let dt = 1.0 / config.fps;
    let mut features = Vec::with_capacity(weights.features.len());
    for fw in &weights.features {
        let phase = weights
            .phases
            .iter()
            .find(|p| p.name == fw.phase)
            .ok_or_else(|| Error::Internal("validated phase missing".into()))?;
        let r = features::series(fw.feature, fw.joint, &rp, &rv, &sg, dt);
        let t_all = features::series(fw.feature, fw.joint, &tp, &tv, &sg, dt);
        let t: Vec<f64> = matched
            .iter()
            .map(|js| js.iter().map(|&j| t_all[j]).sum::<f64>() / js.len().max(1) as f64)
            .collect();
        let (base, range) = features::dynamic_range(fw.feature, &r);
        // As pixel intensities from 0 to the range: measured from the reference's lowest value,
        // so the amplitude term sees an offset against the motion's own span, not against the
        // angle's distance from 0°.
        let rel = |v: &[f64]| -> Vec<f64> { v.iter().map(|x| x - base).collect() };
        let score = filter::ssim(
            &rel(&r[phase.start_frame..=phase.end_frame]),
            &rel(&t[phase.start_frame..=phase.end_frame]),
            config.ssim_window,
            range,
            config.ssim_weights,
        );
        features.push(FeatureScore {
            phase: fw.phase.clone(),
            joint: fw.joint,
            feature: fw.feature,
            score,
            weight: fw.weight,
            reference: r,
            trial: t,
        });
    }
    let mut phases = Vec::new();
    for p in &weights.phases {
        let (score, nominal) = features
            .iter()
            .filter(|f| f.phase == p.name)
            .fold((0.0, 0.0), |(s, n), f| {
                (s + f.weight * f.score, n + f.weight)
            });
        if nominal > 0.0 {
            phases.push(PhaseScore {
                name: p.name.clone(),
                score,
                nominal,
            });
        }
    }
    let total: f64 = phases.iter().map(|p| p.nominal).sum();
    let overall = phases.iter().map(|p| p.score).sum::<f64>() / total;
    let worst_phase = phases
        .iter()
        .min_by(|a, b| (a.score / a.nominal).total_cmp(&(b.score / b.nominal)))
        .ok_or_else(|| Error::Internal("no scored phase".into()))?;
    let wf = features
        .iter()
        .filter(|f| f.phase == worst_phase.name)
        .min_by(|a, b| a.score.total_cmp(&b.score))
        .ok_or_else(|| Error::Internal("no scored feature".into()))?;
    let worst = Worst {
        phase: wf.phase.clone(),
        joint: wf.joint,
        feature: wf.feature,
        score: wf.score,
    };
    Ok(MotionReport {
        overall,
        phases,
        features,
        worst,
        shift,
        path,
    })
}

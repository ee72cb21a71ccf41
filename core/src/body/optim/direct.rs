//! DIRECT-L: the locally biased DIviding RECTangles global optimiser of Gablonsky & Kelley (2001)
//! for a box-bounded, derivative-free objective.
//!
//! The box is normalised to the unit hypercube and cut into hyper-rectangles by trisection. Each
//! iteration picks the "potentially optimal" rectangles — the lower-right convex hull of (size,
//! value), at most one per size (the locally biased variant) — and trisects each along its longest
//! sides, best side first. Size is the half-length of the longest side (Gablonsky's measure).

use crate::error::{Error, Result};

/// Why DIRECT-L stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DirectTermination {
    /// The best value reached the stop value.
    StopValue,
    /// The best value improved by less than the tolerance for `patience` iterations.
    NoImprovement,
    /// The iteration cap was reached.
    MaxIterations,
    /// The evaluation budget was spent.
    MaxEvaluations,
    /// The best rectangle became smaller than the size tolerance.
    SizeConverged,
}

/// The outcome of a DIRECT-L run.
#[derive(Debug, Clone, PartialEq)]
pub struct DirectReport {
    /// Best point found (original coordinates).
    pub x: Vec<f64>,
    /// Objective at `x`.
    pub value: f64,
    /// Objective evaluations.
    pub evaluations: usize,
    /// Iterations.
    pub iterations: usize,
    /// Why it stopped.
    pub termination: DirectTermination,
}

/// DIRECT-L settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DirectL {
    /// Iteration cap.
    pub max_iterations: usize,
    /// Evaluation cap (checked between rectangle divisions).
    pub max_evaluations: usize,
    /// Stop once the best value is at or below this.
    pub stop_value: f64,
    /// An iteration "improves" when the best value drops by more than this fraction of its magnitude.
    pub improvement_tolerance: f64,
    /// Stop after this many consecutive iterations without improvement.
    pub patience: usize,
    /// Stop when the best rectangle's longest side (unit-cube units) is below this.
    pub size_tolerance: f64,
    /// Jones' ε: a rectangle must promise an improvement of at least ε·|f_min|.
    pub epsilon: f64,
}

impl Default for DirectL {
    fn default() -> Self {
        Self {
            max_iterations: 50,
            max_evaluations: 500,
            stop_value: f64::NEG_INFINITY,
            improvement_tolerance: 1e-2,
            patience: 3,
            size_tolerance: 1e-4,
            // Jones et al.'s recommended value.
            epsilon: 1e-4,
        }
    }
}

struct Rect {
    center: Vec<f64>,
    levels: Vec<u32>,
    value: f64,
}

impl Rect {
    fn min_level(&self) -> u32 {
        self.levels.iter().copied().min().unwrap_or(0)
    }
    fn size(&self) -> f64 {
        0.5 * 3f64.powi(-(self.min_level() as i32))
    }
}

impl DirectL {
    /// Minimises `f` over the box [`lower`, `upper`].
    ///
    /// # Errors
    /// [`Error::InvalidConfig`] for empty, mismatched or non-finite bounds, or `lower ≥ upper`.
    pub fn minimize<F: FnMut(&[f64]) -> f64>(
        &self,
        mut f: F,
        lower: &[f64],
        upper: &[f64],
    ) -> Result<DirectReport> {
        let n = lower.len();
        if n == 0
            || upper.len() != n
            || lower
                .iter()
                .zip(upper)
                .any(|(l, u)| !(l.is_finite() && u.is_finite() && l < u))
        {
            return Err(Error::InvalidConfig(format!(
                "DIRECT-L needs finite bounds with lower < upper, got {lower:?} / {upper:?}"
            )));
        }
        let mut x = vec![0.0; n];
        let mut eval = |u: &[f64], x: &mut Vec<f64>, count: &mut usize| {
            for i in 0..n {
                x[i] = lower[i] + u[i] * (upper[i] - lower[i]);
            }
            *count += 1;
            let v = f(x);
            // A non-finite objective is the worst possible value, never a minimum.
            if v.is_nan() { f64::INFINITY } else { v }
        };
        let mut evaluations = 0;
        let c0 = vec![0.5; n];
        let v0 = eval(&c0, &mut x, &mut evaluations);
        let mut rects = vec![Rect {
            center: c0,
            levels: vec![0; n],
            value: v0,
        }];
        let mut best = 0usize;
        let mut stale = 0;
        let mut iterations = 0;
        let termination = loop {
            if rects[best].value <= self.stop_value {
                break DirectTermination::StopValue;
            }
            if iterations >= self.max_iterations {
                break DirectTermination::MaxIterations;
            }
            if evaluations >= self.max_evaluations {
                break DirectTermination::MaxEvaluations;
            }
            if 2.0 * rects[best].size() < self.size_tolerance {
                break DirectTermination::SizeConverged;
            }
            iterations += 1;
            let before = rects[best].value;
            let selected = self.potentially_optimal(&rects);
            for r in selected {
                if evaluations >= self.max_evaluations {
                    break;
                }
                self.divide(r, &mut rects, &mut |u| eval(u, &mut x, &mut evaluations));
            }
            best = (0..rects.len())
                .min_by(|&a, &b| rects[a].value.total_cmp(&rects[b].value))
                .unwrap_or(0);
            let after = rects[best].value;
            if before - after > self.improvement_tolerance * before.abs().max(1e-12) {
                stale = 0;
            } else {
                stale += 1;
                if stale >= self.patience {
                    break DirectTermination::NoImprovement;
                }
            }
        };
        let b = &rects[best];
        Ok(DirectReport {
            x: (0..n)
                .map(|i| lower[i] + b.center[i] * (upper[i] - lower[i]))
                .collect(),
            value: b.value,
            evaluations,
            iterations,
            termination,
        })
    }

    /// Indices of the potentially optimal rectangles, one per size (the lowest value), on the lower
    /// right convex hull of (size, value) and promising an ε-improvement.
    fn potentially_optimal(&self, rects: &[Rect]) -> Vec<usize> {
        // Best rectangle per size level (larger level = smaller size).
        let mut per_level: Vec<(u32, usize)> = Vec::new();
        for (i, r) in rects.iter().enumerate() {
            let l = r.min_level();
            match per_level.iter_mut().find(|(k, _)| *k == l) {
                Some((_, j)) => {
                    if r.value < rects[*j].value {
                        *j = i;
                    }
                }
                None => per_level.push((l, i)),
            }
        }
        // Ascending size.
        per_level.sort_by_key(|e| std::cmp::Reverse(e.0));
        let pts: Vec<(f64, f64, usize)> = per_level
            .iter()
            .map(|&(_, i)| (rects[i].size(), rects[i].value, i))
            .collect();
        let fmin = pts.iter().map(|p| p.1).fold(f64::INFINITY, f64::min);
        // Start the hull at the smallest-size point holding f_min's value... the largest such size.
        let start = pts
            .iter()
            .rposition(|p| p.1 == fmin)
            .unwrap_or(pts.len() - 1);
        // Lower convex hull (monotone chain) of pts[start..], ascending size.
        let mut hull: Vec<usize> = Vec::new();
        for k in start..pts.len() {
            while hull.len() >= 2 {
                let (a, b) = (pts[hull[hull.len() - 2]], pts[hull[hull.len() - 1]]);
                let c = pts[k];
                // Drop b if it lies on or above the segment a→c.
                let cross = (b.0 - a.0) * (c.1 - a.1) - (b.1 - a.1) * (c.0 - a.0);
                if cross <= 0.0 {
                    hull.pop();
                } else {
                    break;
                }
            }
            hull.push(k);
        }
        let mut out = Vec::with_capacity(hull.len());
        for (h, &k) in hull.iter().enumerate() {
            let (d, v, idx) = pts[k];
            let ok = match hull.get(h + 1) {
                // The largest rectangle is always potentially optimal (K → ∞).
                None => true,
                Some(&next) => {
                    let (d2, v2, _) = pts[next];
                    let slope = (v2 - v) / (d2 - d);
                    v - slope * d <= fmin - self.epsilon * fmin.abs()
                }
            };
            if ok {
                out.push(idx);
            }
        }
        out
    }

    /// Trisects rectangle `r` along its longest sides, the side with the best new point first (so
    /// it ends in the largest piece).
    fn divide(&self, r: usize, rects: &mut Vec<Rect>, eval: &mut impl FnMut(&[f64]) -> f64) {
        let lmin = rects[r].min_level();
        let n = rects[r].levels.len();
        let delta = 3f64.powi(-(lmin as i32 + 1));
        let mut dims: Vec<(f64, usize, f64, f64)> = Vec::new();
        for i in 0..n {
            if rects[r].levels[i] != lmin {
                continue;
            }
            let mut c = rects[r].center.clone();
            c[i] += delta;
            let fp = eval(&c);
            c[i] -= 2.0 * delta;
            let fm = eval(&c);
            dims.push((fp.min(fm), i, fp, fm));
        }
        dims.sort_by(|a, b| a.0.total_cmp(&b.0));
        for (_, i, fp, fm) in dims {
            rects[r].levels[i] += 1;
            let lv = rects[r].levels.clone();
            for (sgn, v) in [(1.0, fp), (-1.0, fm)] {
                let mut c = rects[r].center.clone();
                c[i] += sgn * delta;
                rects.push(Rect {
                    center: c,
                    levels: lv.clone(),
                    value: v,
                });
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_the_global_minimum_of_a_multimodal_1d_function() {
        // Local minima near -1.3 and 2.9; the global one near 2.9 (f ≈ -4.1).
        let f = |x: &[f64]| (3.0 * x[0]).sin() * 2.0 + 0.3 * (x[0] - 2.0).powi(2) - 2.0;
        let rep = DirectL {
            max_iterations: 100,
            patience: 100,
            ..Default::default()
        }
        .minimize(f, &[-4.0], &[4.0])
        .unwrap();
        // Dense reference.
        let (mut bx, mut bv) = (0.0, f64::INFINITY);
        for k in 0..=80000 {
            let x = -4.0 + 8.0 * k as f64 / 80000.0;
            if f(&[x]) < bv {
                (bx, bv) = (x, f(&[x]));
            }
        }
        assert!((rep.x[0] - bx).abs() < 1e-3, "{rep:?} vs {bx}");
        assert!(rep.value - bv < 1e-5);
    }

    #[test]
    fn minimises_branin_to_a_global_minimum() {
        // Branin: three global minima of value 0.397887.
        let f = |x: &[f64]| {
            let (a, b, c) = (
                1.0,
                5.1 / (4.0 * std::f64::consts::PI.powi(2)),
                5.0 / std::f64::consts::PI,
            );
            let (r, s, t) = (6.0, 10.0, 1.0 / (8.0 * std::f64::consts::PI));
            a * (x[1] - b * x[0] * x[0] + c * x[0] - r).powi(2) + s * (1.0 - t) * x[0].cos() + s
        };
        let rep = DirectL {
            max_iterations: 200,
            max_evaluations: 2000,
            patience: 200,
            ..Default::default()
        }
        .minimize(f, &[-5.0, 0.0], &[10.0, 15.0])
        .unwrap();
        assert!((rep.value - 0.397887).abs() < 1e-3, "{rep:?}");
    }

    #[test]
    fn stops_at_the_stop_value_and_rejects_bad_bounds() {
        let rep = DirectL {
            stop_value: 0.5,
            ..Default::default()
        }
        .minimize(|x| (x[0] - 0.3).powi(2), &[-1.0], &[1.0])
        .unwrap();
        assert_eq!(rep.termination, DirectTermination::StopValue);
        assert!(
            DirectL::default()
                .minimize(|x| x[0], &[1.0], &[0.0])
                .is_err()
        );
        assert!(
            DirectL::default()
                .minimize(|x| x[0], &[f64::NAN], &[0.0])
                .is_err()
        );
    }
}

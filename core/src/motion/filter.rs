//! Savitzky–Golay smoothing and differentiation, and the 1-D SSIM similarity.

use super::Pose3;
use crate::body::N_JOINTS;
use crate::math::Libm;
use nalgebra::DMatrix;

/// Savitzky–Golay filter coefficients: a polynomial of `order` fitted by least squares to each
/// window of `window` samples, evaluated (value, first and second derivative per sample) at the
/// sample.
/// Near the ends the window shifts inwards instead of padding, so no sample is invented.
#[derive(Debug, Clone)]
pub(crate) struct SavitzkyGolay {
    window: usize,
    /// `coeffs[d][e]`: the weights of the window's samples for derivative `d` at window offset `e`.
    coeffs: [Vec<Vec<f64>>; 3],
}

impl SavitzkyGolay {
    /// `order` < `window` (`MotionConfig` checks its own: odd `window` ≥ 3).
    pub(crate) fn new(window: usize, order: usize) -> Self {
        let coeffs = [0, 1, 2].map(|d| {
            (0..window)
                .map(|e| Self::weights(window, order, e, d))
                .collect::<Vec<_>>()
        });
        Self { window, coeffs }
    }

    fn weights(window: usize, order: usize, at: usize, deriv: usize) -> Vec<f64> {
        let cols = order + 1;
        let a = DMatrix::from_fn(window, cols, |k, i| (k as f64 - at as f64).powi(i as i32));
        let ata = a.transpose() * &a;
        let Some(inv) = ata.try_inverse() else {
            return vec![0.0; window];
        };
        if deriv > order {
            return vec![0.0; window];
        }
        let pinv = inv * a.transpose();
        // The fitted polynomial in (k − at): its coefficient `deriv` times deriv! is its value,
        // slope or curvature at `at`.
        let factorial = (1..=deriv).product::<usize>() as f64;
        (0..window).map(|k| factorial * pinv[(deriv, k)]).collect()
    }

    /// The filtered series (`deriv` 0: values, 1: first, 2: second derivative per sample). Series
    /// shorter than the window are fitted whole.
    pub(crate) fn apply(&self, x: &[f64], deriv: usize) -> Vec<f64> {
        let n = x.len();
        if n < self.window {
            let order = (n.saturating_sub(1)).min(3);
            let short = SavitzkyGolay::new(n.max(1), order);
            return (0..n)
                .map(|i| {
                    short.coeffs[deriv][i]
                        .iter()
                        .zip(x)
                        .map(|(c, v)| c * v)
                        .sum()
                })
                .collect();
        }
        let h = self.window / 2;
        (0..n)
            .map(|i| {
                let start = i.saturating_sub(h).min(n - self.window);
                let e = i - start;
                self.coeffs[deriv][e]
                    .iter()
                    .zip(&x[start..start + self.window])
                    .map(|(c, v)| c * v)
                    .sum()
            })
            .collect()
    }

    /// Every joint coordinate of `seq` filtered.
    pub(crate) fn smooth_poses(&self, seq: &[Pose3], deriv: usize) -> Vec<Pose3> {
        let mut out = vec![[[0.0; 3]; N_JOINTS]; seq.len()];
        let mut x = vec![0.0; seq.len()];
        for j in 0..N_JOINTS {
            for c in 0..3 {
                for (v, p) in x.iter_mut().zip(seq) {
                    *v = p[j][c];
                }
                for (o, v) in out.iter_mut().zip(self.apply(&x, deriv)) {
                    o[j][c] = v;
                }
            }
        }
        out
    }
}

/// 1-D SSIM of `y` against `x` over sliding neighbourhoods of `window` samples (the whole series
/// when shorter), averaged: amplitude (means), contrast (spreads) and structure (correlation)
/// terms raised to `weights`, stabilised by constants from `range` (the feature's dynamic range) as
/// image SSIM does from the pixel range. Negative structure counts as 0; the result is 0..1.
pub(crate) fn ssim(x: &[f64], y: &[f64], window: usize, range: f64, weights: [f64; 3]) -> f64 {
    let n = x.len().min(y.len());
    if n == 0 {
        return 0.0;
    }
    let win = window.min(n).max(1);
    let c1 = (0.01 * range).powi(2);
    let c2 = (0.03 * range).powi(2);
    let c3 = c2 / 2.0;
    let mut total = 0.0;
    let count = n - win + 1;
    for s in 0..count {
        let (a, b) = (&x[s..s + win], &y[s..s + win]);
        let k = win as f64;
        let (ma, mb) = (a.iter().sum::<f64>() / k, b.iter().sum::<f64>() / k);
        let (mut va, mut vb, mut cov) = (0.0, 0.0, 0.0);
        for (p, q) in a.iter().zip(b) {
            va += (p - ma).powi(2);
            vb += (q - mb).powi(2);
            cov += (p - ma) * (q - mb);
        }
        let (va, vb, cov) = (va / k, vb / k, cov / k);
        let (sa, sb) = (va.sqrt(), vb.sqrt());
        let l = (2.0 * ma * mb + c1) / (ma * ma + mb * mb + c1);
        let c = (2.0 * sa * sb + c2) / (va + vb + c2);
        let st = (cov + c3) / (sa * sb + c3);
        let term = |v: f64, w: f64| v.clamp(0.0, 1.0).mpowf(w);
        total += term(l, weights[0]) * term(c, weights[1]) * term(st, weights[2]);
    }
    total / count as f64
}

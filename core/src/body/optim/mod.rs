//! Optimisers for the body fit: a finite-difference adapter that turns a residual function into a
//! [`LeastSquares`] problem for the core's Levenberg–Marquardt solver, the DIRECT-L global search
//! ([`direct`], our own: no pure-Rust crate implements it) and COBYLA ([`cobyla`], a thin wrapper
//! over the pure-Rust `cobyla` crate, a translation of NLopt's implementation).

pub mod cobyla;
pub mod direct;

use nalgebra::{SMatrix, SVector};

use crate::fit::solver::{LeastSquares, symmetrize};

/// Largest residual count a [`Residuals`] problem may have (the body objective in the full model
/// has 30 reprojection, 32 joint-limit, 17 floor, 1 contact and 48 prior residuals; in the reduced
/// model 30, 15, 15, 1 and 21; the floor calibration 9).
pub const MAX_RESIDUALS: usize = 128;

/// A vector of residuals in N parameters; ½‖r‖² is minimised.
pub trait Residuals<const N: usize> {
    /// Writes the residuals into `r` (length [`MAX_RESIDUALS`]) and returns how many there are
    /// (always the same count for a given problem).
    fn residuals(&self, x: &SVector<f64, N>, r: &mut [f64; MAX_RESIDUALS]) -> usize;
    /// Forward-difference step of parameter `i`.
    fn step(&self, i: usize) -> f64;
}

/// A [`Residuals`] problem seen as a [`LeastSquares`] one, its Jacobian by forward differences (the
/// residuals mix joint limits, floor penalties and projections, whose analytic derivatives would
/// cost more code than their speed is worth at 27 parameters).
pub struct NumericLeastSquares<'a, P>(pub &'a P);

impl<const N: usize, P: Residuals<N>> LeastSquares<N> for NumericLeastSquares<'_, P> {
    fn cost(&self, x: &SVector<f64, N>) -> f64 {
        let mut r = [0.0; MAX_RESIDUALS];
        let m = self.0.residuals(x, &mut r);
        0.5 * r[..m].iter().map(|v| v * v).sum::<f64>()
    }

    fn normal_equations(
        &self,
        x: &SVector<f64, N>,
        jtj: &mut SMatrix<f64, N, N>,
        jtr: &mut SVector<f64, N>,
    ) -> f64 {
        let mut r0 = [0.0; MAX_RESIDUALS];
        let m = self.0.residuals(x, &mut r0);
        // Column-major Jacobian kept on the stack: N columns of MAX_RESIDUALS.
        let mut jac = [[0.0; MAX_RESIDUALS]; N];
        let mut r1 = [0.0; MAX_RESIDUALS];
        let mut xp = *x;
        for (i, col) in jac.iter_mut().enumerate() {
            let h = self.0.step(i);
            xp[i] = x[i] + h;
            self.0.residuals(&xp, &mut r1);
            xp[i] = x[i];
            for k in 0..m {
                col[k] = (r1[k] - r0[k]) / h;
            }
        }
        jtj.fill(0.0);
        jtr.fill(0.0);
        // Rows are sparse (a limb's parameters move only its own joints; prior and limit rows have
        // one to three entries; inactive floor rows none): accumulate over the non-zeros only, in
        // ascending order so the upper triangle is what gets written.
        let mut nz = [0usize; N];
        for k in 0..m {
            let mut n = 0;
            for (i, col) in jac.iter().enumerate() {
                if col[k] != 0.0 {
                    nz[n] = i;
                    n += 1;
                }
            }
            let r = r0[k];
            for a in 0..n {
                let ia = nz[a];
                let ja = jac[ia][k];
                jtr[ia] += ja * r;
                for &ib in &nz[a..n] {
                    jtj[(ia, ib)] += ja * jac[ib][k];
                }
            }
        }
        symmetrize(jtj);
        0.5 * r0[..m].iter().map(|v| v * v).sum::<f64>()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::solver::LevenbergMarquardt;

    struct Rosenbrock;
    impl Residuals<2> for Rosenbrock {
        fn residuals(&self, x: &SVector<f64, 2>, r: &mut [f64; MAX_RESIDUALS]) -> usize {
            r[0] = 10.0 * (x[1] - x[0] * x[0]);
            r[1] = 1.0 - x[0];
            2
        }
        fn step(&self, _: usize) -> f64 {
            1e-7
        }
    }

    #[test]
    fn numeric_least_squares_solves_rosenbrock() {
        let mut x = SVector::<f64, 2>::new(-1.2, 1.0);
        let lm = LevenbergMarquardt {
            max_iterations: 200,
            cost_tolerance: 1e-14,
            ..Default::default()
        };
        let rep = lm.minimize(&NumericLeastSquares(&Rosenbrock), &mut x);
        assert!(
            (x[0] - 1.0).abs() < 1e-4 && (x[1] - 1.0).abs() < 1e-4,
            "{x:?} {rep:?}"
        );
    }

    /// Residuals with the sparsity of the body objective: each depends on a few parameters.
    struct Sparse;
    impl Residuals<4> for Sparse {
        fn residuals(&self, x: &SVector<f64, 4>, r: &mut [f64; MAX_RESIDUALS]) -> usize {
            r[0] = x[0] * x[1] - 1.0;
            r[1] = x[2].sin() + x[0];
            r[2] = 0.0;
            r[3] = 3.0 * x[3] - x[1] * x[1];
            r[4] = x[3];
            5
        }
        fn step(&self, _: usize) -> f64 {
            1e-6
        }
    }

    #[test]
    fn sparse_normal_equations_equal_the_dense_product() {
        let x = SVector::<f64, 4>::new(0.3, -1.2, 0.7, 2.0);
        let mut jtj = SMatrix::<f64, 4, 4>::zeros();
        let mut jtr = SVector::<f64, 4>::zeros();
        let cost = NumericLeastSquares(&Sparse).normal_equations(&x, &mut jtj, &mut jtr);
        // Analytic Jacobian of `Sparse`.
        let j = nalgebra::SMatrix::<f64, 5, 4>::from_row_slice(&[
            x[1],
            x[0],
            0.0,
            0.0, //
            1.0,
            0.0,
            x[2].cos(),
            0.0, //
            0.0,
            0.0,
            0.0,
            0.0, //
            0.0,
            -2.0 * x[1],
            0.0,
            3.0, //
            0.0,
            0.0,
            0.0,
            1.0,
        ]);
        let mut r = [0.0; MAX_RESIDUALS];
        Sparse.residuals(&x, &mut r);
        let rv = nalgebra::SVector::<f64, 5>::from_column_slice(&r[..5]);
        let want_jtj = j.transpose() * j;
        let want_jtr = j.transpose() * rv;
        assert!((jtj - want_jtj).abs().max() < 1e-4, "{jtj} vs {want_jtj}");
        assert!((jtr - want_jtr).abs().max() < 1e-4, "{jtr} vs {want_jtr}");
        assert!((cost - 0.5 * rv.norm_squared()).abs() < 1e-12);
    }
}

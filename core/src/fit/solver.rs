//! Small dense solvers for the fits: Levenberg–Marquardt for least squares and BFGS for smooth
//! objectives, both over fixed-size parameter vectors so nothing allocates per call.
//!
//! Shape follows the levenberg-marquardt crate: the problem is a trait, the solver a config value,
//! and every run returns a report with its termination reason.

use nalgebra::{SMatrix, SVector};
use serde::Serialize;

/// Why a solver stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Termination {
    /// The relative cost decrease fell below the tolerance.
    CostConverged,
    /// The step (or gradient) became negligible.
    StepConverged,
    /// The iteration budget was spent.
    MaxIterations,
    /// The damping grew without finding a better point (a minimum at numerical precision).
    NoImprovement,
    /// The cost or a derivative became non-finite.
    NonFinite,
}

impl Termination {
    /// Whether the run ended at a (local) minimum rather than by running out of budget or numbers.
    pub fn converged(self) -> bool {
        matches!(
            self,
            Self::CostConverged | Self::StepConverged | Self::NoImprovement
        )
    }
}

/// What a solver run did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SolverReport {
    /// Iterations taken.
    pub iterations: u32,
    /// Final objective value.
    pub cost: f64,
    /// Why it stopped.
    pub termination: Termination,
}

/// A least-squares problem in N parameters: it accumulates the Gauss–Newton normal equations
/// (JᵀJ, Jᵀr) and returns ½‖r‖², without materialising the Jacobian.
pub trait LeastSquares<const N: usize> {
    /// ½‖r(x)‖².
    fn cost(&self, x: &SVector<f64, N>) -> f64;
    /// ½‖r(x)‖², and JᵀJ and Jᵀr written into `jtj` and `jtr` (overwritten).
    fn normal_equations(
        &self,
        x: &SVector<f64, N>,
        jtj: &mut SMatrix<f64, N, N>,
        jtr: &mut SVector<f64, N>,
    ) -> f64;
}

/// Adds one residual's row `j` (already scaled by √weight) and residual `r` (likewise) to the
/// upper triangle of JᵀJ and to Jᵀr. Call [`symmetrize`] once after the last row: half the work
/// of a full outer product, which dominates the fits' cost.
#[inline]
pub fn accumulate_row<const N: usize>(
    jtj: &mut SMatrix<f64, N, N>,
    jtr: &mut SVector<f64, N>,
    j: &SVector<f64, N>,
    r: f64,
) {
    for a in 0..N {
        let ja = j[a];
        if ja == 0.0 {
            continue;
        }
        jtr[a] += ja * r;
        for b in a..N {
            jtj[(a, b)] += ja * j[b];
        }
    }
}

/// Copies the upper triangle of `m` onto its lower triangle.
#[inline]
pub fn symmetrize<const N: usize>(m: &mut SMatrix<f64, N, N>) {
    for a in 0..N {
        for b in 0..a {
            m[(a, b)] = m[(b, a)];
        }
    }
}

/// Levenberg–Marquardt settings.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct LevenbergMarquardt {
    /// Iteration cap.
    pub max_iterations: u32,
    /// Stop when the relative cost decrease of an accepted step is below this.
    pub cost_tolerance: f64,
    /// Stop when the step's norm is below this (parameter units).
    pub step_tolerance: f64,
    /// Initial damping relative to the largest diagonal entry of JᵀJ.
    pub initial_lambda: f64,
}

impl Default for LevenbergMarquardt {
    fn default() -> Self {
        Self {
            max_iterations: 30,
            // Relative decrease of ½‖r‖² per accepted step: far below what pixel-noise landmarks
            // can resolve.
            cost_tolerance: 1e-5,
            step_tolerance: 1e-9,
            initial_lambda: 1e-3,
        }
    }
}

impl LevenbergMarquardt {
    /// Minimises the problem from `x` (updated in place).
    pub fn minimize<const N: usize, P: LeastSquares<N>>(
        &self,
        problem: &P,
        x: &mut SVector<f64, N>,
    ) -> SolverReport {
        let mut jtj = SMatrix::<f64, N, N>::zeros();
        let mut jtr = SVector::<f64, N>::zeros();
        let mut cost = problem.normal_equations(x, &mut jtj, &mut jtr);
        if !cost.is_finite() {
            return SolverReport {
                iterations: 0,
                cost,
                termination: Termination::NonFinite,
            };
        }
        let max_diag = (0..N).map(|i| jtj[(i, i)]).fold(0.0, f64::max).max(1e-12);
        // Dimensionless: the damping below is Marquardt's, λ·diag(JᵀJ).
        let mut lambda = self.initial_lambda;
        let mut nu = 2.0;
        for it in 1..=self.max_iterations {
            if cost == 0.0 {
                return SolverReport {
                    iterations: it - 1,
                    cost,
                    termination: Termination::CostConverged,
                };
            }
            let mut a = jtj;
            for i in 0..N {
                // Marquardt's scaling: damp each parameter by its own curvature.
                a[(i, i)] += lambda * jtj[(i, i)].max(1e-9 * max_diag);
            }
            let Some(chol) = a.cholesky() else {
                lambda *= nu;
                nu *= 2.0;
                continue;
            };
            let step = -chol.solve(&jtr);
            let candidate = *x + step;
            let new_cost = problem.cost(&candidate);
            let predicted = -(step.dot(&jtr) + 0.5 * step.dot(&(jtj * step)));
            let rho = if predicted > 0.0 {
                (cost - new_cost) / predicted
            } else {
                -1.0
            };
            if new_cost.is_finite() && rho > 0.0 {
                *x = candidate;
                let rel = (cost - new_cost) / cost.max(1e-300);
                cost = problem.normal_equations(x, &mut jtj, &mut jtr);
                lambda *= (1.0 - (2.0 * rho - 1.0).powi(3)).max(1.0 / 3.0);
                nu = 2.0;
                if rel < self.cost_tolerance {
                    return SolverReport {
                        iterations: it,
                        cost,
                        termination: Termination::CostConverged,
                    };
                }
                if step.norm() < self.step_tolerance {
                    return SolverReport {
                        iterations: it,
                        cost,
                        termination: Termination::StepConverged,
                    };
                }
            } else {
                lambda *= nu;
                nu *= 2.0;
                if lambda > 1e16 {
                    return SolverReport {
                        iterations: it,
                        cost,
                        termination: Termination::NoImprovement,
                    };
                }
            }
        }
        SolverReport {
            iterations: self.max_iterations,
            cost,
            termination: Termination::MaxIterations,
        }
    }
}

/// A smooth objective in N parameters with its gradient.
pub trait Objective<const N: usize> {
    /// f(x).
    fn value(&self, x: &SVector<f64, N>) -> f64;
    /// f(x), and ∇f(x) written into `grad`.
    fn value_and_gradient(&self, x: &SVector<f64, N>, grad: &mut SVector<f64, N>) -> f64;
    /// A positive-definite approximation of ∇²f(x) (e.g. Gauss–Newton) written into `hess`, used
    /// to seed BFGS's inverse Hessian so its first steps are nearly Newton steps. `false` (the
    /// default) when the problem offers none.
    fn hessian_approximation(&self, _x: &SVector<f64, N>, _hess: &mut SMatrix<f64, N, N>) -> bool {
        false
    }
}

/// BFGS settings (inverse-Hessian update, backtracking Armijo line search, box bounds by projection).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Bfgs {
    /// Iteration cap.
    pub max_iterations: u32,
    /// Stop when ‖∇f‖∞ falls below this.
    pub gradient_tolerance: f64,
    /// Stop when the relative decrease of f is below this.
    pub cost_tolerance: f64,
    /// Parameters are kept inside [-bound, bound].
    pub bound: f64,
}

impl Default for Bfgs {
    fn default() -> Self {
        Self {
            max_iterations: 30,
            gradient_tolerance: 1e-6,
            cost_tolerance: 1e-5,
            bound: 3.0,
        }
    }
}

impl Bfgs {
    /// Minimises from `x` (updated in place). `h0` scales the initial inverse Hessian (≈ 1 / typical
    /// curvature), which saves the first few line-search halvings.
    pub fn minimize<const N: usize, P: Objective<N>>(
        &self,
        problem: &P,
        x: &mut SVector<f64, N>,
        h0: f64,
    ) -> SolverReport {
        let clamp = |v: &mut SVector<f64, N>| {
            for c in v.iter_mut() {
                *c = c.clamp(-self.bound, self.bound);
            }
        };
        clamp(x);
        let mut g = SVector::<f64, N>::zeros();
        let mut f = problem.value_and_gradient(x, &mut g);
        if !f.is_finite() {
            return SolverReport {
                iterations: 0,
                cost: f,
                termination: Termination::NonFinite,
            };
        }
        let mut h = SMatrix::<f64, N, N>::identity() * h0;
        let mut approx = SMatrix::<f64, N, N>::zeros();
        if problem.hessian_approximation(x, &mut approx)
            && let Some(inv) = approx.cholesky().map(|c| c.inverse())
        {
            h = inv;
        }
        let h_start = h;
        let mut g_new = SVector::<f64, N>::zeros();
        for it in 1..=self.max_iterations {
            if g.amax() < self.gradient_tolerance {
                return SolverReport {
                    iterations: it - 1,
                    cost: f,
                    termination: Termination::StepConverged,
                };
            }
            let mut dir = -(h * g);
            if dir.dot(&g) >= 0.0 {
                // Lost positive definiteness (bounds clipping): restart with steepest descent.
                h = h_start;
                dir = -(h * g);
                if dir.dot(&g) >= 0.0 {
                    h = SMatrix::identity() * h0;
                    dir = -(g * h0);
                }
            }
            let mut alpha = 1.0;
            let mut accepted = None;
            for trial in 0..20 {
                let mut cand = *x + dir * alpha;
                clamp(&mut cand);
                // The full step is usually accepted (the seeded Hessian makes it nearly Newton's),
                // so evaluate the gradient with it and save a second pass.
                let fc = if trial == 0 {
                    problem.value_and_gradient(&cand, &mut g_new)
                } else {
                    problem.value(&cand)
                };
                if fc.is_finite() && fc <= f + 1e-4 * g.dot(&(cand - *x)) {
                    accepted = Some((cand, fc, trial == 0));
                    break;
                }
                alpha *= 0.5;
            }
            let Some((cand, fc, have_gradient)) = accepted else {
                return SolverReport {
                    iterations: it,
                    cost: f,
                    termination: Termination::NoImprovement,
                };
            };
            let s = cand - *x;
            let f_new = if have_gradient {
                fc
            } else {
                problem.value_and_gradient(&cand, &mut g_new)
            };
            let y = g_new - g;
            let sy = s.dot(&y);
            let rel = (f - f_new) / f.abs().max(1e-300);
            *x = cand;
            f = f_new;
            if sy > 1e-12 {
                let rho = 1.0 / sy;
                let i = SMatrix::<f64, N, N>::identity();
                let a = i - s * y.transpose() * rho;
                h = a * h * a.transpose() + s * s.transpose() * rho;
            }
            g = g_new;
            if rel < self.cost_tolerance || s.amax() < 1e-10 {
                return SolverReport {
                    iterations: it,
                    cost: f,
                    termination: Termination::CostConverged,
                };
            }
        }
        SolverReport {
            iterations: self.max_iterations,
            cost: f,
            termination: Termination::MaxIterations,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector2;

    /// Rosenbrock as least squares: r = (10 (y - x²), 1 - x).
    struct Rosen;
    impl LeastSquares<2> for Rosen {
        fn cost(&self, p: &Vector2<f64>) -> f64 {
            let r = [10.0 * (p.y - p.x * p.x), 1.0 - p.x];
            0.5 * (r[0] * r[0] + r[1] * r[1])
        }
        fn normal_equations(
            &self,
            p: &Vector2<f64>,
            jtj: &mut SMatrix<f64, 2, 2>,
            jtr: &mut Vector2<f64>,
        ) -> f64 {
            let r = Vector2::new(10.0 * (p.y - p.x * p.x), 1.0 - p.x);
            let j = SMatrix::<f64, 2, 2>::new(-20.0 * p.x, 10.0, -1.0, 0.0);
            *jtj = j.transpose() * j;
            *jtr = j.transpose() * r;
            0.5 * r.norm_squared()
        }
    }
    impl Objective<2> for Rosen {
        fn value(&self, p: &Vector2<f64>) -> f64 {
            2.0 * LeastSquares::cost(self, p)
        }
        fn value_and_gradient(&self, p: &Vector2<f64>, g: &mut Vector2<f64>) -> f64 {
            let mut jtj = SMatrix::zeros();
            let mut jtr = Vector2::zeros();
            let c = self.normal_equations(p, &mut jtj, &mut jtr);
            *g = jtr * 2.0;
            2.0 * c
        }
    }

    #[test]
    fn lm_solves_rosenbrock() {
        let mut x = Vector2::new(-1.2, 1.0);
        let rep = LevenbergMarquardt {
            max_iterations: 200,
            ..Default::default()
        }
        .minimize(&Rosen, &mut x);
        assert!((x - Vector2::new(1.0, 1.0)).norm() < 1e-5, "{x} {rep:?}");
        assert!(rep.termination.converged());
    }

    #[test]
    fn bfgs_solves_rosenbrock() {
        let mut x = Vector2::new(-1.2, 1.0);
        let rep = Bfgs {
            max_iterations: 500,
            cost_tolerance: 1e-14,
            gradient_tolerance: 1e-9,
            bound: 10.0,
        }
        .minimize(&Rosen, &mut x, 1e-3);
        assert!((x - Vector2::new(1.0, 1.0)).norm() < 1e-4, "{x} {rep:?}");
    }

    #[test]
    fn bfgs_respects_bounds() {
        // min (x - 5)² with bound 3 → x = 3.
        struct Q;
        impl Objective<1> for Q {
            fn value(&self, x: &SVector<f64, 1>) -> f64 {
                (x[0] - 5.0).powi(2)
            }
            fn value_and_gradient(&self, x: &SVector<f64, 1>, g: &mut SVector<f64, 1>) -> f64 {
                g[0] = 2.0 * (x[0] - 5.0);
                self.value(x)
            }
        }
        let mut x = SVector::<f64, 1>::new(0.0);
        Bfgs::default().minimize(&Q, &mut x, 0.5);
        assert!((x[0] - 3.0).abs() < 1e-9);
    }
}

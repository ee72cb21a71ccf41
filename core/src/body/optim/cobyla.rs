//! COBYLA (Powell's Constrained Optimisation BY Linear Approximations) for box-bounded,
//! derivative-free objectives, through the pure-Rust `cobyla` crate (a translation of NLopt 2.7.1;
//! it builds for the mobile targets). This wrapper fixes the settings the body fit needs and maps
//! the crate's status onto a typed report.

use crate::error::{Error, Result};

/// Why COBYLA stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CobylaTermination {
    /// The objective reached the stop value.
    StopValue,
    /// The relative change of the objective fell below the tolerance.
    CostConverged,
    /// The trust region shrank to the parameter tolerance.
    StepConverged,
    /// The evaluation budget was spent.
    MaxEvaluations,
    /// Rounding errors limited progress (the point returned is still the best seen).
    RoundoffLimited,
}

/// The outcome of a COBYLA run.
#[derive(Debug, Clone, PartialEq)]
pub struct CobylaReport {
    /// Best point found.
    pub x: Vec<f64>,
    /// Objective at `x`.
    pub value: f64,
    /// Why it stopped.
    pub termination: CobylaTermination,
}

/// COBYLA settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cobyla {
    /// Evaluation cap.
    pub max_evaluations: usize,
    /// Initial trust-region radius, as a fraction of each parameter's box width.
    pub initial_step: f64,
    /// Stop when the objective changes by less than this fraction.
    pub cost_tolerance: f64,
    /// Stop when the parameters change by less than this fraction of the box width.
    pub step_tolerance: f64,
    /// Stop once the objective is at or below this.
    pub stop_value: f64,
}

impl Default for Cobyla {
    fn default() -> Self {
        Self {
            max_evaluations: 100,
            initial_step: 0.25,
            cost_tolerance: 1e-2,
            step_tolerance: 1e-3,
            stop_value: f64::NEG_INFINITY,
        }
    }
}

impl Cobyla {
    /// Minimises `f` from `x0` inside the box [`lower`, `upper`].
    ///
    /// # Errors
    /// [`Error::InvalidConfig`] for mismatched or empty bounds or a start outside them;
    /// [`Error::Internal`] when the crate reports a failure (invalid arguments, forced stop).
    pub fn minimize<F: Fn(&[f64]) -> f64>(
        &self,
        f: F,
        x0: &[f64],
        lower: &[f64],
        upper: &[f64],
    ) -> Result<CobylaReport> {
        let n = x0.len();
        if n == 0
            || lower.len() != n
            || upper.len() != n
            || (0..n).any(|i| {
                !(lower[i].is_finite()
                    && upper[i].is_finite()
                    && lower[i] < upper[i]
                    && (lower[i]..=upper[i]).contains(&x0[i]))
            })
        {
            return Err(Error::InvalidConfig(format!(
                "COBYLA needs finite bounds around the start, got x0 {x0:?} in {lower:?} / {upper:?}"
            )));
        }
        let bounds: Vec<(f64, f64)> = lower.iter().copied().zip(upper.iter().copied()).collect();
        let steps: Vec<f64> = (0..n)
            .map(|i| self.initial_step * (upper[i] - lower[i]))
            .collect();
        let tols = cobyla::StopTols {
            ftol_rel: self.cost_tolerance,
            xtol_abs: (0..n)
                .map(|i| self.step_tolerance * (upper[i] - lower[i]))
                .collect(),
            ..Default::default()
        };
        let obj = |x: &[f64], _: &mut ()| {
            let v = f(x);
            if v.is_finite() { v } else { f64::MAX }
        };
        let cons: Vec<&dyn cobyla::Func<()>> = Vec::new();
        let run = cobyla::minimize(
            obj,
            x0,
            &bounds,
            &cons,
            (),
            self.max_evaluations,
            cobyla::RhoBeg::Set(steps),
            Some(tols),
        );
        let (termination, x, value) = match run {
            Ok((s, x, v)) => (
                match s {
                    cobyla::SuccessStatus::StopValReached => CobylaTermination::StopValue,
                    cobyla::SuccessStatus::FtolReached | cobyla::SuccessStatus::Success => {
                        CobylaTermination::CostConverged
                    }
                    cobyla::SuccessStatus::XtolReached => CobylaTermination::StepConverged,
                    cobyla::SuccessStatus::MaxEvalReached
                    | cobyla::SuccessStatus::MaxTimeReached => CobylaTermination::MaxEvaluations,
                },
                x,
                v,
            ),
            Err((cobyla::FailStatus::RoundoffLimited, x, v)) => {
                (CobylaTermination::RoundoffLimited, x, v)
            }
            Err((s, _, _)) => {
                return Err(Error::Internal(format!("COBYLA failed: {s:?}")));
            }
        };
        // The crate has no stop value; apply it afterwards so the report says so.
        let termination = if value <= self.stop_value {
            CobylaTermination::StopValue
        } else {
            termination
        };
        Ok(CobylaReport {
            x,
            value,
            termination,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn minimises_a_shifted_quadratic_and_respects_bounds() {
        let f =
            |x: &[f64]| (x[0] - 0.3).powi(2) + 10.0 * (x[1] + 0.2).powi(2) + (x[2] - 2.0).powi(2);
        let c = Cobyla {
            max_evaluations: 500,
            cost_tolerance: 1e-10,
            step_tolerance: 1e-7,
            ..Default::default()
        };
        let rep = c
            .minimize(f, &[0.0, 0.0, 0.0], &[-1.0, -1.0, -1.0], &[1.0, 1.0, 1.0])
            .unwrap();
        assert!((rep.x[0] - 0.3).abs() < 1e-3, "{rep:?}");
        assert!((rep.x[1] + 0.2).abs() < 1e-3, "{rep:?}");
        // x2's optimum (2) is outside the box: it must stop at the bound.
        assert!((rep.x[2] - 1.0).abs() < 1e-3, "{rep:?}");
    }

    #[test]
    fn rejects_a_start_outside_the_box() {
        assert!(
            Cobyla::default()
                .minimize(|x| x[0], &[2.0], &[-1.0], &[1.0])
                .is_err()
        );
    }
}

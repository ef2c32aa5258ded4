//! The `[solver]` section: the planning method and the solver's options.

use super::error::{ConfigError, FileCheck};
use super::raw::RawSolver;
use crate::method::Method;
use vic_core::model::{Actuator, ArmModel};
use vic_core::solver::IlqgOptions;
use vic_core::solver::sooc_newton::{Indefinite, SoocOptions};

/// The `[solver]` section: the method and the solver's options (every key optional).
#[derive(Debug, Clone, PartialEq)]
pub struct SolverSection {
    /// The planning method.
    pub method: Method,
    pub options: IlqgOptions,
    /// SOOC: fractions of the noise solved in turn, ending at 1 (default [1.0]: the stagewise
    /// Newton solver converges from the deterministic plan directly; intermediate stages only
    /// add iterations on the type-2 arm: 22 Newton steps at [1.0], 44 over [0.1, 0.3, 1.0], same
    /// optimum).
    pub noise_continuation: Vec<f64>,
    /// SOOC: what a backward pass does with a stage whose Newton model is indefinite (default
    /// `regularize`: raise μ for every stage; `saddle_free`: convexify that stage alone).
    pub indefinite: Indefinite,
    /// SOOC: the Newton model leaves the flow's third derivatives out while an accepted step
    /// gains more than this fraction of the expected cost (`None`, the default: always in; see
    /// [`vic_core::solver::sooc_newton::SoocOptions::third_derivatives_below`]).
    pub third_derivatives_below: Option<f64>,
    /// SOOC: every other Newton step keeps the previous point's third derivatives (default
    /// false; see [`vic_core::solver::sooc_newton::SoocOptions::keep_third_derivatives`]).
    pub keep_third_derivatives: bool,
}

impl Default for SolverSection {
    fn default() -> Self {
        let raw = RawSolver::default();
        SolverSection {
            method: raw.method,
            options: raw.options(),
            noise_continuation: raw.noise_continuation,
            indefinite: raw.indefinite,
            third_derivatives_below: raw.third_derivatives_below,
            keep_third_derivatives: raw.keep_third_derivatives,
        }
    }
}

impl SolverSection {
    /// SOOC's options from this section: the iteration limit (per noise stage), the treatment of
    /// indefinite stages and when the flow's third derivatives join the Newton model; the rest
    /// SOOC's defaults.
    pub fn sooc_options(&self) -> SoocOptions {
        SoocOptions {
            max_iterations: self.options.max_iterations,
            indefinite: self.indefinite,
            third_derivatives_below: self
                .third_derivatives_below
                .unwrap_or(SoocOptions::default().third_derivatives_below),
            keep_third_derivatives: self.keep_third_derivatives,
            ..SoocOptions::default()
        }
    }
}

impl RawSolver {
    fn options(&self) -> IlqgOptions {
        IlqgOptions {
            max_iterations: self.max_iterations,
            tolerance: self.tolerance,
            gradient_tolerance: self.gradient_tolerance,
            mu_init: self.mu_init,
            mu_min: self.mu_min,
            mu_max: self.mu_max,
            stochastic: self.stochastic,
            damp_short_steps: self.damp_short_steps,
            shrink_below_step: IlqgOptions::default().shrink_below_step,
            // Set from the actuator by `held_first` once the model is known.
            held_first: Vec::new(),
        }
    }

    /// Checks the options: the continuation must end at the full noise, the iteration limit and
    /// the regularisation must leave the solver room to work.
    pub(super) fn resolve(self, check: &FileCheck) -> Result<SolverSection, ConfigError> {
        let fractions = &self.noise_continuation;
        if fractions.last() != Some(&1.0) || fractions.iter().any(|f| !(f.is_finite() && *f > 0.0))
        {
            return Err(check.invalid(
                "solver",
                "noise_continuation",
                format!("must be positive fractions ending with 1.0, got {fractions:?}"),
            ));
        }
        if self.max_iterations == 0 {
            return Err(check.invalid("solver", "max_iterations", "must be at least 1"));
        }
        check.non_negative(self.tolerance, "solver", "tolerance")?;
        check.non_negative(self.mu_init, "solver", "mu_init")?;
        check.positive(self.mu_max, "solver", "mu_max")?;
        // `inf`: always the exact model (the default).
        if let Some(below) = self.third_derivatives_below
            && (below.is_nan() || below <= 0.0)
        {
            return Err(check.invalid(
                "solver",
                "third_derivatives_below",
                format!("must be a positive number or inf, got {below}"),
            ));
        }
        Ok(SolverSection {
            method: self.method,
            options: self.options(),
            noise_continuation: self.noise_continuation,
            indefinite: self.indefinite,
            third_derivatives_below: self.third_derivatives_below,
            keep_third_derivatives: self.keep_third_derivatives,
        })
    }
}

/// The controls a deterministic solve holds at their lower limits first
/// ([`IlqgOptions::held_first`]): an impedance's stiffnesses, which act only through the
/// deviation from the reference. Not a VSA's: its springs carry the motor torque to the link, so
/// at zero stiffness nothing moves it.
pub(super) fn held_first(model: &ArmModel, hold_stiffness_first: bool) -> Vec<usize> {
    match model.actuator {
        Actuator::Impedance { .. } if hold_stiffness_first => (model.dof()..model.nu()).collect(),
        _ => Vec::new(),
    }
}

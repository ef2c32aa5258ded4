//! The `[solver]` section: the planning method and the solver's options.

use super::error::{ConfigError, FileCheck};
use super::raw::RawSolver;
use crate::method::Method;
use vic_core::model::{Actuator, ArmModel};
use vic_core::solver::IlqgOptions;
use vic_core::solver::sooc_newton::SoocOptions;

/// The `[solver]` section: the method and the solver's options (every key optional, its
/// default the solver's own).
#[derive(Debug, Clone, PartialEq)]
pub struct SolverSection {
    /// The planning method.
    pub method: Method,
    /// ILQG's options; their iteration limit is SOOC's too ([`SolverSection::sooc_options`]).
    pub options: IlqgOptions,
    /// SOOC: fractions of the noise solved in turn, ending at 1. Not a key of the file: the
    /// stagewise Newton solver converges from the deterministic plan at the full noise directly
    /// on every scenario, so the default `[1.0]` is the only value in use.
    pub noise_continuation: Vec<f64>,
    /// SOOC's options but the iteration limit: what a backward pass does with an indefinite
    /// stage ([`SoocOptions::indefinite`]) and when the flow's third derivatives join the Newton
    /// model ([`SoocOptions::third_derivatives_below`],
    /// [`SoocOptions::keep_third_derivatives`]).
    pub sooc: SoocOptions,
}

impl Default for SolverSection {
    fn default() -> Self {
        RawSolver::default().section()
    }
}

impl SolverSection {
    /// SOOC's options from this section: [`SolverSection::sooc`] with the iteration limit (per
    /// noise stage) of [`SolverSection::options`].
    pub fn sooc_options(&self) -> SoocOptions {
        SoocOptions {
            max_iterations: self.options.max_iterations,
            ..self.sooc.clone()
        }
    }
}

impl RawSolver {
    /// The section: each key given replaces the solver's default.
    fn section(&self) -> SolverSection {
        let d = IlqgOptions::default();
        let options = IlqgOptions {
            max_iterations: self.max_iterations.unwrap_or(d.max_iterations),
            tolerance: self.tolerance.unwrap_or(d.tolerance),
            gradient_tolerance: self.gradient_tolerance.unwrap_or(d.gradient_tolerance),
            mu_init: self.mu_init.unwrap_or(d.mu_init),
            mu_min: self.mu_min.unwrap_or(d.mu_min),
            mu_max: self.mu_max.unwrap_or(d.mu_max),
            stochastic: self.stochastic.unwrap_or(d.stochastic),
            damp_short_steps: self.damp_short_steps.unwrap_or(d.damp_short_steps),
            // Set from the actuator by `held_first` once the model is known.
            held_first: Vec::new(),
            ..d
        };
        let s = SoocOptions::default();
        let sooc = SoocOptions {
            indefinite: self.indefinite.unwrap_or(s.indefinite),
            third_derivatives_below: self
                .third_derivatives_below
                .unwrap_or(s.third_derivatives_below),
            keep_third_derivatives: self
                .keep_third_derivatives
                .unwrap_or(s.keep_third_derivatives),
            ..s
        };
        SolverSection {
            method: self.method,
            options,
            noise_continuation: vec![1.0],
            sooc,
        }
    }

    /// Checks the options: the iteration limit and the regularisation must leave the solver
    /// room to work.
    pub(super) fn resolve(self, check: &FileCheck) -> Result<SolverSection, ConfigError> {
        let section = self.section();
        let o = &section.options;
        if o.max_iterations == 0 {
            return Err(check.invalid("solver", "max_iterations", "must be at least 1"));
        }
        check.non_negative(o.tolerance, "solver", "tolerance")?;
        check.non_negative(o.mu_init, "solver", "mu_init")?;
        check.positive(o.mu_max, "solver", "mu_max")?;
        // `inf`: always the exact model (the default).
        let below = section.sooc.third_derivatives_below;
        if below.is_nan() || below <= 0.0 {
            return Err(check.invalid(
                "solver",
                "third_derivatives_below",
                format!("must be a positive number or inf, got {below}"),
            ));
        }
        Ok(section)
    }

    /// Whether deterministic solves hold an impedance's stiffness at its lower limit first
    /// (default true: see [`held_first`]).
    pub(super) fn hold_stiffness_first(&self) -> bool {
        self.hold_stiffness_first.unwrap_or(true)
    }
}

/// The controls a deterministic solve holds at their lower limits first
/// ([`IlqgOptions::held_first`]): an impedance's stiffnesses, which act only through the
/// deviation from the reference. Not a VSA's: its springs carry the motor torque to the link, so
/// at zero stiffness nothing moves it.
pub(super) fn held_first(model: &ArmModel, hold_stiffness_first: bool) -> Vec<usize> {
    match model.actuator {
        Actuator::Impedance { .. } | Actuator::ImpedanceLag { .. } if hold_stiffness_first => {
            (model.dof()..model.nu()).collect()
        }
        _ => Vec::new(),
    }
}

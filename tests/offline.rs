//! The library's tests that run in this process alone: models, derivatives, solvers against
//! closed forms, finite differences, KKT and Monte Carlo, scenarios, plan files, plots and the
//! command line's answers to bad input. One binary, so that the build links once.

mod common;

// The allocation tests count this thread's allocations only, so the other tests running in
// parallel do not disturb them.
#[global_allocator]
static GLOBAL: common::alloc::Counting = common::alloc::Counting;

mod alternating_stiffness;
mod architecture;
mod board;
mod central_overrun;
mod central_predictor;
mod configs;
mod delay;
mod delayed_planner;
mod derivatives;
mod diverged_trials;
mod exit_codes;
mod experiments;
mod fuzz;
mod held_first;
mod identify;
mod ilqg_lqg;
mod ilqg_phases;
mod ilqg_workspace;
mod kkt;
mod late_knots;
mod multiplicative_noise;
mod numeric_flags;
mod plan_file;
mod plot;
mod predicted_cost;
mod predictor;
mod protocol;
mod python_bindings;
mod readme;
mod record_format;
mod replan;
mod report_text;
mod sooc;
mod sooc_newton;
mod sooc_workspace;
mod stiffness_lag;
mod strategy_plan;
mod sweep;
mod wide_vectors;

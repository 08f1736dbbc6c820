//! Fitting material parameters to a photo set, in two rooms, and the pipeline that runs them.
//!
//! | room | question | modules |
//! | --- | --- | --- |
//! | [`point`] | which one material fits the records best? | [`point`] itself (the pipeline: pyramid, starts, local searches, report: [`point::fit_point`], [`FitOptions`], [`ModelFit`]), [`point::objective`] (the loss and its gradients), [`point::params`] (parameter spaces), [`point::projection`] (variable projection), [`point::local`] (L-BFGS, Nelder-Mead), [`point::start`] (global starts), [`point::exposure`] (the exposure value, exposed records), [`point::uniformity`] (does one material explain a region) |
//! | [`bayes`] | how sure are we, and which model? | [`bayes::log_posterior`] (the loss read as a likelihood, priors, noise level), [`bayes::target`] (a log density and its gradient), [`bayes::laplace`] (Laplace approximation and evidence), [`bayes::adjustment`] (the linear map an adjusted likelihood is read through), [`bayes::exposure`] (the exposure's Laplace interval), [`bayes::sampler`] (MALA and between-model jumps), [`bayes::mcmc`] (`--mcmc` runs and checkpoints), [`bayes::posterior`] (posterior summaries), [`bayes::diagnostics`] (R-hat, ESS), [`bayes::selection`] (BIC, held-out rankings), [`bayes::holdout`] (K-fold cross-validation) |
//! | shared numerics | | [`cholesky`] (used by `bayes` and by `crate::maps`) |
//! | the pipeline | how `fit` and `compare` run both rooms on a photo set | [`pipeline`] (records, the fits of the candidate models and the posterior over them, their measurement and BIC ranking), [`fit_file`] (the fit file they write) |
//!
//! The rule: calls go from `bayes` into `point`, never from `point` into `bayes` (a test in
//! `tests/layout.rs` reads the sources of `point/` and fails on an import of `bayes/`). The Bayesian
//! room works on what the point room gives it: a [`point::PointFit`] (the fit and its
//! coordinates) and the [`point::objective::Objective`] its log posterior wraps. This module is
//! the entry that joins them: [`fit_model`] is the point estimate plus the exposure's interval.

pub mod bayes;
pub mod cholesky;
pub mod fit_file;
pub mod pipeline;
pub mod point;

pub use point::{edge_tint, FitOptions, ModelFit, Optimizer, TracePoint};

use crate::error::Result;
use crate::shading::ShadingRecords;

/// Fit one model (the one in `options.space`) to the records: the point estimate
/// ([`point::fit_point`]) with the Laplace interval of its exposure when it fits one
/// ([`bayes::exposure::with_interval`]).
pub fn fit_model(records: &ShadingRecords, options: &FitOptions) -> Result<ModelFit> {
    let point = point::fit_point(records, options)?;
    Ok(bayes::exposure::with_interval(point, records, options))
}

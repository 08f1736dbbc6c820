//! Bayesian inference over the point estimates' parameter spaces.

pub mod adjustment;
pub mod diagnostics;
pub mod discrepancy;
pub mod exposure;
pub mod holdout;
pub mod laplace;
pub mod log_posterior;
pub mod mcmc;
pub mod model_error;
pub mod posterior;
pub mod sampler;
pub mod selection;
pub mod target;

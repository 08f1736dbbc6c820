//! Fitting material parameters to a photo set, in two rooms.
//!
//! | room | question | modules |
//! | --- | --- | --- |
//! | [`point`] | which one material fits the records best? | [`point`] itself (the pipeline: pyramid, starts, local searches, report: [`point::fit_point`], [`FitOptions`], [`ModelFit`]), [`point::objective`] (the loss and its gradients), [`point::params`] (parameter spaces), [`point::projection`] (variable projection), [`point::local`] (L-BFGS, Nelder-Mead), [`point::start`] (global starts), [`point::exposure`] (the exposure value, exposed records), [`point::uniformity`] (does one material explain a region) |
//! | [`bayes`] | how sure are we, and which model? | [`bayes::log_posterior`] (the loss read as a likelihood, priors, noise level), [`bayes::laplace`] (Laplace approximation and evidence), [`bayes::exposure`] (the exposure's Laplace interval), [`bayes::sampler`] (MALA and between-model jumps), [`bayes::mcmc`] (`--mcmc` runs and checkpoints), [`bayes::posterior`] (posterior summaries), [`bayes::diagnostics`] (R-hat, ESS), [`bayes::selection`] (BIC, held-out rankings), [`bayes::holdout`] (K-fold cross-validation) |
//! | shared numerics | | [`cholesky`] (used by `bayes` and by `crate::maps`) |
//!
//! The rule: calls go from `bayes` into `point`, never from `point` into `bayes` (a test below
//! reads the sources of `point/` and fails where code outside comments names `bayes`). The Bayesian
//! room works on what the point room gives it: a [`point::PointFit`] (the fit and its
//! coordinates) and the [`point::objective::Objective`] its log posterior wraps. This module is
//! the entry that joins them: [`fit_model`] is the point estimate plus the exposure's interval.

pub mod bayes;
pub mod cholesky;
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

#[cfg(test)]
mod tests {
    use std::path::Path;

    /// Every `.rs` file below `dir`.
    fn sources(dir: &Path, found: &mut Vec<std::path::PathBuf>) {
        for entry in std::fs::read_dir(dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                sources(&path, found);
            } else if path.extension().is_some_and(|e| e == "rs") {
                found.push(path);
            }
        }
    }

    #[test]
    fn point_room_never_calls_into_the_bayes_room() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("src/fit/point");
        let mut files = Vec::new();
        sources(&dir, &mut files);
        assert!(
            files.len() >= 8,
            "point/ sources not found in {}",
            dir.display()
        );
        for file in files {
            let text = std::fs::read_to_string(&file).unwrap();
            for (n, line) in text.lines().enumerate() {
                // Doc comments may name the other room; code may not.
                let code = line.trim_start();
                if code.starts_with("//") {
                    continue;
                }
                let names_bayes = code.match_indices("bayes").any(|(i, _)| {
                    let ident = |c: char| c.is_alphanumeric() || c == '_';
                    !code[..i].ends_with(ident) && !code[i + 5..].starts_with(ident)
                });
                assert!(
                    !names_bayes,
                    "{}:{}: the point room calls into bayes: {line}",
                    file.display(),
                    n + 1
                );
            }
        }
    }
}

//! What the Bayesian room samples and approximates: a log density over unbounded coordinates
//! with its gradient ([`super::log_posterior::LogPosterior`] in production, Gaussians and
//! mixtures in the tests).

/// A log density over unbounded coordinates, with its gradient.
pub trait Target: Sync {
    fn dim(&self) -> usize;
    /// `ln p(x)` up to a constant shared by all candidates; `-inf` outside the support.
    fn log_density(&self, x: &[f64]) -> f64;
    fn gradient(&self, x: &[f64]) -> Vec<f64>;
}

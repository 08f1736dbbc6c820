//! The fit's image loss read as a log posterior over the unbounded coordinates of a
//! [`ParamSpace`], in the spirit of Guo, Hašan, Yan and Zhao 2020, "A Bayesian Inference
//! Framework for Procedural Material Parameter Estimation" (CGF 39(7), section 4: the image
//! loss as a negative log-likelihood with a noise level, priors on the parameters).
//!
//! Likelihood: with `N = 3 * (pixels in the loss)` and the loss a weighted mean over pixels and
//! channels (weights normalised to mean 1, so `N * loss` is the weighted sum),
//!
//! | loss kind | reading | `ln L` | noise level `s` |
//! | --- | --- | --- | --- |
//! | squared (`l2`, and any relative squared loss) | Gaussian | `-N loss / (2 s^2) - N/2 ln(2 pi s^2)` | standard deviation of a residual in the loss's units (radiance for `l2`, relative for a relative loss) |
//! | `log-l1` | Laplace | `-N loss / s - N ln(2 s)` | mean absolute log residual |
//!
//! `s` is given (`--noise-sigma`) or estimated as the maximum-likelihood value at the best MAP
//! among the candidate models (Gaussian: `s^2 = loss`; Laplace: `s = loss`), the same for every
//! model so that their likelihoods compare. It is floored at [`NOISE_FLOOR`] so that noise-free
//! synthetic photos do not give an infinitely sharp posterior.
//!
//! Priors (proper, so that the Laplace evidence of [`super::laplace`] is meaningful):
//!
//! | parameter | prior | density in the coordinate |
//! | --- | --- | --- |
//! | `alpha`, `alpha_x`, `alpha_y` | log-uniform on [1e-3, 3] | `u = ln alpha` uniform on [ln 1e-3, ln 3]: `1 / ln 3000`, zero outside |
//! | F0, conductor reflectivity and edge tint, diffuse (per channel) | uniform on (0, 1) | `y = logit p`: `p (1 - p)` (the Jacobian of the logit) |
//!
//! Gradients of the likelihood come from the `Gradient` implementation of [`Objective`] (today
//! central differences with common random numbers), so any exact gradient put behind that trait
//! is used as is. Stochastic models keep the objective's fixed random numbers, so the target is
//! a deterministic function of the coordinates (a fixed-noise approximation of the posterior of
//! the exact model, with the models' per-pixel Monte Carlo error added to the image noise).

use super::objective::Objective;
use super::params::{sigmoid, ParamSpace};
use super::sampler::Target;
use crate::loss::LossKind;
use crate::shading::ShadingRecords;
use argmin::core::{CostFunction, Gradient};
use rand::seq::index::sample;
use serde::{Deserialize, Serialize};

/// Lower bound of the estimated noise level, relative to the root-mean-square target (Gaussian)
/// or absolute in log units (Laplace): below 16-bit quantisation, so it binds only for
/// noise-free synthetic photos.
pub const NOISE_FLOOR: f64 = 1e-5;

/// Support of the log-uniform roughness prior.
pub const ALPHA_PRIOR: [f64; 2] = [1e-3, 3.0];

/// How the loss is read as a negative log-likelihood.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Reading {
    Gaussian,
    Laplace,
}

impl Reading {
    pub fn of(kind: LossKind) -> Reading {
        match kind {
            LossKind::LogL1 => Reading::Laplace,
            // Every other loss is a (possibly relative) squared error.
            _ => Reading::Gaussian,
        }
    }
}

/// The noise model of the likelihood.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Noise {
    pub reading: Reading,
    /// Gaussian standard deviation or Laplace scale, in the loss's units.
    pub sigma: f64,
    /// Estimated from the data (true) or given (false).
    pub estimated: bool,
}

impl Noise {
    /// Maximum-likelihood noise level for the lowest MAP loss, floored (see the module docs).
    pub fn estimate(kind: LossKind, best_loss: f64, rms_target: f64) -> Noise {
        let reading = Reading::of(kind);
        let sigma = match reading {
            Reading::Gaussian => best_loss.max(0.0).sqrt().max(NOISE_FLOOR * rms_target),
            Reading::Laplace => best_loss.max(NOISE_FLOOR),
        };
        Noise {
            reading,
            sigma,
            estimated: true,
        }
    }

    /// `ln L` and `d ln L / d loss` for `count` residuals with mean loss `loss`.
    fn log_likelihood(&self, loss: f64, count: f64) -> (f64, f64) {
        let s = self.sigma;
        match self.reading {
            Reading::Gaussian => {
                let slope = -count / (2.0 * s * s);
                let norm = -0.5 * count * (2.0 * std::f64::consts::PI * s * s).ln();
                (slope * loss + norm, slope)
            }
            Reading::Laplace => {
                let slope = -count / s;
                (slope * loss - count * (2.0 * s).ln(), slope)
            }
        }
    }
}

/// Prior of one coordinate.
#[derive(Clone, Copy, Debug)]
enum Prior {
    /// `ln alpha` uniform on `[ln lo, ln hi]`.
    LogUniform { lo: f64, hi: f64 },
    /// `logit p` with `p` uniform on (0, 1).
    LogitUniform,
}

impl Prior {
    /// Log density and its derivative at coordinate `y`.
    fn log_density(self, y: f64) -> (f64, f64) {
        match self {
            Prior::LogUniform { lo, hi } => {
                if (lo.ln()..=hi.ln()).contains(&y) {
                    (-(hi / lo).ln().ln(), 0.0)
                } else {
                    (f64::NEG_INFINITY, 0.0)
                }
            }
            Prior::LogitUniform => {
                // ln p(1-p) = -softplus(-y) - softplus(y), derivative 1 - 2p.
                let softplus = |t: f64| t.max(0.0) + (-t.abs()).exp().ln_1p();
                (-softplus(-y) - softplus(y), 1.0 - 2.0 * sigmoid(y))
            }
        }
    }
}

/// Log posterior of one candidate model (a [`ParamSpace`]) given the records.
pub struct LogPosterior<'a> {
    pub objective: Objective<'a>,
    pub noise: Noise,
    /// Number of residuals `N` (3 per pixel in the loss).
    pub count: f64,
    priors: Vec<Prior>,
}

impl<'a> LogPosterior<'a> {
    pub fn new(
        space: ParamSpace,
        records: &'a ShadingRecords,
        kind: LossKind,
        seed: u64,
        noise: Noise,
    ) -> Self {
        let objective = Objective::new(space, records, kind, seed);
        let priors = space
            .names()
            .iter()
            .map(|name| {
                if name.starts_with("ln_alpha") {
                    Prior::LogUniform {
                        lo: ALPHA_PRIOR[0],
                        hi: ALPHA_PRIOR[1],
                    }
                } else {
                    debug_assert!(name.starts_with("logit_"), "{name}");
                    Prior::LogitUniform
                }
            })
            .collect();
        LogPosterior {
            count: 3.0 * objective.pixel_count() as f64,
            objective,
            noise,
            priors,
        }
    }

    /// Log prior density and its gradient.
    fn log_prior(&self, x: &[f64]) -> (f64, Vec<f64>) {
        let mut total = 0.0;
        let gradient = self
            .priors
            .iter()
            .zip(x)
            .map(|(prior, &y)| {
                let (value, slope) = prior.log_density(y);
                total += value;
                slope
            })
            .collect();
        (total, gradient)
    }
}

impl Target for LogPosterior<'_> {
    fn dim(&self) -> usize {
        self.priors.len()
    }

    fn log_density(&self, x: &[f64]) -> f64 {
        let (prior, _) = self.log_prior(x);
        if prior == f64::NEG_INFINITY {
            return prior;
        }
        let cost = (&self.objective).cost(&x.to_vec()).unwrap_or(f64::INFINITY);
        let loss = self.objective.loss_from_cost(cost);
        let value = prior + self.noise.log_likelihood(loss, self.count).0;
        if value.is_nan() {
            f64::NEG_INFINITY
        } else {
            value
        }
    }

    fn gradient(&self, x: &[f64]) -> Vec<f64> {
        let (_, mut gradient) = self.log_prior(x);
        let slope = self.noise.log_likelihood(0.0, self.count).1;
        match (&self.objective).gradient(&x.to_vec()) {
            Ok(cost_gradient) => {
                for (g, c) in gradient.iter_mut().zip(cost_gradient) {
                    *g += slope * self.objective.loss_from_cost(c);
                }
            }
            Err(_) => gradient.fill(f64::NAN),
        }
        gradient
    }
}

/// The records with all but `count` randomly chosen (seeded) loss pixels given weight 0, or the
/// records unchanged when `count` is 0 or at least the number of loss pixels. The posterior is
/// then that of the subset: intervals widen by about `sqrt(all / count)`.
pub fn pixel_subset(records: &ShadingRecords, count: usize, seed: u64) -> ShadingRecords {
    let used: Vec<usize> = (0..records.pixel_count())
        .filter(|&p| records.weight[p] > 0.0)
        .collect();
    let mut subset = records.clone();
    if count == 0 || count >= used.len() {
        return subset;
    }
    let mut rng = crate::albedo::rng_stream(seed, 0x5375_6273_6574);
    let mut keep = vec![false; records.pixel_count()];
    for i in sample(&mut rng, used.len(), count) {
        keep[used[i]] = true;
    }
    for (w, k) in subset.weight.iter_mut().zip(keep) {
        if !k {
            *w = 0.0;
        }
    }
    subset
}

/// Root-mean-square target radiance over the loss pixels (the scale of the noise floor).
pub fn rms_target(records: &ShadingRecords) -> f64 {
    let (mut sum, mut count) = (0.0, 0.0f64);
    for (t, w) in records.target.iter().zip(&records.weight) {
        if *w > 0.0 {
            sum += t.iter().map(|v| v * v).sum::<f64>();
            count += 3.0;
        }
    }
    (sum / count.max(1.0)).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn priors_integrate_to_one_and_match_their_derivatives() {
        for prior in [Prior::LogUniform { lo: 1e-3, hi: 3.0 }, Prior::LogitUniform] {
            // Trapezoid rule over a range wide enough for the logistic tails (< 1e-13).
            let (a, b, n) = (-30.0, 30.0, 600_000);
            let h = (b - a) / n as f64;
            let integral: f64 = (0..=n)
                .map(|i| {
                    let w = if i == 0 || i == n { 0.5 } else { 1.0 };
                    w * prior.log_density(a + h * i as f64).0.exp()
                })
                .sum::<f64>()
                * h;
            assert!((integral - 1.0).abs() < 1e-4, "{prior:?}: {integral}");
            for y in [-2.0, -0.3, 0.7] {
                let d = 1e-6;
                let numeric = (prior.log_density(y + d).0 - prior.log_density(y - d).0) / (2.0 * d);
                assert!((numeric - prior.log_density(y).1).abs() < 1e-7);
            }
        }
    }

    #[test]
    fn gaussian_and_laplace_likelihoods_are_normalised_densities_of_a_residual() {
        // One residual r: the Gaussian reads loss = r^2, the Laplace loss = |r|.
        for (reading, loss_of) in [
            (Reading::Gaussian, (|r: f64| r * r) as fn(f64) -> f64),
            (Reading::Laplace, |r: f64| r.abs()),
        ] {
            let noise = Noise {
                reading,
                sigma: 0.3,
                estimated: false,
            };
            let h = 1e-4;
            let integral: f64 = (-100_000..=100_000)
                .map(|i| noise.log_likelihood(loss_of(h * i as f64), 1.0).0.exp())
                .sum::<f64>()
                * h;
            assert!((integral - 1.0).abs() < 1e-6, "{reading:?}: {integral}");
        }
    }
}

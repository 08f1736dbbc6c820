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
//! | `l2` | Gaussian | `-N loss / (2 s^2) - N/2 ln(2 pi s^2)` | standard deviation of a residual, in radiance |
//! | `relative-l2` | Gaussian proportional to the predicted radiance `p` | `-sum_i,c w_i [(p - t)^2 / (2 s^2 v) + 1/2 ln(2 pi s^2 v)]`, `v = p^2 + e^2` | standard deviation relative to the pixel's radiance (`synth --noise`) |
//! | `log-l1` | Laplace | `-N loss / s - N ln(2 s)` | mean absolute log residual |
//! | `ssim` | none: refused | | |
//!
//! The `relative-l2` loss divides by the noisy target, `(p - t)^2 / (t^2 + e^2)`: pixels that
//! came out bright by chance count less, which pulls the fitted radiance scale down by about
//! `2 s^2` (measured: F0 0.3-0.7% low at 2.5-4% noise, so 95% intervals from 2304 pixels held
//! the truth on 3 of 10 sets). Its likelihood reading therefore divides by the prediction and
//! keeps the `ln v` normaliser that then depends on the parameters, with `e` =
//! [`PROPORTIONAL_FLOOR`] of the mean target radiance as in the loss; its gradient is by central
//! differences of that log-likelihood (same common random numbers as the objective).
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
//! | `exposure` | log-uniform on [1e-3, 1e3] | `u = ln s` uniform on [ln 1e-3, ln 1e3] |
//!
//! Gradients of the likelihood come from the `Gradient` implementation of [`Objective`] (today
//! central differences with common random numbers), so any exact gradient put behind that trait
//! is used as is. Stochastic models keep the objective's fixed random numbers, so the target is
//! a deterministic function of the coordinates (a fixed-noise approximation of the posterior of
//! the exact model, with the models' per-pixel Monte Carlo error added to the image noise).

use super::adjustment::Adjustment;
use super::target::Target;
use crate::fit::point::objective::Objective;
use crate::fit::point::params::{sigmoid, ParamSpace};
use crate::loss::LossKind;
use crate::render::batch::Precision;
use crate::shading::ShadingRecords;
use argmin::core::{CostFunction, Gradient};
use rand::seq::index::sample;
use serde::{Deserialize, Serialize};

/// Lower bound of the estimated noise level, relative to the root-mean-square target (`l2`) or
/// in the loss's relative or log units (the others): below 16-bit quantisation, so it binds
/// only for noise-free synthetic photos.
pub const NOISE_FLOOR: f64 = 1e-5;

/// Floor `e` of the proportional noise, a fraction of the mean target radiance (the
/// `relative-l2` loss's floor).
pub const PROPORTIONAL_FLOOR: f64 = 1e-2;

/// Relative step of the central differences of the proportional log-likelihood.
pub(super) const FD_STEP: f64 = 1e-5;

/// Support of the log-uniform roughness prior.
pub const ALPHA_PRIOR: [f64; 2] = [1e-3, 3.0];

/// Support of the log-uniform exposure prior.
pub const EXPOSURE_PRIOR: [f64; 2] = [1e-3, 1e3];

/// How the loss is read as a negative log-likelihood.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Reading {
    Gaussian,
    /// Gaussian with standard deviation `s sqrt(p^2 + e^2)` for predicted radiance `p`.
    Proportional,
    Laplace,
}

impl Reading {
    /// The reading of a loss kind; `None` for `ssim`, which is not the likelihood of any noise.
    pub fn of(kind: LossKind) -> Option<Reading> {
        match kind {
            LossKind::L2 => Some(Reading::Gaussian),
            LossKind::RelativeL2 => Some(Reading::Proportional),
            LossKind::LogL1 => Some(Reading::Laplace),
            LossKind::Ssim => None,
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
    pub fn estimate(reading: Reading, kind: LossKind, best_loss: f64, rms_target: f64) -> Noise {
        // The loss's units: radiance for l2, relative (or log) radiance otherwise.
        let floor = match kind {
            LossKind::L2 => NOISE_FLOOR * rms_target,
            _ => NOISE_FLOOR,
        };
        let sigma = match reading {
            Reading::Gaussian | Reading::Proportional => best_loss.max(0.0).sqrt(),
            Reading::Laplace => best_loss,
        };
        Noise {
            reading,
            sigma: sigma.max(floor),
            estimated: true,
        }
    }

    /// `ln L` and `d ln L / d loss` for `count` residuals with mean loss `loss`.
    fn log_likelihood(&self, loss: f64, count: f64) -> (f64, f64) {
        let s = self.sigma;
        match self.reading {
            Reading::Gaussian | Reading::Proportional => {
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
    /// `ln` of the parameter uniform on `[ln lo, ln hi]`.
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

/// Targets, weights (mean 1) and floor of the proportional reading, per loss pixel.
struct ProportionalData {
    target: Vec<[f64; 3]>,
    weight: Vec<f64>,
    floor_squared: f64,
}

impl ProportionalData {
    fn new(records: &ShadingRecords) -> Self {
        let used: Vec<usize> = (0..records.pixel_count())
            .filter(|&p| records.weight[p] > 0.0)
            .collect();
        let mean_weight =
            used.iter().map(|&p| records.weight[p]).sum::<f64>() / used.len().max(1) as f64;
        let target: Vec<[f64; 3]> = used.iter().map(|&p| records.target[p]).collect();
        let mean_target = target.iter().flatten().sum::<f64>() / (3 * target.len().max(1)) as f64;
        ProportionalData {
            weight: used
                .iter()
                .map(|&p| records.weight[p] / mean_weight)
                .collect(),
            target,
            floor_squared: (PROPORTIONAL_FLOOR * mean_target).powi(2),
        }
    }

    /// Per pixel: its part of `ln L` for predictions `predicted` (the objective's loss pixels,
    /// in order).
    fn pixel_log_likelihoods(&self, predicted: &[[f64; 3]], sigma: f64) -> Vec<f64> {
        let s2 = sigma * sigma;
        predicted
            .iter()
            .zip(&self.target)
            .zip(&self.weight)
            .map(|((p, t), w)| {
                let sum: f64 = (0..3)
                    .map(|c| {
                        let v = s2 * (p[c] * p[c] + self.floor_squared);
                        (p[c] - t[c]).powi(2) / v + (2.0 * std::f64::consts::PI * v).ln()
                    })
                    .sum();
                -0.5 * w * sum
            })
            .collect()
    }

    /// `ln L` of predictions `predicted` (the objective's loss pixels, in order).
    fn log_likelihood(&self, predicted: &[[f64; 3]], sigma: f64) -> f64 {
        self.pixel_log_likelihoods(predicted, sigma).iter().sum()
    }
}

/// Log posterior of one candidate model (a [`ParamSpace`]) given the records.
pub struct LogPosterior<'a> {
    pub objective: Objective<'a>,
    pub noise: Noise,
    /// Number of residuals `N` (3 per pixel in the loss).
    pub count: f64,
    priors: Vec<Prior>,
    proportional: Option<ProportionalData>,
    /// The model-error adjustment through which the likelihood is read ([`super::model_error`]).
    adjustment: Option<Adjustment>,
}

impl<'a> LogPosterior<'a> {
    pub fn new(
        space: ParamSpace,
        records: &'a ShadingRecords,
        kind: LossKind,
        seed: u64,
        noise: Noise,
    ) -> Self {
        // The curvature and the model-error adjustment take central differences of the
        // likelihood's gradient (step 1e-3), which would amplify the `f32` lanes' rounding of
        // the tangents (up to 5e-4 relative) into the intervals: the posterior uses `f64` lanes.
        let objective = Objective::new(space, records, kind, seed).with_precision(Precision::F64);
        let priors = space
            .names()
            .iter()
            .map(|name| {
                if name.starts_with("ln_alpha") {
                    Prior::LogUniform {
                        lo: ALPHA_PRIOR[0],
                        hi: ALPHA_PRIOR[1],
                    }
                } else if name == "ln_exposure" {
                    Prior::LogUniform {
                        lo: EXPOSURE_PRIOR[0],
                        hi: EXPOSURE_PRIOR[1],
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
            proportional: (noise.reading == Reading::Proportional)
                .then(|| ProportionalData::new(records)),
            noise,
            priors,
            adjustment: None,
        }
    }

    /// The same posterior with its likelihood read through `adjustment`.
    pub fn with_adjustment(self, adjustment: Option<Adjustment>) -> Self {
        LogPosterior { adjustment, ..self }
    }

    /// Where the likelihood is read for coordinates `x`.
    fn likelihood_point(&self, x: &[f64]) -> Vec<f64> {
        match &self.adjustment {
            Some(a) => a.apply(x),
            None => x.to_vec(),
        }
    }

    /// `ln L` at `x`.
    fn log_likelihood(&self, x: &[f64]) -> f64 {
        if let Some(data) = &self.proportional {
            return data.log_likelihood(&self.objective.predict(x), self.noise.sigma);
        }
        let cost = (&self.objective).cost(&x.to_vec()).unwrap_or(f64::INFINITY);
        let loss = self.objective.loss_from_cost(cost);
        self.noise.log_likelihood(loss, self.count).0
    }

    /// Per loss pixel (the objective's order): its part of `ln L` at `x`, up to a constant
    /// (without the adjustment).
    pub fn pixel_log_likelihoods(&self, x: &[f64]) -> Vec<f64> {
        if let Some(data) = &self.proportional {
            return data.pixel_log_likelihoods(&self.objective.predict(x), self.noise.sigma);
        }
        let loss = self.objective.image_loss();
        let slope = self.noise.log_likelihood(0.0, self.count).1;
        loss.renders_terms(&self.objective.renders(x))
            .into_iter()
            .map(|t| slope * loss.mean_of(&[t]))
            .collect()
    }

    /// Per loss pixel and channel: the precision `lambda` of its residual, with
    /// `ln L = -1/2 sum lambda (p - t)^2 + const` near predictions `predicted` (the objective's
    /// loss pixels); `None` for the Laplace reading, which is not a quadratic form.
    pub fn residual_precisions(&self, predicted: &[[f64; 3]]) -> Option<Vec<[f64; 3]>> {
        let s2 = self.noise.sigma * self.noise.sigma;
        if let Some(data) = &self.proportional {
            return Some(
                predicted
                    .iter()
                    .zip(&data.weight)
                    .map(|(p, w)| p.map(|p| w / (s2 * (p * p + data.floor_squared))))
                    .collect(),
            );
        }
        if self.noise.reading != Reading::Gaussian {
            return None;
        }
        let weights = self.objective.image_loss().quadratic_weights()?;
        Some(
            weights
                .into_iter()
                .map(|v| v.map(|v| self.count * v / s2))
                .collect(),
        )
    }

    /// Gradient of `ln L` (without the adjustment) at `x`.
    pub fn likelihood_gradient(&self, x: &[f64]) -> Vec<f64> {
        if self.proportional.is_some() {
            return central_differences(x, FD_STEP, |probe| vec![self.log_likelihood(probe)])
                .remove(0);
        }
        let slope = self.noise.log_likelihood(0.0, self.count).1;
        match (&self.objective).gradient(&x.to_vec()) {
            Ok(cost_gradient) => cost_gradient
                .into_iter()
                .map(|c| slope * self.objective.loss_from_cost(c))
                .collect(),
            Err(_) => vec![f64::NAN; x.len()],
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
        let value = prior + self.log_likelihood(&self.likelihood_point(x));
        if value.is_nan() {
            f64::NEG_INFINITY
        } else {
            value
        }
    }

    fn gradient(&self, x: &[f64]) -> Vec<f64> {
        let (_, prior) = self.log_prior(x);
        let likelihood = self.likelihood_gradient(&self.likelihood_point(x));
        let likelihood = match &self.adjustment {
            Some(a) => a.pull_back(&likelihood),
            None => likelihood,
        };
        prior.iter().zip(likelihood).map(|(p, l)| p + l).collect()
    }
}

/// Central differences of each output of `f` at `x` with steps `step * max(1, |x_i|)`: row `k`
/// is the gradient of output `k`.
pub(super) fn central_differences(
    x: &[f64],
    step: f64,
    f: impl Fn(&[f64]) -> Vec<f64>,
) -> Vec<Vec<f64>> {
    let mut rows: Vec<Vec<f64>> = Vec::new();
    let mut probe = x.to_vec();
    for i in 0..x.len() {
        let h = step * x[i].abs().max(1.0);
        probe[i] = x[i] + h;
        let plus = f(&probe);
        probe[i] = x[i] - h;
        let minus = f(&probe);
        probe[i] = x[i];
        rows.resize_with(plus.len(), || vec![0.0; x.len()]);
        for (row, (p, m)) in rows.iter_mut().zip(plus.iter().zip(&minus)) {
            row[i] = (p - m) / (2.0 * h);
        }
    }
    rows
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
    let mut rng = crate::random::rng_stream(seed, 0x5375_6273_6574);
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

//! The interval of the fitted exposure (`--fit-exposure`), added to a point estimate.
//!
//! | piece | behaviour |
//! | --- | --- |
//! | interval | central 95% of the Laplace approximation ([`Laplace`], MacKay 2003, section 27.1) of the posterior of [`LogPosterior`] at the point estimate's coordinates, noise level estimated from the fit's loss as the sampler does; `exp(mu +- 1.96 sd)` in `ln s`. `None` for `ssim`, which has no likelihood reading |
//!
//! The value itself is the point estimate's ([`crate::fit::point::exposure`]).

use super::laplace::Laplace;
use super::log_posterior::{rms_target, LogPosterior, Noise, Reading};
use crate::fit::point::params::ParamSpace;
use crate::fit::point::{FitOptions, ModelFit, PointFit};
use crate::loss::LossKind;
use crate::shading::ShadingRecords;
use std::time::Instant;

/// Standard normal quantile of a central 95% interval.
const Z95: f64 = 1.959_963_984_540_054;

/// Central 95% Laplace interval of the exposure at coordinates `x` of `space` given `records`,
/// the loss `kind` and its value `loss` at `x`; `None` when the loss has no likelihood reading.
pub fn interval(
    space: ParamSpace,
    records: &ShadingRecords,
    kind: LossKind,
    seed: u64,
    x: &[f64],
    loss: f64,
) -> Option<[f64; 2]> {
    Reading::of(kind).map(|reading| {
        let noise = Noise::estimate(reading, kind, loss, rms_target(records));
        let target = LogPosterior::new(space, records, kind, seed, noise);
        let laplace = Laplace::at_mode(&target, x);
        let last = x.len() - 1;
        let (mu, sd) = (laplace.mean[last], laplace.standard_deviations()[last]);
        [(mu - Z95 * sd).exp(), (mu + Z95 * sd).exp()]
    })
}

/// The point estimate `point` of `records` under `options` with the interval of its exposure
/// (when it fits one); the time taken is added to the fit's seconds.
pub fn with_interval(point: PointFit, records: &ShadingRecords, options: &FitOptions) -> ModelFit {
    let started = Instant::now();
    let PointFit { mut fit, x } = point;
    if let Some(exposure) = &mut fit.exposure {
        exposure.interval = interval(
            options.space,
            records,
            options.loss,
            options.seed,
            &x,
            fit.loss,
        );
    }
    fit.seconds += started.elapsed().as_secs_f64();
    fit
}

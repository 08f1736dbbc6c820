//! The global exposure of `--fit-exposure`: its estimate with a Laplace interval, and the
//! records a fitted exposure applies to.
//!
//! | piece | behaviour |
//! | --- | --- |
//! | coordinate | `ln s`, the last coordinate of the [`ParamSpace`]; `s` multiplies every prediction, which is linear in the light power, so `s` = true power / nominal power (or a camera gain) |
//! | identifiability | only with a known Fresnel ([`ParamSpace::check`]): a flash photo shows `s` times the reflectance |
//! | value | `s` at the optimiser's answer |
//! | interval | central 95% of the Laplace approximation ([`Laplace`], MacKay 2003, section 27.1) of the posterior of [`LogPosterior`] at that point, noise level estimated from the fit's loss as the sampler does; `exp(mu +- 1.96 sd)` in `ln s`. `None` for `ssim`, which has no likelihood reading |
//! | use | predictions of a fitted material (residual images, BIC, held-out error) are rendered on the records with irradiance times `s` ([`exposed_records`]) |

use crate::fit::bayes::laplace::Laplace;
use crate::fit::bayes::log_posterior::{rms_target, LogPosterior, Noise, Reading};
use super::params::ParamSpace;
use crate::loss::LossKind;
use crate::shading::ShadingRecords;
use serde::{Deserialize, Serialize};
use std::borrow::Cow;

/// Standard normal quantile of a central 95% interval.
const Z95: f64 = 1.959_963_984_540_054;

/// A fitted exposure, written to fit files as `exposure: {value, interval}`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ExposureEstimate {
    pub value: f64,
    /// Central 95% Laplace interval (`None` when the loss has no likelihood reading, or for
    /// intermediate pyramid levels).
    pub interval: Option<[f64; 2]>,
}

/// The exposure at coordinates `x` of `space` with its Laplace interval given `records`, the
/// loss `kind` and its value `loss` at `x`; `None` when the space does not fit one.
pub fn estimate(
    space: ParamSpace,
    records: &ShadingRecords,
    kind: LossKind,
    seed: u64,
    x: &[f64],
    loss: f64,
) -> Option<ExposureEstimate> {
    if !space.exposure {
        return None;
    }
    let interval = Reading::of(kind).map(|reading| {
        let noise = Noise::estimate(reading, kind, loss, rms_target(records));
        let target = LogPosterior::new(space, records, kind, seed, noise);
        let laplace = Laplace::at_mode(&target, x);
        let last = x.len() - 1;
        let (mu, sd) = (laplace.mean[last], laplace.standard_deviations()[last]);
        [(mu - Z95 * sd).exp(), (mu + Z95 * sd).exp()]
    });
    Some(ExposureEstimate {
        value: space.exposure(x),
        interval,
    })
}

/// `records` with every irradiance times `exposure` (borrowed unchanged at 1): renders of a
/// material on them are the predictions of a fit with that exposure.
pub fn exposed_records(records: &ShadingRecords, exposure: f64) -> Cow<'_, ShadingRecords> {
    if exposure == 1.0 {
        return Cow::Borrowed(records);
    }
    let mut scaled = records.clone();
    for e in scaled.irradiance.iter_mut() {
        *e = e.map(|v| v * exposure);
    }
    Cow::Owned(scaled)
}

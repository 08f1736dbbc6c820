//! The global exposure of `--fit-exposure`: its value at the fit, and the records a fitted
//! exposure applies to. Its interval is the Bayesian room's (`crate::fit::bayes::exposure`).
//!
//! | piece | behaviour |
//! | --- | --- |
//! | coordinate | `ln s`, the last coordinate of the [`ParamSpace`]; `s` multiplies every prediction, which is linear in the light power, so `s` = true power / nominal power (or a camera gain) |
//! | identifiability | only with a known Fresnel ([`ParamSpace::check`]): a flash photo shows `s` times the reflectance |
//! | value | `s` at the optimiser's answer ([`estimate`]) |
//! | use | predictions of a fitted material (residual images, BIC, held-out error) are rendered on the records with irradiance times `s` ([`exposed_records`]) |

use super::params::ParamSpace;
use crate::shading::ShadingRecords;
use serde::{Deserialize, Serialize};
use std::borrow::Cow;

/// A fitted exposure, written to fit files as `exposure: {value, interval}`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ExposureEstimate {
    pub value: f64,
    /// Central 95% Laplace interval (`None` when the loss has no likelihood reading, or for
    /// intermediate pyramid levels).
    pub interval: Option<[f64; 2]>,
}

/// The exposure at coordinates `x` of `space`, without an interval; `None` when the space does
/// not fit one.
pub fn estimate(space: ParamSpace, x: &[f64]) -> Option<ExposureEstimate> {
    space.exposure.then(|| ExposureEstimate {
        value: space.exposure(x),
        interval: None,
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

/// `records` with every irradiance of photo `i` times `gains[i]` per channel: renders on them
/// are the predictions under each photo's own exposure and white balance (the maps fit's
/// `--photo-gains`).
pub fn photo_exposed_records(records: &ShadingRecords, gains: &[[f64; 3]]) -> ShadingRecords {
    let mut scaled = records.clone();
    let spp = records.samples_per_pixel;
    for (photo, gain) in records.photos.iter().zip(gains) {
        let first = photo.first_pixel * spp;
        let count = photo.width * photo.height * spp;
        for e in &mut scaled.irradiance[first..first + count] {
            *e = std::array::from_fn(|c| e[c] * gain[c]);
        }
    }
    scaled
}

//! Sampling shared by the analytic models that add a broad lobe to `single` (`fast-msx`,
//! `kulla-conty`, `turquin`): one-sample multiple importance sampling of the single-bounce
//! visible-normal lobe (probability [`P_SINGLE_LOBE`]) and the cosine distribution, with the
//! exact mixture density, so the weight `f cos / pdf` is unbiased and bounded for any added lobe
//! whose value is bounded (Veach 1997, sec. 9.2.4, one-sample model).
//!
//! The first uniform number chooses the technique and is then rescaled, so stratification of
//! `u` carries over to the chosen technique.

use super::single::SingleBounce;
use super::{Brdf, BrdfSample, BrdfValue};

use crate::random::Rng;
use crate::scalar::Vec3;
use std::f64::consts::{FRAC_1_PI, PI};

/// Probability of drawing from the single-bounce lobe.
pub const P_SINGLE_LOBE: f64 = 0.75;

/// Density of the mixture at `wo`.
pub fn pdf(single: &SingleBounce<f64>, wi: Vec3<f64>, wo: Vec3<f64>) -> f64 {
    if wo.z <= 0.0 || wi.z <= 0.0 {
        return 0.0;
    }
    P_SINGLE_LOBE * single.pdf(wi, wo) + (1.0 - P_SINGLE_LOBE) * wo.z * FRAC_1_PI
}

/// Draw `wo` from the mixture and weight it by `eval(wo) * wo.z / pdf`. `bounces` is 0: these
/// models have no path structure.
pub fn sample(
    single: &SingleBounce<f64>,
    wi: Vec3<f64>,
    u: [f64; 2],
    eval: impl FnOnce(Vec3<f64>) -> [f64; 3],
) -> Option<BrdfSample> {
    if wi.z <= 0.0 {
        return None;
    }
    let wo = if u[0] < P_SINGLE_LOBE {
        single.sample_weighted(wi, [u[0] / P_SINGLE_LOBE, u[1]])?.0
    } else {
        let v = (u[0] - P_SINGLE_LOBE) / (1.0 - P_SINGLE_LOBE);
        let r = v.sqrt();
        let phi = 2.0 * PI * u[1];
        Vec3::new(r * phi.cos(), r * phi.sin(), (1.0 - v).max(0.0).sqrt())
    };
    let density = pdf(single, wi, wo);
    if density.is_nan() || density <= 0.0 {
        return None;
    }
    let f = eval(wo);
    Some(BrdfSample {
        wo,
        weight: f.map(|v| v * wo.z / density),
        pdf: density,
        bounces: 0,
    })
}

/// A model whose value is the single-bounce lobe plus an added deterministic lobe
/// (`fast-msx`, `kulla-conty`, `turquin`): evaluation, sampling and density follow for free.
pub trait AddedLobe: Send + Sync {
    /// The exact single-bounce part.
    fn single_lobe(&self) -> &SingleBounce<f64>;
    /// The added lobe, 1/sr.
    fn added_lobe(&self, wi: Vec3<f64>, wo: Vec3<f64>) -> [f64; 3];
}

impl<M: AddedLobe> Brdf for M {
    fn eval(&self, wi: Vec3<f64>, wo: Vec3<f64>, _rng: &mut Rng) -> BrdfValue {
        BrdfValue {
            single: self.single_lobe().eval(wi, wo).0,
            multi: self.added_lobe(wi, wo),
        }
    }

    fn eval_multi(&self, wi: Vec3<f64>, wo: Vec3<f64>, _rng: &mut Rng) -> [f64; 3] {
        self.added_lobe(wi, wo)
    }

    fn sample(&self, wi: Vec3<f64>, u: [f64; 2], _rng: &mut Rng) -> Option<BrdfSample> {
        sample(self.single_lobe(), wi, u, |wo| {
            let (s, m) = (self.single_lobe().eval(wi, wo).0, self.added_lobe(wi, wo));
            [s[0] + m[0], s[1] + m[1], s[2] + m[2]]
        })
    }

    fn pdf(&self, wi: Vec3<f64>, wo: Vec3<f64>) -> f64 {
        pdf(self.single_lobe(), wi, wo)
    }
}

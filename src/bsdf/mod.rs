//! BRDF models: the common interface, one file per model, and the registry of models
//! ([`registry`]: the model names of the command line, what each model can do, and their
//! constructors).
//!
//! Every model is a reflection-only BRDF of a flat sample in the local frame (`z` = normal,
//! `wi` toward the light, `wo` toward the camera; PHYSICS.md "Conventions"). Values are `f` in
//! 1/sr, split into the exact single-bounce part and the part carried by paths of two or more
//! bounces, so that stochastic models spend samples only where they are needed.
//!
//! | model | file | kind |
//! | --- | --- | --- |
//! | `single` | [`single`] | analytic, Walter et al. 2007 |
//! | `fast-msx` | [`fast_msx`] | analytic second bounce, Rosales et al. 2023; not energy conserving, not reciprocal |
//! | `kulla-conty` | [`kulla_conty`] | tabulated energy compensation lobe, Kulla & Conty 2017; reciprocal |
//! | `turquin` | [`turquin`] | tabulated scaling of the single lobe, Turquin 2019; not reciprocal |
//! | `tabulated` | [`tabulated`] | `heitz`'s multiple-bounce lobe tabulated by order (Heitz et al. 2016), Fresnel per order from the walks' measured vertex cosines; reciprocal |
//! | `bitterli` | [`bitterli`] | stochastic, position-free, unbiased; Bitterli & d'Eon 2022 |
//! | `cui` | [`cui`] | stochastic, position-free, unbiased; Cui et al. 2023 |
//! | `heitz` | [`heitz`] | stochastic random walk with explicit heights, Heitz et al. 2016 (the reference) |
//! | `wang-pt`, `wang-bdpt` | [`wang`] | stochastic, position-free path integral, Wang et al. 2022 |

pub mod albedo_table;
pub mod bitterli;
pub mod bounce_tails;
#[cfg(test)]
mod compensation_tests;
pub mod cui;
pub mod fast_msx;
pub mod heitz;
pub mod kulla_conty;
pub mod lobe_mixture;
mod position_free;
#[cfg(test)]
mod properties;
#[cfg(test)]
mod published_quirks;
pub mod registry;
pub mod roulette;
pub mod single;
pub mod tabulated;
#[cfg(test)]
pub(crate) mod testing;
#[cfg(test)]
mod tests;
pub mod turquin;
pub mod wang;

pub use registry::Model;

use crate::random::Rng;
use crate::scalar::{Real, Rgb, Vec3};

/// Most reflections a path of a stochastic estimator may have (`heitz`, `bitterli`, `cui`,
/// `wang-*`): a walk that would go past it is not continued, so paths of more reflections are
/// dropped from the estimate (a bias of minus their energy). The render plan's `bounce-cap`
/// skip chooses it from [`bounce_tails`]; [`BounceCap::NONE`] leaves every estimator as it is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BounceCap(u32);

impl BounceCap {
    /// No cap beyond each estimator's own safety limit.
    pub const NONE: BounceCap = BounceCap(u32::MAX);

    /// Paths of at most `reflections` reflections (at least 1: the single bounce).
    pub fn at(reflections: u32) -> BounceCap {
        BounceCap(reflections.max(1))
    }

    /// The cap, `None` when there is none.
    pub fn get(self) -> Option<u32> {
        (self != BounceCap::NONE).then_some(self.0)
    }

    /// An estimator's own limit on reflections, lowered to the cap.
    #[inline]
    pub fn limit(self, own: u32) -> u32 {
        own.min(self.0)
    }
}

/// A BRDF value split by path length.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BrdfValue {
    /// Exact single-bounce part, 1/sr.
    pub single: [f64; 3],
    /// Paths of two or more bounces (an estimate for stochastic models), 1/sr.
    pub multi: [f64; 3],
}

impl From<(Rgb<f64>, Rgb<f64>)> for BrdfValue {
    /// The `(single, multi)` split of [`ScalarBrdf::eval_split`].
    fn from((single, multi): (Rgb<f64>, Rgb<f64>)) -> Self {
        BrdfValue {
            single: single.0,
            multi: multi.0,
        }
    }
}

impl BrdfValue {
    pub fn total(&self) -> [f64; 3] {
        [0, 1, 2].map(|c| self.single[c] + self.multi[c])
    }
}

/// An outgoing direction drawn by a model's sampler.
#[derive(Clone, Copy, Debug)]
pub struct BrdfSample {
    pub wo: Vec3<f64>,
    /// `f(wi, wo) * wo.z / pdf(wo)` per channel (for stochastic models an unbiased estimate).
    pub weight: [f64; 3],
    /// Density of `wo` in solid angle (1/sr); for stochastic models the density used for
    /// multiple importance sampling, which each model documents (it may be approximate).
    pub pdf: f64,
    /// Number of microfacet reflections on the sampled path (1 for the single-bounce lobe).
    pub bounces: u32,
}

/// The interface every model implements.
pub trait Brdf: Send + Sync {
    /// `f(wi, wo)` in 1/sr for unit directions above the surface; zero below it. Stochastic
    /// models draw their random numbers from `rng`, analytic models ignore it.
    fn eval(&self, wi: Vec3<f64>, wo: Vec3<f64>, rng: &mut Rng) -> BrdfValue;

    /// The `multi` part of [`Brdf::eval`] alone, from the same random numbers: what the render
    /// plan's anchors and a corrected fit's defect read. Models whose multiple-bounce term does
    /// not need the single lobe's value skip computing it.
    fn eval_multi(&self, wi: Vec3<f64>, wo: Vec3<f64>, rng: &mut Rng) -> [f64; 3] {
        self.eval(wi, wo, rng).multi
    }

    /// Draw `wo` given `wi`. The first two uniform numbers come from `u` (so a caller can
    /// stratify or integrate over them), any further ones from `rng`. `None` when the sampled
    /// path leaves below the horizon or is absorbed.
    fn sample(&self, wi: Vec3<f64>, u: [f64; 2], rng: &mut Rng) -> Option<BrdfSample>;

    /// Density in solid angle with which [`Brdf::sample`] returns `wo`.
    fn pdf(&self, wi: Vec3<f64>, wo: Vec3<f64>) -> f64;

    /// Whether `eval` is a Monte Carlo estimate.
    fn is_stochastic(&self) -> bool {
        false
    }

    /// Whether the weight of [`Brdf::sample`] is a smooth bounded function of `u` (with at most
    /// a kink where `wo` crosses the horizon), so that [`crate::albedo::directional_albedo`]
    /// may integrate it by a product midpoint rule and trust its error estimate. Mixtures are
    /// not: their cosine branch meets a narrow single-bounce peak as a spike the grid can miss
    /// (the stress sweep saw `kulla-conty` at alpha 0.01 come out 1.0040 +- 2e-5 on 128^2
    /// nodes, 0.9998 on 512^2); they are integrated by stratified Monte Carlo.
    fn smooth_sample_weight(&self) -> bool {
        false
    }

    /// `(paths that took a numerical fallback, paths)` since construction, for models that
    /// detect numerically unsafe paths (`bitterli`); `None` for the others.
    fn fallback_stats(&self) -> Option<(u64, u64)> {
        None
    }
}

/// The total value `f(wi, wo)` of a model at scalar type `T`: what the renderer needs. `f64`
/// through any [`Brdf`] object; dual numbers (exact and pathwise derivatives for the fitter)
/// through the models that are generic over the scalar ([`registry::differentiable`]).
pub trait ScalarBrdf<T: Real>: Send + Sync {
    /// `f(wi, wo)` in 1/sr as `(single, multi)`: the single-bounce part and everything the
    /// model adds to it; stochastic models draw from `rng` exactly as [`Brdf::eval`] does, so
    /// every scalar type sees the same paths. `crate::render::plan` evaluates the two parts at
    /// different places, so the split must be the model's own, not a difference of totals.
    fn eval_split(&self, wi: Vec3<T>, wo: Vec3<T>, rng: &mut Rng) -> (Rgb<T>, Rgb<T>);

    /// The `multi` part of [`ScalarBrdf::eval_split`] alone, from the same random numbers
    /// (see [`Brdf::eval_multi`]).
    #[inline]
    fn eval_multi(&self, wi: Vec3<T>, wo: Vec3<T>, rng: &mut Rng) -> Rgb<T> {
        self.eval_split(wi, wo, rng).1
    }

    /// `f(wi, wo)` in 1/sr, the single and multiple-bounce parts together.
    #[inline]
    fn eval_total(&self, wi: Vec3<T>, wo: Vec3<T>, rng: &mut Rng) -> Rgb<T> {
        let (single, multi) = self.eval_split(wi, wo, rng);
        single + multi
    }
}

impl ScalarBrdf<f64> for dyn Brdf {
    #[inline]
    fn eval_split(&self, wi: Vec3<f64>, wo: Vec3<f64>, rng: &mut Rng) -> (Rgb<f64>, Rgb<f64>) {
        let value = self.eval(wi, wo, rng);
        (Rgb(value.single), Rgb(value.multi))
    }

    #[inline]
    fn eval_multi(&self, wi: Vec3<f64>, wo: Vec3<f64>, rng: &mut Rng) -> Rgb<f64> {
        Rgb(Brdf::eval_multi(self, wi, wo, rng))
    }

    #[inline]
    fn eval_total(&self, wi: Vec3<f64>, wo: Vec3<f64>, rng: &mut Rng) -> Rgb<f64> {
        Rgb(self.eval(wi, wo, rng).total())
    }
}

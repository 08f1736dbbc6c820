//! One Monte Carlo sample of the radiance a surface point reflects toward the camera,
//! `L_o(wo) = integral (f(wi, wo) + diffuse / pi) L_i(wi) cos(wi) dwi`, under an environment or
//! one light of a photo set's kinds.
//!
//! The value of the material is always the texel's own `eval` ([`TexelLobe::value`]), the
//! estimator the renderer uses, so stochastic models (`heitz`, `bitterli`, ...) enter with the
//! same unbiased estimate as in a fit. Directions below the geometric surface (`wi.z <= 0` in
//! tangent space) carry no light: the object shadows itself (a sphere and a plane are the only
//! objects, and both are convex), and a normal map's frame is treated as in
//! [`crate::maps::render`].
//!
//! Under an environment, each sample draws one direction from the environment
//! ([`Environment::sample`]) and, with [`Sampling::Mis`], one from the material, and weights
//! the two by the power heuristic (beta = 2) of multiple importance sampling (Veach 1997,
//! "Robust Monte Carlo Methods for Light Transport Simulation", ch. 9). The material's technique is the one-sample
//! mixture of [`lobe_mixture`]: the visible-normal lobe of the texel's single bounce (Heitz
//! 2018) and the cosine lobe, whose density is exact for every model. The models' own samplers
//! ([`crate::bsdf::Brdf::sample`]) are not used: the stochastic models report only an
//! approximate density for them (see `heitz`, `bitterli`, `cui`, `wang`), and an estimate that
//! divides the model's `eval` by the density of the technique that drew the direction needs the
//! exact one; the mixture's cosine branch also samples the diffuse layer, which no model's
//! sampler knows of. Any pair of densities gives an unbiased estimate, since the two weights
//! of a direction sum to one.

use super::environment::Environment;
use super::geometry::{SurfacePoint, VIEW};
use crate::bsdf::lobe_mixture;
use crate::capture::Light;
use crate::maps::lobe::TexelLobe;
use crate::random::Rng;
use crate::scalar::Vec3;
use glam::DVec3;
use rand::Rng as _;

/// How directions are drawn under an environment.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Sampling {
    /// From the environment and from the material, combined by the power heuristic.
    Mis,
    /// From the environment alone (a reference for the tests; noisy on smooth samples).
    Light,
}

/// The light of one frame.
#[derive(Clone, Debug)]
pub enum Lighting<'a> {
    /// `env` turned about `+z` by `turn`.
    Environment {
        env: &'a Environment,
        turn: Turn,
        sampling: Sampling,
    },
    /// A light of a photo set's kind; `camera` is where a flash sits.
    Light { light: Light, camera: DVec3 },
}

impl Lighting<'_> {
    /// One sample of the radiance `point` reflects toward the camera ([`VIEW`]) when it shows
    /// the texel `lobe`; random numbers come from `rng`.
    pub fn sample(&self, point: &SurfacePoint, lobe: &TexelLobe, rng: &mut Rng) -> [f64; 3] {
        let wo = point.frame.local(VIEW);
        if wo.z <= 0.0 {
            return [0.0; 3];
        }
        match self {
            Lighting::Environment {
                env,
                turn,
                sampling,
            } => environment(env, *turn, *sampling, point, lobe, wo, rng),
            Lighting::Light { light, camera } => {
                let arriving = light.perpendicular(*camera, point.position);
                let wi = point.frame.local(Vec3::from_f64(arriving.wi.to_array()));
                match seen(lobe, wi, wo) {
                    Some((i, o)) => {
                        let f = lobe.value(i, o, rng);
                        std::array::from_fn(|c| f[c] * i.z * arriving.irradiance[c])
                    }
                    None => [0.0; 3],
                }
            }
        }
    }
}

/// Tangent-space `wi`, `wo` in the texel's shading frame, `None` where `wi` lies below the
/// surface or either direction below the shading normal's horizon.
fn seen(lobe: &TexelLobe, wi: Vec3<f64>, wo: Vec3<f64>) -> Option<(Vec3<f64>, Vec3<f64>)> {
    if wi.z <= 0.0 {
        return None;
    }
    lobe.local(wi, wo)
}

/// A rotation about `+z`, counter-clockwise seen from above.
#[derive(Clone, Copy, Debug)]
pub struct Turn {
    sin: f64,
    cos: f64,
}

impl Turn {
    /// The rotation by `angle` radians.
    pub fn by(angle: f64) -> Turn {
        let (sin, cos) = angle.sin_cos();
        Turn { sin, cos }
    }

    /// `w` turned.
    fn apply(self, w: Vec3<f64>) -> Vec3<f64> {
        Vec3::new(
            w.x * self.cos - w.y * self.sin,
            w.x * self.sin + w.y * self.cos,
            w.z,
        )
    }

    /// `w` turned back (the inverse of [`Turn::apply`]).
    fn undo(self, w: Vec3<f64>) -> Vec3<f64> {
        Vec3::new(
            w.x * self.cos + w.y * self.sin,
            w.y * self.cos - w.x * self.sin,
            w.z,
        )
    }
}

/// The power heuristic's weight (beta = 2) of a technique of density `this` against one of
/// density `other` (Veach 1997, ch. 9).
fn power_heuristic(this: f64, other: f64) -> f64 {
    let (a, b) = (this * this, other * other);
    if a.is_infinite() {
        1.0
    } else if a + b > 0.0 {
        a / (a + b)
    } else {
        0.0
    }
}

/// One sample under `env` turned by `turn`, toward the tangent-space view `wo`.
fn environment(
    env: &Environment,
    turn: Turn,
    sampling: Sampling,
    point: &SurfacePoint,
    lobe: &TexelLobe,
    wo: Vec3<f64>,
    rng: &mut Rng,
) -> [f64; 3] {
    let mut sum = [0.0; 3];
    let mut add = |f: [f64; 3], radiance: [f64; 3], factor: f64| {
        for c in 0..3 {
            sum[c] += f[c] * radiance[c] * factor;
        }
    };
    // The environment's technique.
    let xi = [rng.random(), rng.random()];
    if let Some(light) = env.sample(xi) {
        let wi = point.frame.local(turn.apply(light.direction));
        if let Some((i, o)) = seen(lobe, wi, wo) {
            let weight = match sampling {
                Sampling::Mis => power_heuristic(light.pdf, lobe_mixture::pdf(&lobe.single, o, i)),
                Sampling::Light => 1.0,
            };
            let f = lobe.value(i, o, rng);
            add(f, light.radiance, i.z * weight / light.pdf);
        }
    }
    // The material's technique: the mixture draws wi given the view, weighted f(wi, wo) cos / pdf.
    let o = lobe.shading(wo);
    if sampling == Sampling::Mis && o.z > 0.0 {
        let xi = [rng.random(), rng.random()];
        let drawn = lobe_mixture::sample(&lobe.single, o, xi, |i| lobe.value(i, o, rng));
        if let Some(drawn) = drawn {
            let wi = lobe.tangent(drawn.wo);
            if wi.z > 0.0 {
                let w = turn.undo(point.frame.tangent(wi));
                let weight = power_heuristic(drawn.pdf, env.pdf(w));
                add(drawn.weight, env.radiance(w), weight);
            }
        }
    }
    sum
}

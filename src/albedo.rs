//! Directional albedo `E(wi) = integral f(wi, wo) wo.z dwo` of any model, through its sampler.
//!
//! The integral is taken over the sampler's unit square: `E = integral weight(u) du` where
//! `weight = f cos / pdf` of the direction drawn from `u`. Where the weight is a smooth bounded
//! function of `u` ([`Brdf::smooth_sample_weight`]; `single`: `F G2 / G1(wi)`, between 0 and 1,
//! smooth but for a kink where `wo` crosses the horizon) a product midpoint rule (after a
//! smoothstep change of variable) converges at every roughness, however peaked the lobe; the
//! error reported for it is the difference to the same rule on a grid half as fine per axis
//! (a conservative estimate of the error of the fine grid). Stochastic models and the lobe
//! mixtures of the compensation models use jittered stratification of the first two dimensions
//! and report the standard error of the mean (computed as for independent samples, which
//! over-estimates it under stratification). [`mean_value`] is the plain mean of repeated
//! evaluations at one pair of directions, the estimate the stress sweep and the bench compare.

use crate::bsdf::Brdf;
use crate::random::{rng_stream, Estimate, Moments, Rng};
use crate::scalar::Vec3;
use rand::Rng as _;
use rayon::prelude::*;

/// Mean of `n` evaluations of `f(wi, wo)` per channel, with the standard error of that mean
/// ([`Moments`]; infinite for `n < 2`): a stochastic model's estimate of its value at one pair
/// of directions, or an analytic model's value ([`Estimate::exact`]).
pub fn mean_value(
    brdf: &dyn Brdf,
    wi: Vec3<f64>,
    wo: Vec3<f64>,
    n: usize,
    rng: &mut Rng,
) -> Estimate {
    let mut moments = Moments::default();
    for _ in 0..n {
        moments.push(brdf.eval(wi, wo, rng).total());
    }
    if brdf.is_stochastic() {
        moments.estimate()
    } else {
        Estimate::exact(moments.mean(), n)
    }
}

/// Directional albedo of `brdf` for the unit direction `wi`, with about `samples` evaluations.
pub fn directional_albedo(brdf: &dyn Brdf, wi: Vec3<f64>, samples: usize, seed: u64) -> Estimate {
    let n = (samples.max(4) as f64).sqrt().ceil() as usize;
    if brdf.is_stochastic() || !brdf.smooth_sample_weight() {
        stratified_monte_carlo(brdf, wi, n, seed)
    } else {
        let fine = midpoint_grid(brdf, wi, n, seed);
        let coarse = midpoint_grid(brdf, wi, n.div_ceil(2), seed);
        Estimate {
            value: fine,
            stderr: [0, 1, 2].map(|c| (fine[c] - coarse[c]).abs()),
            samples: n * n,
        }
    }
}

/// Smoothstep change of variable `u = t^2 (3 - 2t)` and its Jacobian `6 t (1 - t)`: clusters
/// nodes at both ends of each axis, where samplers put grazing normals (GGX: `r = sqrt(u)`)
/// and where the weight has its kink (`wo` crossing the horizon).
fn smoothstep(t: f64) -> (f64, f64) {
    (t * t * (3.0 - 2.0 * t), 6.0 * t * (1.0 - t))
}

fn midpoint_grid(brdf: &dyn Brdf, wi: Vec3<f64>, n: usize, seed: u64) -> [f64; 3] {
    let rows: Vec<[f64; 3]> = (0..n)
        .into_par_iter()
        .map(|j| {
            let mut rng = rng_stream(seed, j as u64);
            let mut sum = [0.0; 3];
            let (u1, jac1) = smoothstep((j as f64 + 0.5) / n as f64);
            for i in 0..n {
                let (u0, jac0) = smoothstep((i as f64 + 0.5) / n as f64);
                if let Some(s) = brdf.sample(wi, [u0, u1], &mut rng) {
                    (0..3).for_each(|c| sum[c] += s.weight[c] * jac0 * jac1);
                }
            }
            sum
        })
        .collect();
    let total = (n * n) as f64;
    [0, 1, 2].map(|c| rows.iter().map(|r| r[c]).sum::<f64>() / total)
}

fn stratified_monte_carlo(brdf: &dyn Brdf, wi: Vec3<f64>, n: usize, seed: u64) -> Estimate {
    let rows: Vec<Moments<3>> = (0..n)
        .into_par_iter()
        .map(|j| {
            let mut rng = rng_stream(seed, j as u64);
            let mut row = Moments::default();
            for i in 0..n {
                let u = [
                    (i as f64 + rng.random::<f64>()) / n as f64,
                    (j as f64 + rng.random::<f64>()) / n as f64,
                ];
                // A direction the sampler cannot draw weighs 0.
                row.push(brdf.sample(wi, u, &mut rng).map_or([0.0; 3], |s| s.weight));
            }
            row
        })
        .collect();
    let mut all = Moments::default();
    rows.iter().for_each(|row| all.merge(row));
    all.estimate()
}

/// The adjoint of a BRDF, `f*(a, b) = f(b, a)` (Veach 1997, sec. 3.7.5). The albedo of a
/// non-reciprocal model toward a fixed view direction, `integral f(wi, wo) wi.z dwi`, is the
/// [`directional_albedo`] of its adjoint at `wo`. Directions are drawn with the model's own
/// sampler at the fixed direction and weighted by the swapped value, so the estimate stays
/// unbiased wherever that sampler covers the adjoint's support.
pub struct Adjoint<'a>(pub &'a dyn Brdf);

impl Brdf for Adjoint<'_> {
    fn eval(&self, wi: Vec3<f64>, wo: Vec3<f64>, rng: &mut Rng) -> crate::bsdf::BrdfValue {
        self.0.eval(wo, wi, rng)
    }
    fn sample(&self, wi: Vec3<f64>, u: [f64; 2], rng: &mut Rng) -> Option<crate::bsdf::BrdfSample> {
        let s = self.0.sample(wi, u, rng).filter(|s| s.pdf > 0.0)?;
        let f = self.0.eval(s.wo, wi, rng).total();
        Some(crate::bsdf::BrdfSample {
            weight: f.map(|v| v * s.wo.z / s.pdf),
            ..s
        })
    }
    fn pdf(&self, wi: Vec3<f64>, wo: Vec3<f64>) -> f64 {
        self.0.pdf(wi, wo)
    }
    fn is_stochastic(&self) -> bool {
        self.0.is_stochastic()
    }
    /// Reciprocal smooth models keep their weights under the swap.
    fn smooth_sample_weight(&self) -> bool {
        self.0.smooth_sample_weight()
    }
}

/// Directional albedo split by path length: `[bounce 1, bounce 2, bounce 3, bounces 4+]` per
/// channel, from the sampler's bounce counts. Models without path structure (analytic
/// compensation lobes, `bounces == 0`) are split through `eval` into the exact single-bounce part
/// (column 1) and everything else (column 2, with `resolved = false`).
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct BounceEnergy {
    pub by_bounce: [[f64; 3]; 4],
    pub resolved: bool,
    pub samples: usize,
}

pub fn albedo_by_bounce(brdf: &dyn Brdf, wi: Vec3<f64>, samples: usize, seed: u64) -> BounceEnergy {
    let moments = bounce_moments(brdf, wi, samples, seed, 4);
    BounceEnergy {
        by_bounce: std::array::from_fn(|k| moments.mean[k]),
        resolved: moments.resolved,
        samples: moments.samples,
    }
}

/// First and second moments of the sampled weight split by bounce count: column `k` holds the
/// paths of `k + 1` bounces, the last column every longer path too (split as in
/// [`albedo_by_bounce`], which is this with 4 columns). A path falls in exactly one column, so
/// the energy of any set of columns is the sum of their means and the per-sample second moment
/// of that sum is the sum of their `mean_square`s.
#[derive(Clone, Debug)]
pub struct BounceMoments {
    pub mean: Vec<[f64; 3]>,
    pub mean_square: Vec<[f64; 3]>,
    pub resolved: bool,
    pub samples: usize,
}

pub fn bounce_moments(
    brdf: &dyn Brdf,
    wi: Vec3<f64>,
    samples: usize,
    seed: u64,
    columns: usize,
) -> BounceMoments {
    let n = (samples.max(4) as f64).sqrt().ceil() as usize;
    let columns = columns.max(2);
    // Per row of the stratification: sums (not yet means) of the weights and their squares.
    let rows: Vec<BounceMoments> = (0..n)
        .into_par_iter()
        .map(|j| {
            let mut rng = rng_stream(seed, j as u64);
            let (mut acc, mut acc2) = (vec![[0.0; 3]; columns], vec![[0.0; 3]; columns]);
            let mut add = |k: usize, c: usize, w: f64| {
                acc[k][c] += w;
                acc2[k][c] += w * w;
            };
            let mut resolved = true;
            for i in 0..n {
                let u = [
                    (i as f64 + rng.random::<f64>()) / n as f64,
                    (j as f64 + rng.random::<f64>()) / n as f64,
                ];
                let Some(s) = brdf.sample(wi, u, &mut rng) else {
                    continue;
                };
                if s.bounces == 0 {
                    resolved = false;
                    let v = brdf.eval(wi, s.wo, &mut rng);
                    let scale = s.wo.z / s.pdf;
                    for (c, (single, multi)) in v.single.iter().zip(&v.multi).enumerate() {
                        add(0, c, single * scale);
                        add(1, c, multi * scale);
                    }
                } else {
                    let k = (s.bounces as usize).min(columns) - 1;
                    (0..3).for_each(|c| add(k, c, s.weight[c]));
                }
            }
            BounceMoments {
                mean: acc,
                mean_square: acc2,
                resolved,
                samples: n,
            }
        })
        .collect();
    let total = (n * n) as f64;
    let mut mean = vec![[0.0; 3]; columns];
    let mut mean_square = vec![[0.0; 3]; columns];
    for row in &rows {
        for k in 0..columns {
            for c in 0..3 {
                mean[k][c] += row.mean[k][c] / total;
                mean_square[k][c] += row.mean_square[k][c] / total;
            }
        }
    }
    BounceMoments {
        mean,
        mean_square,
        resolved: rows.iter().all(|r| r.resolved),
        samples: n * n,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bsdf::turquin::Turquin;
    use crate::bsdf::Model;
    use crate::material::{FresnelSpec, Material};
    use crate::microfacet::{Height, NdfKind};

    fn material(model: Model, alpha: f64) -> Material {
        Material {
            model,
            ndf: NdfKind::Ggx,
            height: Height::Correlated,
            alpha: [alpha; 2],
            fresnel: FresnelSpec::White,
            diffuse: [0.0; 3],
        }
    }

    /// For a reciprocal model the adjoint's sampled weights are the model's own: both albedos
    /// agree to rounding, so a wrong cosine or density in the reweighting would show.
    #[test]
    fn adjoint_of_a_reciprocal_model_has_the_same_albedo() {
        let brdf = material(Model::KullaConty, 0.6).brdf();
        for theta in [0.0f64, 50.0, 85.0] {
            let wi = Vec3::new(theta.to_radians().sin(), 0.0, theta.to_radians().cos());
            let forward = directional_albedo(brdf.as_ref(), wi, 4096, 3).value[0];
            let adjoint = directional_albedo(&Adjoint(brdf.as_ref()), wi, 4096, 3).value[0];
            assert!(
                (forward - adjoint).abs() < 1e-9 * forward,
                "theta {theta}: {forward} vs {adjoint}"
            );
        }
    }

    /// Turquin 2019 conserves white energy toward a fixed view (eq. 6-7), not from a fixed light:
    /// the adjoint albedo is 1 up to the table (< 1%), the forward one is far above 1 at grazing.
    #[test]
    fn adjoint_albedo_is_the_one_turquin_conserves() {
        let m = material(Model::Turquin, 1.5);
        let turquin = Turquin::new(m.single::<f64>());
        let wo = Vec3::new(80f64.to_radians().sin(), 0.0, 80f64.to_radians().cos());
        let toward_view = directional_albedo(&Adjoint(&turquin), wo, 16_384, 5);
        let from_light = directional_albedo(&turquin, wo, 16_384, 5);
        assert!((toward_view.value[0] - 1.0).abs() < 0.01, "{toward_view:?}");
        assert!(from_light.value[0] > 1.2, "{from_light:?}");
    }
}

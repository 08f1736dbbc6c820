//! Directional albedo `E(wi) = integral f(wi, wo) wo.z dwo` of any model, through its sampler.
//!
//! The integral is taken over the sampler's unit square: `E = integral weight(u) du` where
//! `weight = f cos / pdf` of the direction drawn from `u`. For the analytic models the weight is
//! a bounded function of `u` (for `single`: `F G2 / G1(wi)`, between 0 and 1), smooth but for a
//! kink where `wo` crosses the horizon, so a product midpoint rule (after a smoothstep change
//! of variable) converges at every roughness, however peaked the lobe; the error
//! reported for it is the difference to the same rule on a grid half as fine per axis
//! (a conservative estimate of the error of the fine grid). Stochastic models use jittered
//! stratification of the first two dimensions and report the standard error of the mean
//! (computed as for independent samples, which over-estimates it under stratification).

use crate::bsdf::{Brdf, Rng};
use crate::scalar::Vec3;
use rand::{Rng as _, SeedableRng};
use rayon::prelude::*;

/// A value per channel with its error bar.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Estimate {
    pub value: [f64; 3],
    /// Standard error of the mean (stochastic models) or quadrature error estimate (analytic).
    pub stderr: [f64; 3],
    pub samples: usize,
}

/// Independent random stream `stream` of the run seeded by `seed`, the same whatever the thread
/// count (SplitMix64 finaliser of the pair, Steele et al. 2014).
pub fn rng_stream(seed: u64, stream: u64) -> Rng {
    let mut z = seed ^ stream.wrapping_add(1).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    Rng::seed_from_u64(z ^ (z >> 31))
}

/// Directional albedo of `brdf` for the unit direction `wi`, with about `samples` evaluations.
pub fn directional_albedo(brdf: &dyn Brdf, wi: Vec3<f64>, samples: usize, seed: u64) -> Estimate {
    let n = (samples.max(4) as f64).sqrt().ceil() as usize;
    if brdf.is_stochastic() {
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
    let rows: Vec<([f64; 3], [f64; 3])> = (0..n)
        .into_par_iter()
        .map(|j| {
            let mut rng = rng_stream(seed, j as u64);
            let (mut sum, mut sum2) = ([0.0; 3], [0.0; 3]);
            for i in 0..n {
                let u = [
                    (i as f64 + rng.random::<f64>()) / n as f64,
                    (j as f64 + rng.random::<f64>()) / n as f64,
                ];
                if let Some(s) = brdf.sample(wi, u, &mut rng) {
                    for c in 0..3 {
                        sum[c] += s.weight[c];
                        sum2[c] += s.weight[c] * s.weight[c];
                    }
                }
            }
            (sum, sum2)
        })
        .collect();
    let total = (n * n) as f64;
    let mean = [0, 1, 2].map(|c| rows.iter().map(|r| r.0[c]).sum::<f64>() / total);
    let stderr = [0, 1, 2].map(|c| {
        let m2 = rows.iter().map(|r| r.1[c]).sum::<f64>() / total;
        ((m2 - mean[c] * mean[c]).max(0.0) / (total - 1.0)).sqrt()
    });
    Estimate {
        value: mean,
        stderr,
        samples: n * n,
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
    let n = (samples.max(4) as f64).sqrt().ceil() as usize;
    let rows: Vec<([[f64; 3]; 4], bool)> = (0..n)
        .into_par_iter()
        .map(|j| {
            let mut rng = rng_stream(seed, j as u64);
            let mut acc = [[0.0; 3]; 4];
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
                        acc[0][c] += single * scale;
                        acc[1][c] += multi * scale;
                    }
                } else {
                    let k = (s.bounces as usize).min(4) - 1;
                    (0..3).for_each(|c| acc[k][c] += s.weight[c]);
                }
            }
            (acc, resolved)
        })
        .collect();
    let total = (n * n) as f64;
    let mut by_bounce = [[0.0; 3]; 4];
    for (acc, _) in &rows {
        for k in 0..4 {
            for c in 0..3 {
                by_bounce[k][c] += acc[k][c] / total;
            }
        }
    }
    BounceEnergy {
        by_bounce,
        resolved: rows.iter().all(|r| r.1),
        samples: n * n,
    }
}

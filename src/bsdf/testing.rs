//! Statistical checks that every model must pass, shared by the models' test modules:
//! white furnace (through the sampler and through evaluation), reciprocity, agreement of two
//! estimators, sampler against evaluation by histogram, and finiteness over random queries.
//!
//! Every Monte Carlo comparison is a z-score against the *measured* standard errors of both
//! sides (`|a - b| / sqrt(se_a^2 + se_b^2)`), with a fixed seed, so a test fails on a biased
//! estimator and never on an unlucky run.

use super::single::SingleBounce;
use super::Brdf;

use crate::albedo::{directional_albedo, mean_value};

use crate::material::{FresnelSpec, Material};
use crate::microfacet::{Height, Microfacet, NdfKind};
use crate::random::{rng_stream, Estimate, Moments, Rng};
use crate::scalar::Vec3;
use rand::Rng as _;
use std::f64::consts::{FRAC_1_PI, PI};

/// Measured copper (Johnson & Christy 1972 at 650, 550, 450 nm, from `shared/data/conductors_nk.json`),
/// the conductor of the agreement and reciprocity tests.
pub const COPPER: FresnelSpec = FresnelSpec::Conductor {
    eta: [0.2378, 1.0066, 1.2404],
    k: [3.6264, 2.5823, 2.3929],
};

/// Unit direction from polar angles in degrees.
pub fn unit(theta_deg: f64, phi_deg: f64) -> Vec3<f64> {
    let (t, p) = (theta_deg.to_radians(), phi_deg.to_radians());
    Vec3::new(t.sin() * p.cos(), t.sin() * p.sin(), t.cos())
}

/// A random unit direction above the surface, cosine-distributed (never exactly grazing).
pub fn random_upper(rng: &mut Rng) -> Vec3<f64> {
    let (u, v): (f64, f64) = (rng.random(), rng.random());
    let r = u.sqrt();
    let phi = 2.0 * PI * v;
    Vec3::new(r * phi.cos(), r * phi.sin(), (1.0 - u).max(1e-6).sqrt())
}

/// The material of `model` on isotropic GGX at roughness `alpha`, correlated heights, no
/// diffuse layer.
pub fn ggx_material(model: super::Model, alpha: f64, fresnel: FresnelSpec) -> Material {
    Material {
        model,
        ndf: NdfKind::Ggx,
        height: Height::Correlated,
        alpha: [alpha, alpha],
        fresnel,
        diffuse: [0.0; 3],
    }
}

/// Mean of `n` independent evaluations of `f(wi, wo)` with its standard error ([`mean_value`]).
pub fn mean_eval(brdf: &dyn Brdf, wi: Vec3<f64>, wo: Vec3<f64>, n: usize, seed: u64) -> Estimate {
    mean_value(brdf, wi, wo, n, &mut rng_stream(seed, 0))
}

/// z-score of the difference of two estimates in channel `c` (0 when both are exact and equal).
pub fn z_score(a: &Estimate, b: &Estimate, c: usize) -> f64 {
    let diff = (a.value[c] - b.value[c]).abs();
    let se = (a.stderr[c].powi(2) + b.stderr[c].powi(2)).sqrt();
    if diff <= 1e-12 * a.value[c].abs().max(b.value[c].abs()) {
        0.0
    } else {
        diff / se
    }
}

/// Directional albedo through the model's own sampler (mean sample weight).
pub fn albedo_by_sampling(brdf: &dyn Brdf, wi: Vec3<f64>, n: usize, seed: u64) -> Estimate {
    directional_albedo(brdf, wi, n, seed)
}

/// Directional albedo through evaluation only: `integral f cos dwo` with `wo` drawn by one-sample
/// MIS from the visible-normal lobe of `guide` (the single-bounce model of the same surface,
/// whose sampler is tested separately) and from the cosine distribution, both with exact
/// densities. Independent of the model's sampler, so it checks `eval`.
pub fn albedo_by_eval(
    brdf: &dyn Brdf,
    guide: &SingleBounce<f64>,
    wi: Vec3<f64>,
    n: usize,
    seed: u64,
) -> Estimate {
    let mut rng = rng_stream(seed, 1);
    let mut stats = Moments::default();
    for _ in 0..n {
        let u = [rng.random(), rng.random()];
        let drawn = if rng.random::<f64>() < 0.5 {
            guide.sample_weighted(wi, u).map(|(wo, _)| wo)
        } else {
            let r = u[0].sqrt();
            let phi = 2.0 * PI * u[1];
            Some(Vec3::new(
                r * phi.cos(),
                r * phi.sin(),
                (1.0 - u[0]).max(0.0).sqrt(),
            ))
        };
        // A draw below the horizon contributes zero (it still counts in the mean).
        let value = match drawn.filter(|wo| wo.z > 0.0) {
            Some(wo) => {
                let pdf = 0.5 * guide.pdf(wi, wo) + 0.5 * wo.z * FRAC_1_PI;
                brdf.eval(wi, wo, &mut rng).total().map(|f| f * wo.z / pdf)
            }
            None => [0.0; 3],
        };
        stats.push(value);
    }
    stats.estimate()
}

/// Upper-tail standard normal deviate of a chi-square statistic (Wilson-Hilferty).
pub fn chi_square_z(chi2: f64, dof: f64) -> f64 {
    let k = 2.0 / (9.0 * dof);
    ((chi2 / dof).cbrt() - (1.0 - k)) / k.sqrt()
}

/// Sampler against evaluation: the histogram of sampled `wo` weighted by the returned weight
/// (channel 0) must match `integral_bin f cos` estimated from `eval` at stratified points, bin by
/// bin within their joint standard error. Bins are equal-solid-angle cells in (cos theta, phi).
/// Returns the chi-square z statistic over bins.
pub fn sampler_matches_eval(
    brdf: &dyn Brdf,
    wi: Vec3<f64>,
    samples: usize,
    points_per_bin: usize,
    seed: u64,
) -> f64 {
    let (n_cos, n_phi) = (8usize, 16usize);
    let bins = n_cos * n_phi;
    let bin_of = |w: Vec3<f64>| {
        let i = ((w.z * n_cos as f64) as usize).min(n_cos - 1);
        let j = ((w.y.atan2(w.x).rem_euclid(2.0 * PI) / (2.0 * PI) * n_phi as f64) as usize)
            .min(n_phi - 1);
        i * n_phi + j
    };
    let mut rng = rng_stream(seed, 2);
    let (mut hist, mut hist2, mut counts) = (vec![0.0; bins], vec![0.0; bins], vec![0usize; bins]);
    for _ in 0..samples {
        if let Some(s) = brdf.sample(wi, [rng.random(), rng.random()], &mut rng) {
            if s.wo.z > 0.0 {
                let b = bin_of(s.wo);
                hist[b] += s.weight[0];
                hist2[b] += s.weight[0] * s.weight[0];
                counts[b] += 1;
            }
        }
    }
    let total_count: usize = counts.iter().sum();
    let mean_weight = hist.iter().sum::<f64>() / total_count.max(1) as f64;
    let bin_area = 2.0 * PI / bins as f64;
    let side = (points_per_bin as f64).sqrt().ceil() as usize;
    let mut chi2 = 0.0;
    for b in 0..bins {
        let n = samples as f64;
        let mean_s = hist[b] / n;
        let var_s = (hist2[b] / n - mean_s * mean_s).max(0.0) / n;
        let (i, j) = (b / n_phi, b % n_phi);
        let (mut sum, mut sum2) = (0.0, 0.0);
        for q in 0..side * side {
            let (a, c) = ((q / side) as f64, (q % side) as f64);
            let z = (i as f64 + (a + rng.random::<f64>()) / side as f64) / n_cos as f64;
            let phi =
                2.0 * PI * (j as f64 + (c + rng.random::<f64>()) / side as f64) / n_phi as f64;
            let r = (1.0 - z * z).max(0.0).sqrt();
            let wo = Vec3::new(r * phi.cos(), r * phi.sin(), z);
            let v = brdf.eval(wi, wo, &mut rng).total()[0] * z * bin_area;
            sum += v;
            sum2 += v * v;
        }
        let m = (side * side) as f64;
        let mean_e = sum / m;
        let var_e = (sum2 / m - mean_e * mean_e).max(0.0) / m;
        // A bin the sampler rarely reaches has a sample variance near zero by chance: floor it
        // at the Poisson variance of a mean built from N * mean_e / w draws of weight w
        // (w: the bin's mean weight, or the overall mean weight if the bin is empty).
        let w_ref = if counts[b] > 0 {
            hist[b] / counts[b] as f64
        } else {
            mean_weight
        };
        let var_s = var_s.max(mean_e.max(0.0) * w_ref / n);
        let var = var_s + var_e;
        if var > 0.0 {
            chi2 += (mean_s - mean_e).powi(2) / var;
        } else {
            assert!(
                (mean_s - mean_e).abs() < 1e-12,
                "bin {b}: sampler {mean_s} vs eval {mean_e} with zero variance"
            );
        }
    }
    chi_square_z(chi2, bins as f64)
}

/// Assert that `eval` and `sample` give finite, non-negative values for `queries` random
/// configurations drawn by `configure` (which picks roughness, Fresnel and so on from `rng`).
pub fn assert_finite_sweep(
    configure: impl Fn(&mut Rng) -> Box<dyn Brdf>,
    queries: usize,
    seed: u64,
) {
    let mut rng = rng_stream(seed, 3);
    let per_model = 100;
    for _ in 0..queries.div_ceil(per_model) {
        let brdf = configure(&mut rng);
        for k in 0..per_model {
            // Every tenth query is at a grazing angle (89.99 degrees or closer).
            let grazing = |rng: &mut Rng| {
                let phi: f64 = rng.random::<f64>() * 2.0 * PI;
                let z: f64 = rng.random::<f64>() * 1.7e-4 + 1e-12;
                let r = (1.0 - z * z).sqrt();
                Vec3::new(r * phi.cos(), r * phi.sin(), z)
            };
            let wi = if k % 10 == 0 {
                grazing(&mut rng)
            } else {
                random_upper(&mut rng)
            };
            let wo = if k % 10 == 5 {
                grazing(&mut rng)
            } else {
                random_upper(&mut rng)
            };
            let v = brdf.eval(wi, wo, &mut rng);
            let ok = |x: &[f64; 3]| x.iter().all(|c| c.is_finite() && *c >= 0.0);
            assert!(
                ok(&v.single) && ok(&v.multi),
                "eval at {wi:?} {wo:?}: {v:?}"
            );
            if let Some(s) = brdf.sample(wi, [rng.random(), rng.random()], &mut rng) {
                assert!(
                    ok(&s.weight) && s.pdf.is_finite() && s.pdf >= 0.0,
                    "sample at {wi:?}: {s:?}"
                );
                assert!(
                    s.wo.re().iter().all(|c| c.is_finite()) && (s.wo.length() - 1.0).abs() < 1e-6,
                    "sample direction {s:?}"
                );
            }
        }
    }
}

/// A random surface for the finite sweeps (the ranges the issues name): roughness log-uniform in
/// [1e-4, 3], anisotropy ratio log-uniform in [1, 100] along x or y, GGX or Beckmann, conductor
/// eta in [0.01, 10] and k in [0, 20] drawn per channel.
pub fn random_surface(rng: &mut Rng) -> (Microfacet<f64>, FresnelSpec) {
    let a = 10f64.powf(rng.random_range(-4.0..0.48));
    let ndf = if rng.random::<bool>() {
        NdfKind::Ggx
    } else {
        NdfKind::Beckmann
    };
    let ratio = 10f64.powf(rng.random_range(-2.0..0.0));
    let (ax, ay) = if rng.random::<bool>() {
        (a, a * ratio)
    } else {
        (a * ratio, a)
    };
    let eta = [0; 3].map(|_| rng.random_range(0.01..10.0));
    let k = [0; 3].map(|_| rng.random_range(0.0..20.0));
    (
        Microfacet::new(ndf, ax, ay),
        FresnelSpec::Conductor { eta, k },
    )
}

/// `n` random configurations `(alpha, wi, wo)` for agreement and reciprocity tests.
pub fn random_configurations(n: usize, seed: u64) -> Vec<(f64, Vec3<f64>, Vec3<f64>)> {
    let mut rng = rng_stream(seed, 4);
    (0..n)
        .map(|_| {
            (
                rng.random_range(0.1..1.5),
                random_upper(&mut rng),
                random_upper(&mut rng),
            )
        })
        .collect()
}

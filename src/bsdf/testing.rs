//! Statistical checks that every model must pass, shared by the models' test modules:
//! white furnace (through the sampler and through evaluation), reciprocity, agreement of two
//! estimators, sampler against evaluation by histogram, and finiteness over random queries.
//!
//! Every Monte Carlo comparison is a z-score against the *measured* standard errors of both
//! sides (`|a - b| / sqrt(se_a^2 + se_b^2)`), with a fixed seed, so a test fails on a biased
//! estimator and never on an unlucky run.

use super::single::SingleBounce;
use super::{Brdf, Rng};
use crate::albedo::{directional_albedo, rng_stream, Estimate};
use crate::scalar::Vec3;
use rand::Rng as _;
use std::f64::consts::{FRAC_1_PI, PI};

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

/// Mean of `n` independent evaluations of `f(wi, wo)` with its standard error.
pub fn mean_eval(brdf: &dyn Brdf, wi: Vec3<f64>, wo: Vec3<f64>, n: usize, seed: u64) -> Estimate {
    let mut rng = rng_stream(seed, 0);
    let (mut sum, mut sum2) = ([0.0; 3], [0.0; 3]);
    for _ in 0..n {
        let f = brdf.eval(wi, wo, &mut rng).total();
        for c in 0..3 {
            sum[c] += f[c];
            sum2[c] += f[c] * f[c];
        }
    }
    finish(sum, sum2, n)
}

fn finish(sum: [f64; 3], sum2: [f64; 3], n: usize) -> Estimate {
    let nf = n as f64;
    let value = sum.map(|s| s / nf);
    let stderr = [0, 1, 2].map(|c| {
        if n > 1 {
            ((sum2[c] / nf - value[c] * value[c]).max(0.0) / (nf - 1.0)).sqrt()
        } else {
            0.0
        }
    });
    Estimate {
        value,
        stderr,
        samples: n,
    }
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
    let (mut sum, mut sum2) = ([0.0; 3], [0.0; 3]);
    for _ in 0..n {
        let u = [rng.random(), rng.random()];
        let wo = if rng.random::<f64>() < 0.5 {
            match guide.sample_weighted(wi, u) {
                Some((wo, _)) => wo,
                None => continue,
            }
        } else {
            let r = u[0].sqrt();
            let phi = 2.0 * PI * u[1];
            Vec3::new(r * phi.cos(), r * phi.sin(), (1.0 - u[0]).max(0.0).sqrt())
        };
        if wo.z <= 0.0 {
            continue;
        }
        let pdf = 0.5 * guide.pdf(wi, wo) + 0.5 * wo.z * FRAC_1_PI;
        let f = brdf.eval(wi, wo, &mut rng).total();
        for c in 0..3 {
            let v = f[c] * wo.z / pdf;
            sum[c] += v;
            sum2[c] += v * v;
        }
    }
    finish(sum, sum2, n)
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
///
/// Bins in which `eval` predicts fewer than [`MIN_EXPECTED_HITS`] sampler hits are pooled into
/// one cell (Pearson's rule): in a bin expecting 0.2 hits the sampler usually records none, its
/// measured variance is then zero, and the bin alone would give a huge z although nothing is
/// wrong (Beckmann tails at alpha 0.5 did this for the exact `single`). The pooled cell uses the
/// Poisson variance of its predicted count as a floor, so weight the sampler puts where `eval`
/// predicts none still fails the test.
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
    let (mut hist, mut hist2, mut hits) = (vec![0.0; bins], vec![0.0; bins], 0usize);
    for _ in 0..samples {
        if let Some(s) = brdf.sample(wi, [rng.random(), rng.random()], &mut rng) {
            if s.wo.z > 0.0 {
                let b = bin_of(s.wo);
                hist[b] += s.weight[0];
                hist2[b] += s.weight[0] * s.weight[0];
                hits += 1;
            }
        }
    }
    let bin_area = 2.0 * PI / bins as f64;
    let side = (points_per_bin as f64).sqrt().ceil() as usize;
    let n = samples as f64;
    // Typical weight of one hit, to turn a predicted bin mass into a predicted hit count.
    let weight_per_hit = if hits > 0 {
        hist.iter().sum::<f64>() / hits as f64
    } else {
        1.0
    };
    let (mut chi2, mut terms) = (0.0, 0usize);
    let mut add_term = |mean_s: f64, var_s: f64, mean_e: f64, var_e: f64, what: &str| {
        let var = var_s + var_e;
        if var > 0.0 {
            chi2 += (mean_s - mean_e).powi(2) / var;
        } else {
            assert!(
                (mean_s - mean_e).abs() < 1e-12,
                "{what}: sampler {mean_s} vs eval {mean_e} with zero variance"
            );
        }
        terms += 1;
    };
    // Pooled sparse bins: (mean_s, var_s, mean_e, var_e) summed.
    let mut pool = [0.0; 4];
    for b in 0..bins {
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
        if mean_e * n / weight_per_hit >= MIN_EXPECTED_HITS {
            add_term(mean_s, var_s, mean_e, var_e, &format!("bin {b}"));
        } else {
            for (p, v) in pool.iter_mut().zip([mean_s, var_s, mean_e, var_e]) {
                *p += v;
            }
        }
    }
    let [mean_s, var_s, mean_e, var_e] = pool;
    if mean_s > 0.0 || mean_e > 0.0 {
        // Poisson variance of the predicted count as a floor for the sampler side.
        let var_s = var_s.max(mean_e * weight_per_hit / n);
        add_term(mean_s, var_s, mean_e, var_e, "pooled sparse bins");
    }
    chi_square_z(chi2, terms as f64)
}

/// Bins of [`sampler_matches_eval`] predicted to receive fewer sampler hits are pooled.
pub const MIN_EXPECTED_HITS: f64 = 10.0;

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

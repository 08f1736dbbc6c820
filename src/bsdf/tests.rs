//! Tests every model must pass; today `single`.

#![allow(clippy::needless_range_loop)] // channel loops over several parallel arrays read best indexed

use super::registry::differentiable;
use super::single::SingleBounce;
use super::testing::COPPER;
use super::*;
use crate::albedo::directional_albedo;

use crate::material::FresnelSpec;
use crate::microfacet::{Fresnel, Height, Microfacet, NdfKind};
use crate::random::rng_stream;
use crate::scalar::Rgb;
use rand::Rng as _;
use std::f64::consts::PI;

fn unit(theta_deg: f64, phi_deg: f64) -> Vec3<f64> {
    let (t, p) = (theta_deg.to_radians(), phi_deg.to_radians());
    Vec3::new(t.sin() * p.cos(), t.sin() * p.sin(), t.cos())
}

fn single(
    ndf: NdfKind,
    ax: f64,
    ay: f64,
    fresnel: FresnelSpec,
    height: Height,
) -> SingleBounce<f64> {
    SingleBounce {
        microfacet: Microfacet::new(ndf, ax, ay),
        fresnel: fresnel.to_fresnel(),
        height,
    }
}

#[test]
fn single_is_reciprocal() {
    use super::testing::{mean_eval, random_configurations, z_score};
    for ndf in [NdfKind::Ggx, NdfKind::Beckmann] {
        for height in [Height::Correlated, Height::Uncorrelated] {
            for (k, (alpha, wi, wo)) in random_configurations(300, 1).into_iter().enumerate() {
                let m = single(
                    ndf,
                    alpha,
                    alpha * (0.2 + (k % 5) as f64 * 0.2),
                    COPPER,
                    height,
                );
                let (f, g) = (mean_eval(&m, wi, wo, 1, 0), mean_eval(&m, wo, wi, 1, 0));
                for c in 0..3 {
                    // Analytic: exact up to rounding (z_score is 0 within 1e-12 relative).
                    assert_eq!(z_score(&f, &g, c), 0.0, "{f:?} vs {g:?}");
                }
            }
        }
    }
}

#[test]
fn single_matches_the_textbook_formula() {
    // Walter et al. 2007 eq. 20 written out with tan-based Lambda, away from grazing.
    let (alpha, wi, wo) = (0.3, unit(30.0, 10.0), unit(50.0, 150.0));
    let m = single(
        NdfKind::Ggx,
        alpha,
        alpha,
        FresnelSpec::Schlick {
            f0: [0.9, 0.6, 0.3],
        },
        Height::Correlated,
    );
    let h = (wi + wo).normalize();
    let lam = |w: Vec3<f64>| {
        let t2 = (1.0 - w.z * w.z) / (w.z * w.z);
        (-1.0 + (1.0 + alpha * alpha * t2).sqrt()) / 2.0
    };
    let cos2 = h.z * h.z;
    let d = 1.0
        / (PI
            * alpha
            * alpha
            * cos2
            * cos2
            * (1.0 + (1.0 - cos2) / cos2 / (alpha * alpha)).powi(2));
    let g2 = 1.0 / (1.0 + lam(wi) + lam(wo));
    let f = m.eval(wi, wo).0;
    let c = wi.dot(h);
    for (ch, f0) in [0.9, 0.6, 0.3].iter().enumerate() {
        let fresnel = f0 + (1.0 - f0) * (1.0 - c).powi(5);
        let expected = fresnel * d * g2 / (4.0 * wi.z * wo.z);
        assert!((f[ch] - expected).abs() < 1e-12 * expected);
    }
}

#[test]
fn sampling_weight_and_pdf_agree_with_eval() {
    let mut rng = rng_stream(2, 0);
    for ndf in [NdfKind::Ggx, NdfKind::Beckmann] {
        let m = single(ndf, 0.4, 0.25, COPPER, Height::Correlated);
        for _ in 0..500 {
            let wi = unit(rng.random_range(0.0..89.0), rng.random_range(0.0..360.0));
            let Some(s) = Brdf::sample(&m, wi, [rng.random(), rng.random()], &mut rng) else {
                continue;
            };
            let f = SingleBounce::eval(&m, wi, s.wo).0;
            let pdf = SingleBounce::pdf(&m, wi, s.wo);
            assert!((pdf - s.pdf).abs() < 1e-9 * pdf);
            for c in 0..3 {
                let expected = f[c] * s.wo.z / pdf;
                assert!(
                    (s.weight[c] - expected).abs() < 1e-9 * expected,
                    "{} vs {expected}",
                    s.weight[c]
                );
            }
        }
    }
}

/// `E(wi)` by direct integration of `f cos` over a warped hemisphere (independent of the sampler).
fn albedo_by_hemisphere_quadrature(m: &SingleBounce<f64>, wi: Vec3<f64>, alpha: f64) -> [f64; 3] {
    let (nu, nv) = (720, 1800);
    let mut sum = [0.0; 3];
    for j in 0..nv {
        let v = (j as f64 + 0.5) / nv as f64;
        let t = (0.5 * PI * v).tan();
        let theta = (alpha * t).atan();
        let jac = alpha * 0.5 * PI * (1.0 + t * t) / (1.0 + alpha * alpha * t * t)
            * theta.sin()
            * 2.0
            * PI;
        for i in 0..nu {
            let phi = 2.0 * PI * (i as f64 + 0.5) / nu as f64;
            // Half vectors are integrated instead of wo: d wo = 4 (wo.h) d h.
            let h = Vec3::new(
                theta.sin() * phi.cos(),
                theta.sin() * phi.sin(),
                theta.cos(),
            );
            let wo = wi.reflect(h);
            if wo.z <= 0.0 || wi.dot(h) <= 0.0 {
                continue;
            }
            let f = m.eval(wi, wo).0;
            for c in 0..3 {
                sum[c] += f[c] * wo.z * 4.0 * wo.dot(h) * jac;
            }
        }
    }
    sum.map(|s| s / (nu * nv) as f64)
}

#[test]
fn albedo_by_sampler_quadrature_is_accurate_to_1e3() {
    for ndf in [NdfKind::Ggx, NdfKind::Beckmann] {
        for alpha in [0.01, 0.1, 0.5, 1.0, 2.0] {
            for theta in [0.0, 45.0, 80.0] {
                let m = single(ndf, alpha, alpha, COPPER, Height::Correlated);
                let wi = unit(theta, 0.0);
                let est = directional_albedo(&m, wi, 65_536, 0);
                let reference = albedo_by_hemisphere_quadrature(&m, wi, alpha);
                for c in 0..3 {
                    let err = (est.value[c] - reference[c]).abs();
                    assert!(
                        err < 1e-3,
                        "{ndf:?} alpha {alpha} theta {theta}: {} vs {}",
                        est.value[c],
                        reference[c]
                    );
                    assert!(
                        est.stderr[c] < 1e-3,
                        "{ndf:?} alpha {alpha} theta {theta}: error estimate {}, true error {err}",
                        est.stderr[c]
                    );
                }
            }
        }
    }
}

#[test]
fn white_albedo_of_single_is_below_one_and_falls_with_roughness() {
    for ndf in [NdfKind::Ggx, NdfKind::Beckmann] {
        for height in [Height::Correlated, Height::Uncorrelated] {
            let mut previous = (1.0, 0.0);
            for alpha in [0.01, 0.1, 0.3, 0.6, 1.0, 1.5, 2.0] {
                let m = single(ndf, alpha, alpha, FresnelSpec::White, height);
                let est = directional_albedo(&m, unit(0.0, 0.0), 65_536, 0);
                let (e, err) = (est.value[0], est.stderr[0]);
                assert!(
                    e < previous.0 + err + previous.1,
                    "{ndf:?} {height:?} alpha {alpha}: {e} >= {previous:?}"
                );
                assert!(
                    e <= 1.0 + err && e > 0.0,
                    "{ndf:?} {height:?} alpha {alpha}: {e} +- {err}"
                );
                previous = (e, err);
            }
            // At alpha = 0.01 almost nothing is lost; at alpha = 2 most is (an independent
            // uniform-hemisphere estimate gives 0.1437 +- 3e-5 for GGX correlated at alpha 1.5).
            let smooth = directional_albedo(
                &single(ndf, 0.01, 0.01, FresnelSpec::White, height),
                unit(0.0, 0.0),
                65_536,
                0,
            )
            .value[0];
            assert!(smooth > 0.999, "{smooth}");
            assert!(previous.0 < 0.8, "{previous:?}");
        }
    }
}

#[test]
fn brdf_is_finite_and_non_negative_at_extremes() {
    let mut rng = rng_stream(3, 0);
    for ndf in [NdfKind::Ggx, NdfKind::Beckmann] {
        for a in [1e-4, 1e-3, 0.05, 1.0, 3.0] {
            for fresnel in [
                FresnelSpec::White,
                COPPER,
                FresnelSpec::Conductor {
                    eta: [0.01; 3],
                    k: [20.0; 3],
                },
                FresnelSpec::Dielectric { eta: 10.0 },
            ] {
                let m = single(ndf, a, a * 0.5, fresnel, Height::Correlated);
                for _ in 0..300 {
                    let wi = unit(rng.random_range(0.0..90.0), rng.random_range(0.0..360.0));
                    let wo = unit(rng.random_range(0.0..90.0), rng.random_range(0.0..360.0));
                    for (x, y) in [
                        (wi, wo),
                        (unit(89.9999, 0.0), wo),
                        (wi, wi),
                        (unit(89.99, 0.0), unit(89.99, 180.0)),
                    ] {
                        let f = m.eval(x, y).0;
                        assert!(
                            f.iter().all(|v| v.is_finite() && *v >= 0.0),
                            "{ndf:?} a {a} {fresnel:?}: {f:?} at {x:?} {y:?}"
                        );
                    }
                }
            }
        }
    }
    let _ = Rgb([0.0f64; 3]);
}

#[test]
fn harness_agrees_on_single_and_rejects_a_mismatch() {
    use super::testing::*;
    for ndf in [NdfKind::Ggx, NdfKind::Beckmann] {
        let m = single(ndf, 0.5, 0.5, COPPER, Height::Correlated);
        let guide = single(ndf, 0.5, 0.5, FresnelSpec::White, Height::Correlated);
        for theta in [0.0, 40.0, 75.0] {
            let wi = unit(theta, 30.0);
            let by_sampling = albedo_by_sampling(&m, wi, 65_536, 1);
            let by_eval = albedo_by_eval(&m, &guide, wi, 200_000, 2);
            for c in 0..3 {
                // The quadrature side is exact to ~1e-5; the eval side carries MC error.
                assert!(
                    z_score(&by_sampling, &by_eval, c) < 4.0,
                    "{ndf:?} theta {theta}: {by_sampling:?} vs {by_eval:?}"
                );
            }
        }
        let z = sampler_matches_eval(&m, unit(35.0, 10.0), 400_000, 64, 3);
        assert!(z < 4.0, "{ndf:?}: sampler vs eval z = {z}");
    }
    // A sampler of alpha 0.5 checked against the evaluation of alpha 0.6 must be rejected.
    struct Mismatched(SingleBounce<f64>, SingleBounce<f64>);
    impl Brdf for Mismatched {
        fn eval(&self, wi: Vec3<f64>, wo: Vec3<f64>, rng: &mut Rng) -> BrdfValue {
            Brdf::eval(&self.1, wi, wo, rng)
        }
        fn sample(&self, wi: Vec3<f64>, u: [f64; 2], rng: &mut Rng) -> Option<BrdfSample> {
            Brdf::sample(&self.0, wi, u, rng)
        }
        fn pdf(&self, wi: Vec3<f64>, wo: Vec3<f64>) -> f64 {
            Brdf::pdf(&self.0, wi, wo)
        }
    }
    let wrong = Mismatched(
        single(NdfKind::Ggx, 0.5, 0.5, COPPER, Height::Correlated),
        single(NdfKind::Ggx, 0.6, 0.6, COPPER, Height::Correlated),
    );
    assert!(sampler_matches_eval(&wrong, unit(35.0, 10.0), 400_000, 64, 3) > 10.0);
}

#[test]
fn single_survives_the_finite_sweep() {
    use super::testing::{assert_finite_sweep, random_surface};
    assert_finite_sweep(
        |rng| {
            let (microfacet, fresnel) = random_surface(rng);
            Box::new(SingleBounce {
                microfacet,
                fresnel: fresnel.to_fresnel(),
                height: Height::Correlated,
            })
        },
        1_000_000,
        9,
    );
}

#[test]
fn sampler_histogram_test_accepts_beckmann_with_nearly_empty_grazing_bins() {
    // Beckmann alpha 0.5: the grazing bins hold ~1e-6 of the energy, far less than one sample.
    let m = single(NdfKind::Beckmann, 0.5, 0.5, COPPER, Height::Correlated);
    for theta in [35.0, 70.0] {
        let z = super::testing::sampler_matches_eval(
            &m,
            super::testing::unit(theta, 10.0),
            400_000,
            256,
            5,
        );
        assert!(z < 4.0, "theta {theta}: z = {z}");
    }
}

#[test]
fn bitterli_and_heitz_estimate_the_same_brdf() {
    use super::bitterli::Bitterli;
    use super::heitz::Heitz;
    use super::testing::{mean_eval, random_configurations, z_score};
    // Both are unbiased estimators of the height-correlated Smith multiple-scattering BRDF of a
    // conductor (Bitterli & d'Eon 2022 sec. 6; Dupuy et al. 2016): on 120 random configurations,
    // half GGX half Beckmann, some anisotropic, every channel agrees within 4 standard errors.
    let (mut max_z, mut sum_z2, mut count) = (0.0f64, 0.0, 0);
    for (k, (alpha, wi, wo)) in random_configurations(120, 31).into_iter().enumerate() {
        let ndf = if k % 2 == 0 {
            NdfKind::Ggx
        } else {
            NdfKind::Beckmann
        };
        let mf = Microfacet::new(ndf, alpha, alpha * if k % 3 == 0 { 0.5 } else { 1.0 });
        let fresnel = COPPER.to_fresnel();
        let h = mean_eval(&Heitz::new(mf, fresnel), wi, wo, 3000, 100 + k as u64);
        let b = mean_eval(&Bitterli::new(mf, fresnel), wi, wo, 3000, 200 + k as u64);
        for c in 0..3 {
            let z = z_score(&h, &b, c);
            assert!(z < 4.0, "config {k}: alpha {alpha} {ndf:?} wi {wi:?} wo {wo:?}: heitz {h:?} vs bitterli {b:?}");
            max_z = max_z.max(z);
            sum_z2 += z * z;
            count += 1;
        }
    }
    eprintln!(
        "bitterli vs heitz: {count} channel comparisons, max |z| = {max_z:.2}, mean z^2 = {:.3}",
        sum_z2 / count as f64
    );
}

const ESTIMATORS: [Model; 5] = [
    Model::Heitz,
    Model::Bitterli,
    Model::Cui,
    Model::WangPt,
    Model::WangBdpt,
];

/// A cap no walk reaches changes no bit: the cap only stops walks, it draws no random number
/// and reorders none (so an uncapped render is today's, bit for bit).
#[test]
fn a_cap_no_walk_reaches_changes_no_bit() {
    use super::testing::random_configurations;
    for model in ESTIMATORS {
        for (k, (alpha, wi, wo)) in random_configurations(40, 17).into_iter().enumerate() {
            let m = super::testing::ggx_material(model, alpha, COPPER);
            let (free, capped) = (m.brdf(), m.capped_brdf(BounceCap::at(1000)));
            let (mut r1, mut r2) = (rng_stream(5, k as u64), rng_stream(5, k as u64));
            for _ in 0..20 {
                let (a, b) = (free.eval(wi, wo, &mut r1), capped.eval(wi, wo, &mut r2));
                assert_eq!(a, b, "{model} config {k}");
            }
            let u = [0.3, 0.7];
            let (a, b) = (free.sample(wi, u, &mut r1), capped.sample(wi, u, &mut r2));
            assert_eq!(a.map(|s| (s.wo, s.weight)), b.map(|s| (s.wo, s.weight)));
        }
    }
}

/// Every estimator capped at `K` reflections loses exactly the energy of the longer paths:
/// `E_capped - E_free = -E_{>K}`, the albedos by evaluation (independent runs) and the tail by
/// the free model's own sampler. sigma is the root sum of the three standard errors (measured,
/// about 1.5e-3); the tail (about 0.03) is far above it, so an estimator that ignored the cap
/// fails. Its sampler, capped, returns no longer path and the same albedo short of the tail.
#[test]
fn capped_estimators_lose_exactly_the_tail() {
    use super::testing::albedo_by_eval;
    use crate::albedo::bounce_moments;
    const K: u32 = 2;
    let wi = unit(45.0, 30.0);
    for (j, model) in ESTIMATORS.into_iter().enumerate() {
        let fresnel = if j % 2 == 0 {
            FresnelSpec::White
        } else {
            COPPER
        };
        let m = super::testing::ggx_material(model, 1.0, fresnel);
        let (free, capped) = (m.brdf(), m.capped_brdf(BounceCap::at(K)));
        let guide = SingleBounce {
            fresnel: Fresnel::White,
            ..m.single::<f64>()
        };
        let n = 1 << 16;
        let e_free = albedo_by_eval(free.as_ref(), &guide, wi, n, 11 + j as u64);
        let e_capped = albedo_by_eval(capped.as_ref(), &guide, wi, n, 23 + j as u64);
        let by_bounce = bounce_moments(free.as_ref(), wi, 1 << 18, 37, K as usize + 1);
        let samples = by_bounce.samples as f64;
        let tail = by_bounce.mean[K as usize];
        let tail_square = by_bounce.mean_square[K as usize];
        let capped_paths = bounce_moments(capped.as_ref(), wi, 1 << 18, 37, K as usize + 1);
        for c in 0..3 {
            let tail_se = ((tail_square[c] - tail[c] * tail[c]) / (samples - 1.0)).sqrt();
            let sigma =
                (e_free.stderr[c].powi(2) + e_capped.stderr[c].powi(2) + tail_se.powi(2)).sqrt();
            let lost = e_free.value[c] - e_capped.value[c];
            assert!(
                (lost - tail[c]).abs() <= 4.0 * sigma && tail[c] > 8.0 * sigma,
                "{model} channel {c}: lost {lost}, tail {} (sigma {sigma})",
                tail[c]
            );
            // The capped sampler's paths of <= K bounces against the free one's (independent
            // after the first dropped path; sigma from the free run's second moment).
            assert_eq!(capped_paths.mean[K as usize][c], 0.0, "{model}");
            let short: f64 = by_bounce.mean[..K as usize].iter().map(|v| v[c]).sum();
            let short_square: f64 = by_bounce.mean_square[..K as usize]
                .iter()
                .map(|v| v[c])
                .sum();
            let short_se = ((short_square - short * short) / (samples - 1.0)).sqrt();
            let capped_total: f64 = capped_paths.mean.iter().map(|v| v[c]).sum();
            assert!(
                (capped_total - short).abs() <= 4.0 * short_se * 2f64.sqrt(),
                "{model}: capped sampler {capped_total} vs paths of <= {K} {short} (se {short_se})"
            );
        }
    }
}

/// `eval_multi` is the `multi` part of `eval` (and of `eval_split`, for the models generic over
/// the scalar) bit for bit, drawn from the same random numbers: the streams end in the same
/// state. A model whose `eval_multi` skipped or reordered a draw, or left out part of its
/// multiple-bounce term, fails; a direction below the surface is among the cases.
#[test]
fn the_multiple_bounce_term_alone_is_evals_from_the_same_draws() {
    use super::testing::{ggx_material, random_configurations};
    let mut cases = random_configurations(40, 7);
    cases.push((0.5, unit(30.0, 0.0), Vec3::new(0.3, 0.0, -0.954)));
    for model in Model::ALL {
        let mut nonzero = 0;
        for (k, &(alpha, wi, wo)) in cases.iter().enumerate() {
            let material = ggx_material(model, alpha, COPPER);
            let brdf = material.capped_brdf(BounceCap::NONE);
            let (mut whole, mut alone) = (rng_stream(3, k as u64), rng_stream(3, k as u64));
            let multi = brdf.eval(wi, wo, &mut whole).multi;
            nonzero += usize::from(multi.iter().any(|&v| v > 0.0));
            assert_eq!(
                multi,
                brdf.eval_multi(wi, wo, &mut alone),
                "{model:?}, case {k}"
            );
            assert_eq!(
                whole.random::<u64>(),
                alone.random::<u64>(),
                "{model:?}, case {k}"
            );
            if let Some(generic) = differentiable::<f64>(model, material.single(), BounceCap::NONE)
            {
                let (mut whole, mut alone) = (rng_stream(4, k as u64), rng_stream(4, k as u64));
                let multi = generic.eval_split(wi, wo, &mut whole).1;
                assert_eq!(
                    multi.0,
                    generic.eval_multi(wi, wo, &mut alone).0,
                    "{model:?}"
                );
                assert_eq!(whole.random::<u64>(), alone.random::<u64>(), "{model:?}");
            }
        }
        // The comparison is not of zeros: every model but `single` has a multiple-bounce term
        // at many of these cases (one evaluation of `heitz`'s walks is 0 at 22 of the 41).
        assert!(
            model == Model::Single || nonzero > cases.len() / 4,
            "{model:?}: {nonzero} nonzero"
        );
    }
}

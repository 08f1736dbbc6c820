//! The published models' quirks, pinned (issue #16 item 1): behaviour that differs from the
//! reference `heitz` or from energy conservation *by the paper's design*, measured here so that
//! a wrong implementation (or a "fix" that departs from the paper) fails.
//!
//! - Wang et al. 2022 light every vertex "from the distance": with correlated heights their
//!   two-bounce transport differs from Heitz et al. 2016's walk by `(s0 + Lo) / s0` for a
//!   downward middle direction and `L1 (s0 + Lo) / ((L1 + Lo) s0)` for an upward one
//!   (`s0 = 1 + Lambda(wi)`, `Lo = Lambda(wo)`, `L1 = |Lambda(d1)|`): exactly 1 when `wo` is the
//!   normal (`Lo = 0`), about 4.3x at alpha 1.5, `wi` normal, `wo` at 80 degrees.
//! - Fast-MSX (Rosales et al. 2023, eq. 9, 16-20) adds energy as printed: at GGX alpha 0.3 and
//!   normal incidence the single lobe holds 0.877 and the added lobe 0.374.

use super::heitz::Heitz;
use super::testing::{mean_eval, unit, z_score};
use super::wang::{Wang, WangEstimator};
use super::{BounceCap, Brdf};
use crate::albedo::directional_albedo;
use crate::bsdf::fast_msx::FastMsx;
use crate::bsdf::single::SingleBounce;
use crate::microfacet::{Fresnel, Height, Microfacet, NdfKind};

fn surface(alpha: f64) -> SingleBounce<f64> {
    SingleBounce {
        microfacet: Microfacet::new(NdfKind::Ggx, alpha, alpha),
        fresnel: Fresnel::White,
        height: Height::Correlated,
    }
}

/// Paths of exactly two bounces: `multi` of each estimator capped at two reflections.
fn two_bounce(
    brdf: &dyn Brdf,
    wi_theta: f64,
    wo_theta: f64,
    n: usize,
    seed: u64,
) -> crate::random::Estimate {
    let (wi, wo) = (unit(wi_theta, 0.0), unit(wo_theta, 180.0));
    let mut e = mean_eval(brdf, wi, wo, n, seed);
    let single = brdf
        .eval(wi, wo, &mut crate::random::rng_stream(0, 0))
        .single;
    e.value = [0, 1, 2].map(|c| e.value[c] - single[c]);
    e
}

fn capped_pair(alpha: f64, estimator: WangEstimator) -> (Wang, Heitz) {
    let s = surface(alpha);
    let cap = BounceCap::at(2);
    (
        Wang::new(s, estimator).with_bounce_cap(cap),
        Heitz::new(s.microfacet, s.fresnel).with_bounce_cap(cap),
    )
}

#[test]
fn correlated_wang_equals_heitz_at_two_bounces_toward_the_normal() {
    // Lo = Lambda(normal) = 0 makes both of Wang's per-path ratios 1: the estimators agree
    // within Monte Carlo error for every wi and alpha (4 sigma, combined standard error).
    for estimator in [WangEstimator::PathTracing, WangEstimator::Bidirectional] {
        for alpha in [0.3, 1.0, 1.5] {
            for theta in [0.0, 40.0, 75.0] {
                let (wang, heitz) = capped_pair(alpha, estimator);
                let seed = (alpha * 100.0) as u64 + theta as u64;
                let w = two_bounce(&wang, theta, 0.0, 40_000, seed);
                let h = two_bounce(&heitz, theta, 0.0, 40_000, seed + 1);
                let z = z_score(&w, &h, 0);
                assert!(
                    z < 4.0,
                    "{estimator:?} alpha {alpha} theta_i {theta}: wang {:.5} +- {:.5}, heitz {:.5} +- {:.5} (z {z:.1})",
                    w.value[0], w.stderr[0], h.value[0], h.stderr[0]
                );
            }
        }
    }
}

#[test]
fn correlated_wang_differs_from_heitz_by_the_papers_design_toward_grazing() {
    // wi normal, wo at 80 degrees, alpha 1.5: the review's numerical integration of the two
    // transports gives a ratio of about 4.3. Measured here with its standard error; the bound
    // is 4.3 +- 0.3 or 4 sigma, whichever is larger.
    let (wang, heitz) = capped_pair(1.5, WangEstimator::PathTracing);
    let w = two_bounce(&wang, 0.0, 80.0, 200_000, 31);
    let h = two_bounce(&heitz, 0.0, 80.0, 200_000, 32);
    let ratio = w.value[0] / h.value[0];
    let sigma =
        ratio * ((w.stderr[0] / w.value[0]).powi(2) + (h.stderr[0] / h.value[0]).powi(2)).sqrt();
    eprintln!("wang / heitz at two bounces: {ratio:.3} +- {sigma:.3}");
    assert!(
        (ratio - 4.3).abs() < (0.3f64).max(4.0 * sigma),
        "ratio {ratio:.3} +- {sigma:.3}"
    );
}

#[test]
fn fast_msx_adds_energy_as_printed() {
    // Eq. 9, 16-20 as printed: white albedo at normal incidence (quadrature, error < 1e-4).
    let albedo = |alpha: f64| {
        let fast = FastMsx {
            single: surface(alpha),
        };
        let single = surface(alpha);
        let wi = unit(0.0, 0.0);
        (
            directional_albedo(&fast, wi, 256 * 256, 1).value[0],
            directional_albedo(&single, wi, 256 * 256, 1).value[0],
        )
    };
    let (total, single) = albedo(0.3);
    assert!(
        (total - 1.25).abs() < 0.01,
        "fast-msx albedo at alpha 0.3: {total}"
    );
    assert!((single - 0.877).abs() < 0.002, "its single lobe: {single}");
    assert!(
        (total - single - 0.374).abs() < 0.005,
        "its added lobe: {}",
        total - single
    );
    // The added lobe is not the missing energy: the scale that would fill the shortfall is
    // 0.33 at alpha 0.3 and 1.31 at alpha 1, so no constant fixes it.
    let scale = |(total, single): (f64, f64)| (1.0 - single) / (total - single);
    let (at_03, at_1) = (scale((total, single)), scale(albedo(1.0)));
    assert!(
        (at_03 - 0.33).abs() < 0.01 && (at_1 - 1.31).abs() < 0.02,
        "scales {at_03:.3}, {at_1:.3}"
    );
    let (total_1, _) = albedo(1.0);
    assert!(
        (total_1 - 0.84).abs() < 0.01,
        "fast-msx albedo at alpha 1: {total_1}"
    );
}

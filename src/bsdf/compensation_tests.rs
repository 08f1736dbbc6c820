//! Tests of the analytic multi-bounce models `fast-msx`, `kulla-conty`, `turquin` and
//! `tabulated` (its agreement with `heitz` and its table: `tabulated/tests.rs`).

#![allow(clippy::needless_range_loop)] // channel loops over parallel arrays read best indexed

use super::fast_msx::FastMsx;
use super::kulla_conty::KullaConty;
use super::single::SingleBounce;
use super::tabulated::Tabulated;
use super::testing::*;
use super::turquin::Turquin;
use super::Brdf;
use crate::albedo::Adjoint;
use crate::material::FresnelSpec;
use crate::microfacet::{Height, Microfacet, NdfKind};
use crate::scalar::{Rgb, Vec3};
use num_dual::Dual64;
use std::f64::consts::PI;

fn single(ndf: NdfKind, a: f64, fresnel: FresnelSpec, height: Height) -> SingleBounce<f64> {
    SingleBounce {
        microfacet: Microfacet::new(ndf, a, a),
        fresnel: fresnel.to_fresnel(),
        height,
    }
}

#[test]
fn fast_msx_matches_the_papers_formulas_for_isotropic_ggx() {
    // Algorithm 1 and eq. 18-20 written out with angles, Schlick F.
    let (alpha, f0) = (0.6, [0.9, 0.6, 0.3]);
    let model = FastMsx {
        single: single(
            NdfKind::Ggx,
            alpha,
            FresnelSpec::Schlick { f0 },
            Height::Uncorrelated,
        ),
    };
    for (l, v) in [
        (unit(30.0, 0.0), unit(50.0, 180.0)),
        (unit(60.0, 20.0), unit(10.0, 90.0)),
        (unit(75.0, 0.0), unit(75.0, 0.0)),
    ] {
        let h = (l + v).normalize();
        let c = (h + Vec3::new(0.0, 0.0, 1.0)).normalize();
        let theta_vc = c.dot(v).acos();
        let theta_m = (PI - v.dot(l).acos()) * 0.25;
        let g_i = 1.0 - ((theta_vc - theta_m).sin() / (theta_vc + theta_m).sin()).max(0.0);
        let cm2 = theta_m.cos().powi(2);
        let d_i = alpha * alpha / (PI * (cm2 * (alpha * alpha - 1.0) + 1.0).powi(2));
        let got = model.indirect(l, v).0;
        for c_ in 0..3 {
            let f = f0[c_] + (1.0 - f0[c_]) * (1.0 - l.dot(h)).powi(5);
            let expected = d_i * g_i * f * f / (2.0 * c.dot(v));
            assert!(
                (got[c_] - expected).abs() < 1e-12 * expected.max(1e-12),
                "{got:?} vs {expected}"
            );
        }
    }
}

#[test]
fn kulla_conty_is_white_furnace_exact_and_reciprocal() {
    for ndf in [NdfKind::Ggx, NdfKind::Beckmann] {
        for alpha in [0.1, 0.3, 0.6, 1.0, 1.5] {
            let model = KullaConty::new(single(ndf, alpha, FresnelSpec::White, Height::Correlated));
            for theta in [0.0, 30.0, 60.0, 80.0] {
                let e = albedo_by_sampling(&model, unit(theta, 0.0), 65_536, 1);
                // Exact by construction up to the table's interpolation (< 5e-3) and quadrature.
                assert!(
                    (e.value[0] - 1.0).abs() < 0.01,
                    "{ndf:?} alpha {alpha} theta {theta}: {:?}",
                    e.value
                );
            }
        }
    }
    let model = KullaConty::new(single(NdfKind::Ggx, 0.7, COPPER, Height::Correlated));
    for (_, wi, wo) in random_configurations(100, 5) {
        let (f, g) = (model.compensation(wi, wo).0, model.compensation(wo, wi).0);
        assert_eq!(f, g);
    }
}

#[test]
fn turquin_conserves_white_energy_toward_a_fixed_view() {
    for ndf in [NdfKind::Ggx, NdfKind::Beckmann] {
        for alpha in [0.1, 0.6, 1.5] {
            let s = single(ndf, alpha, FresnelSpec::White, Height::Correlated);
            let turquin = Turquin::new(s);
            let model = Adjoint(&turquin);
            for theta in [0.0, 45.0, 80.0] {
                let e = albedo_by_eval(&model, &s, unit(theta, 0.0), 200_000, 7);
                assert!(
                    (e.value[0] - 1.0).abs() < 0.01 + 3.0 * e.stderr[0],
                    "{ndf:?} alpha {alpha} theta {theta}: {e:?}"
                );
            }
        }
    }
}

#[test]
fn compensation_models_sample_what_they_evaluate() {
    for ndf in [NdfKind::Ggx, NdfKind::Beckmann] {
        let s = single(ndf, 0.6, COPPER, Height::Correlated);
        let models: [Box<dyn Brdf>; 4] = [
            Box::new(FastMsx { single: s }),
            Box::new(KullaConty::new(s)),
            Box::new(Turquin::new(s)),
            Box::new(Tabulated::new(s)),
        ];
        for (k, m) in models.iter().enumerate() {
            for theta in [35.0, 70.0] {
                let z =
                    sampler_matches_eval(m.as_ref(), unit(theta, 20.0), 300_000, 64, 11 + k as u64);
                assert!(z < 4.0, "{ndf:?} model {k} theta {theta}: z = {z}");
            }
        }
    }
}

#[test]
fn compensation_models_survive_the_finite_sweep() {
    for which in 0..4 {
        assert_finite_sweep(
            |rng| {
                let (microfacet, fresnel) = random_surface(rng);
                let s = SingleBounce {
                    microfacet,
                    fresnel: fresnel.to_fresnel(),
                    height: Height::Correlated,
                };
                match which {
                    0 => Box::new(FastMsx { single: s }) as Box<dyn Brdf>,
                    1 => Box::new(KullaConty::new(s)),
                    2 => Box::new(Turquin::new(s)),
                    _ => Box::new(Tabulated::new(s)),
                }
            },
            1_000_000,
            21 + which,
        );
    }
}

#[test]
fn compensation_models_differentiate_exactly() {
    // d f / d alpha by dual numbers against central differences (Kulla-Conty and Turquin read
    // tables that are piecewise linear in ln alpha; the difference step stays inside one cell).
    let (wi, wo) = (unit(40.0, 10.0), unit(25.0, 200.0));
    let alpha = 0.43;
    let h = 1e-6;
    let build = |a: f64| SingleBounce {
        microfacet: Microfacet::new(NdfKind::Ggx, a, a),
        fresnel: COPPER.to_fresnel::<f64>(),
        height: Height::Correlated,
    };
    let value = |a: f64| -> [[f64; 3]; 3] {
        let s = build(a);
        let (fs, fm) = FastMsx { single: s }.eval_split(wi, wo);
        let k = KullaConty::new(s).compensation(wi, wo);
        let (_, tm) = Turquin::new(s).eval_split(wi, wo);
        [(fs + fm).0, k.0, tm.0]
    };
    let (p, q) = (value(alpha + h), value(alpha - h));
    let a = Dual64::from_re(alpha).derivative();
    let s = SingleBounce {
        microfacet: Microfacet::new(NdfKind::Ggx, a, a),
        fresnel: COPPER.to_fresnel::<Dual64>(),
        height: Height::Correlated,
    };
    let (wi_d, wo_d) = (Vec3::from_f64(wi.re()), Vec3::from_f64(wo.re()));
    let (fs, fm) = FastMsx { single: s }.eval_split(wi_d, wo_d);
    let exact: [Rgb<Dual64>; 3] = [
        fs + fm,
        KullaConty::new(s).compensation(wi_d, wo_d),
        Turquin::new(s).eval_split(wi_d, wo_d).1,
    ];
    for m in 0..3 {
        for c in 0..3 {
            let fd = (p[m][c] - q[m][c]) / (2.0 * h);
            let d = exact[m].0[c].eps;
            assert!(
                (d - fd).abs() < 1e-5 * fd.abs().max(1e-3),
                "model {m} channel {c}: dual {d} vs fd {fd}"
            );
        }
    }
}

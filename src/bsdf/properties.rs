//! Property tests (proptest) of every model, through the public path a user takes
//! ([`Material::brdf`]), over the whole parameter space the command line accepts (issue #6).
//!
//! | input | strategy |
//! | --- | --- |
//! | model | one module per [`Model`] (so a failure names its model) |
//! | distribution, heights | GGX or Beckmann; correlated or uncorrelated |
//! | roughness | `alpha_x`, `alpha_y` log-uniform in [1e-4, 3]; isotropic, or anisotropic with ratio up to 100 |
//! | Fresnel | white; Schlick `F0` in [0, 1]; conductor `eta` log-uniform in [0.01, 10], `k` in [0, 20] (or 0); dielectric `eta` in [1.0001, 10] or in [0.1, 0.9999] (total internal reflection) |
//! | directions | `theta` uniform below 89 degrees, in [89, 89.99] degrees, or exactly 90 (`z = 0`); `wo` also near the mirror direction of `wi` (offsets 1e-6 to 0.1), where narrow lobes are non-zero |
//! | random numbers | `u` in [0, 1)^2 (with 0 exactly); any `u64` seed for the model's own stream |
//!
//! | property | models | cases per model |
//! | --- | --- | --- |
//! | `eval`: single and multi parts finite and >= 0 per channel | all | [`CASES`] |
//! | `sample`: weight finite and >= 0, `wo` unit and above the horizon, `pdf` finite, > 0 and equal to [`Brdf::pdf`] at `wo` | all | [`CASES`] |
//! | `pdf` finite and >= 0 everywhere, > 0 where an estimate of `f` is > 0 | all (every sampler mixes in a lobe covering the support of `f`) | [`CASES`] |
//! | below the horizon (`theta` in (90, 180], down to 1e-12 degrees under it): `f = 0`, `pdf = 0`, no sample from below | all | [`CASES`] |
//! | reciprocity `f(wi, wo) = f(wo, wi)` to 1e-9 relative | `single`, `kulla-conty` | [`CASES`] |
//! | reciprocity in expectation (z-score of two means; alpha >= 0.1, theta <= 80 degrees) | `heitz`, `bitterli`, `cui`, `wang-pt`/`wang-bdpt` with uncorrelated heights | [`STOCHASTIC_RECIPROCITY_CASES`], fixed seed |
//!
//! The models whose reciprocity the table of `src/bsdf/mod.rs` denies (`fast-msx`, `turquin`,
//! correlated `wang-*`) are left out of the reciprocity properties.

use super::{Brdf, Model};
use crate::bsdf::testing::{mean_eval, z_score};
use crate::material::{FresnelSpec, Material};
use crate::microfacet::{Height, NdfKind};
use crate::random::rng_stream;
use crate::scalar::Vec3;
use proptest::prelude::*;
use proptest::test_runner::{Config, RngSeed};

/// Cases per model and property: the whole module runs in about 20 s at opt-level 2.
const CASES: u32 = 1000;

/// Configurations of the stochastic reciprocity test (each costs two means of
/// [`RECIPROCITY_EVALS`] evaluations).
const STOCHASTIC_RECIPROCITY_CASES: u32 = 40;

/// Evaluations per direction in the stochastic reciprocity test.
const RECIPROCITY_EVALS: usize = 2000;

/// Largest z-score of `mean f(wi, wo) - mean f(wo, wi)` accepted (sigma: the measured standard
/// errors of both means combined): a reciprocal estimator passes each of the 40 x 3
/// comparisons with probability 1 - 7e-6, all of them with 1 - 8e-4, so the fixed-seed test
/// fails on a bias, not on an unlucky draw.
const RECIPROCITY_Z: f64 = 4.5;

/// Relative tolerance of exact reciprocity: the two orders evaluate the same formula with the
/// operands of sums and dot products swapped, which changes only the last bits.
const EXACT_RECIPROCITY_TOLERANCE: f64 = 1e-9;

fn config(cases: u32) -> Config {
    Config {
        cases,
        ..Config::default()
    }
}

/// `10^x` for a strategy over exponents.
fn log_uniform(exponents: std::ops::RangeInclusive<f64>) -> impl Strategy<Value = f64> {
    exponents.prop_map(|x| 10f64.powf(x))
}

/// `[alpha_x, alpha_y]`: both log-uniform in [10^lowest, 3], isotropic or with a ratio up to
/// 100 (or what the range allows) along either axis.
fn roughness(lowest: f64) -> impl Strategy<Value = [f64; 2]> {
    let highest = 3f64.log10();
    let largest_ratio = 2f64.min(highest - lowest);
    prop_oneof![
        (lowest..=highest).prop_map(|x| [10f64.powf(x); 2]),
        (0.0..=largest_ratio, 0.0..=1.0f64, any::<bool>()).prop_map(move |(ratio, t, along_x)| {
            let smaller = lowest + t * (highest - lowest - ratio);
            let (a, b) = (10f64.powf(smaller), 10f64.powf(smaller + ratio));
            if along_x {
                [b, a]
            } else {
                [a, b]
            }
        }),
    ]
}

fn fresnel() -> impl Strategy<Value = FresnelSpec> {
    use proptest::array::uniform3;
    let extinction = prop_oneof![Just(0.0), 0.0..=20.0f64];
    prop_oneof![
        Just(FresnelSpec::White),
        uniform3(0.0..=1.0f64).prop_map(|f0| FresnelSpec::Schlick { f0 }),
        (uniform3(log_uniform(-2.0..=1.0)), uniform3(extinction))
            .prop_map(|(eta, k)| FresnelSpec::Conductor { eta, k }),
        prop_oneof![1.0001..=10.0f64, 0.1..=0.9999f64]
            .prop_map(|eta| FresnelSpec::Dielectric { eta }),
    ]
}

/// A material of `model` drawn from the whole accepted parameter space.
fn material(model: Model) -> impl Strategy<Value = Material> {
    material_rougher_than(model, -4.0)
}

/// A material of `model` with roughness at least `10^lowest`.
fn material_rougher_than(model: Model, lowest: f64) -> impl Strategy<Value = Material> {
    (
        prop_oneof![Just(NdfKind::Ggx), Just(NdfKind::Beckmann)],
        prop_oneof![Just(Height::Correlated), Just(Height::Uncorrelated)],
        roughness(lowest),
        fresnel(),
    )
        .prop_map(move |(ndf, height, alpha, fresnel)| Material {
            model,
            ndf,
            height,
            alpha,
            fresnel,
            diffuse: [0.0; 3],
        })
}

/// Unit direction at polar angle `theta` (degrees; exactly 90 gives `z = 0` exactly).
fn polar(theta_deg: f64, phi: f64) -> Vec3<f64> {
    let (sin, cos) = if theta_deg == 90.0 {
        (1.0, 0.0)
    } else {
        theta_deg.to_radians().sin_cos()
    };
    Vec3::new(sin * phi.cos(), sin * phi.sin(), cos)
}

/// A direction on the upper hemisphere, grazing or exactly in the plane a fair share of times.
fn direction() -> impl Strategy<Value = Vec3<f64>> {
    let theta = prop_oneof![
        6 => 0.0..89.0f64,
        3 => 89.0..=89.99f64,
        1 => Just(90.0),
    ];
    (theta, 0.0..std::f64::consts::TAU).prop_map(|(t, phi)| polar(t, phi))
}

/// A direction strictly below the surface (down to just under the horizon).
fn below_horizon() -> impl Strategy<Value = Vec3<f64>> {
    let theta = prop_oneof![
        90.0001..=180.0f64,
        log_uniform(-12.0..=-3.0).prop_map(|d| 90.0 + d)
    ];
    (theta, 0.0..std::f64::consts::TAU).prop_map(|(t, phi)| polar(t, phi))
}

/// An offset from the mirror direction along one tangent axis: +-[1e-6, 0.1], log-uniform.
fn mirror_offset() -> impl Strategy<Value = f64> {
    (log_uniform(-6.0..=-1.0), any::<bool>())
        .prop_map(|(d, negative)| if negative { -d } else { d })
}

/// `(wi, wo)`: independent, or `wo` near the mirror direction of `wi` (offsets
/// [`mirror_offset`] per tangent axis), where the lobes of smooth surfaces are non-zero.
fn direction_pair() -> impl Strategy<Value = (Vec3<f64>, Vec3<f64>)> {
    prop_oneof![
        (direction(), direction()),
        (direction(), mirror_offset(), mirror_offset()).prop_map(|(wi, dx, dy)| {
            let mirror = Vec3::new(-wi.x + dx, -wi.y + dy, wi.z).normalize();
            (wi, mirror)
        }),
    ]
}

fn unit_square() -> impl Strategy<Value = [f64; 2]> {
    let coordinate = prop_oneof![1 => Just(0.0), 9 => 0.0..1.0f64];
    proptest::array::uniform2(coordinate)
}

fn finite_non_negative(v: &[f64; 3]) -> bool {
    v.iter().all(|x| x.is_finite() && *x >= 0.0)
}

fn check_eval(
    brdf: &dyn Brdf,
    wi: Vec3<f64>,
    wo: Vec3<f64>,
    seed: u64,
) -> Result<(), TestCaseError> {
    let value = brdf.eval(wi, wo, &mut rng_stream(seed, 0));
    prop_assert!(
        finite_non_negative(&value.single),
        "single part {:?}",
        value.single
    );
    prop_assert!(
        finite_non_negative(&value.multi),
        "multi part {:?}",
        value.multi
    );
    Ok(())
}

fn check_sample(
    brdf: &dyn Brdf,
    wi: Vec3<f64>,
    u: [f64; 2],
    seed: u64,
) -> Result<(), TestCaseError> {
    let Some(s) = brdf.sample(wi, u, &mut rng_stream(seed, 0)) else {
        return Ok(());
    };
    prop_assert!(finite_non_negative(&s.weight), "weight {:?}", s);
    prop_assert!((s.wo.length() - 1.0).abs() < 1e-9, "wo not unit: {:?}", s);
    prop_assert!(s.wo.z > 0.0, "wo below the horizon: {:?}", s);
    prop_assert!(s.pdf.is_finite() && s.pdf > 0.0, "pdf {:?}", s);
    let pdf = brdf.pdf(wi, s.wo);
    prop_assert!(
        (pdf - s.pdf).abs() <= 1e-9 * s.pdf,
        "sample pdf {} but pdf(wi, wo) = {pdf}",
        s.pdf
    );
    Ok(())
}

fn check_pdf(
    brdf: &dyn Brdf,
    wi: Vec3<f64>,
    wo: Vec3<f64>,
    seed: u64,
) -> Result<(), TestCaseError> {
    let pdf = brdf.pdf(wi, wo);
    prop_assert!(pdf.is_finite() && pdf >= 0.0, "pdf {pdf}");
    let f = brdf.eval(wi, wo, &mut rng_stream(seed, 0)).total();
    prop_assert!(
        pdf > 0.0 || f.iter().all(|&x| x <= 0.0),
        "pdf 0 where f = {f:?}"
    );
    Ok(())
}

fn check_below_horizon(
    brdf: &dyn Brdf,
    up: Vec3<f64>,
    down: Vec3<f64>,
    seed: u64,
) -> Result<(), TestCaseError> {
    let mut rng = rng_stream(seed, 0);
    for (wi, wo) in [(up, down), (down, up), (down, down)] {
        let value = brdf.eval(wi, wo, &mut rng);
        prop_assert!(value.total() == [0.0; 3], "f({wi:?}, {wo:?}) = {value:?}");
        prop_assert!(
            brdf.pdf(wi, wo) == 0.0,
            "pdf({wi:?}, {wo:?}) = {}",
            brdf.pdf(wi, wo)
        );
    }
    prop_assert!(
        brdf.sample(down, [0.5, 0.5], &mut rng).is_none(),
        "sampled from below"
    );
    Ok(())
}

fn check_exact_reciprocity(
    brdf: &dyn Brdf,
    wi: Vec3<f64>,
    wo: Vec3<f64>,
) -> Result<(), TestCaseError> {
    let mut rng = rng_stream(0, 0);
    let (forward, backward) = (
        brdf.eval(wi, wo, &mut rng).total(),
        brdf.eval(wo, wi, &mut rng).total(),
    );
    for c in 0..3 {
        prop_assert!(
            (forward[c] - backward[c]).abs()
                <= EXACT_RECIPROCITY_TOLERANCE * forward[c].abs().max(backward[c].abs()),
            "f(wi, wo) = {forward:?} but f(wo, wi) = {backward:?}"
        );
    }
    Ok(())
}

/// The three properties every model must have, as one module of tests per model.
macro_rules! properties_of_every_model {
    ($($name:ident => $model:expr),* $(,)?) => {
        /// The models the macro generated tests for.
        const COVERED: &[Model] = &[$($model),*];
        $(mod $name {
            use super::*;

            proptest! {
                #![proptest_config(config(CASES))]

                #[test]
                fn eval_is_finite_and_non_negative(
                    m in material($model), (wi, wo) in direction_pair(), seed in any::<u64>()
                ) {
                    check_eval(m.brdf().as_ref(), wi, wo, seed)?;
                }

                #[test]
                fn samples_are_valid(
                    m in material($model), wi in direction(), u in unit_square(), seed in any::<u64>()
                ) {
                    check_sample(m.brdf().as_ref(), wi, u, seed)?;
                }

                #[test]
                fn pdf_is_finite_and_covers_eval(
                    m in material($model), (wi, wo) in direction_pair(), seed in any::<u64>()
                ) {
                    check_pdf(m.brdf().as_ref(), wi, wo, seed)?;
                }

                #[test]
                fn nothing_below_the_horizon(
                    m in material($model), up in direction(), down in below_horizon(), seed in any::<u64>()
                ) {
                    check_below_horizon(m.brdf().as_ref(), up, down, seed)?;
                }
            }
        })*
    };
}

properties_of_every_model! {
    single => Model::Single,
    heitz => Model::Heitz,
    bitterli => Model::Bitterli,
    cui => Model::Cui,
    wang_pt => Model::WangPt,
    wang_bdpt => Model::WangBdpt,
    fast_msx => Model::FastMsx,
    kulla_conty => Model::KullaConty,
    turquin => Model::Turquin,
    tabulated => Model::Tabulated,
}

#[test]
fn every_model_has_its_properties_module() {
    for model in Model::ALL {
        assert!(COVERED.contains(&model), "{model} has no property tests");
    }
}

proptest! {
    #![proptest_config(config(CASES))]

    #[test]
    fn analytic_reciprocal_models_are_exactly_reciprocal(
        m in prop_oneof![material(Model::Single), material(Model::KullaConty)],
        (wi, wo) in direction_pair(),
    ) {
        check_exact_reciprocity(m.brdf().as_ref(), wi, wo)?;
    }
}

/// A stochastic model whose reciprocity the table of `src/bsdf/mod.rs` asserts, with
/// roughness of at least 0.1 (see [`stochastic_reciprocal_models_are_reciprocal_in_expectation`]).
fn reciprocal_stochastic_material() -> impl Strategy<Value = Material> {
    let rough = |model| material_rougher_than(model, -1.0);
    prop_oneof![
        rough(Model::Heitz),
        rough(Model::Bitterli),
        rough(Model::Cui),
        rough(Model::WangPt),
        rough(Model::WangBdpt),
    ]
    .prop_map(|mut m| {
        m.height = Height::Uncorrelated;
        m
    })
}

/// Directions at most 80 degrees from the normal, for the stochastic reciprocity test.
fn non_grazing_direction() -> impl Strategy<Value = Vec3<f64>> {
    (0.0..=80.0f64, 0.0..std::f64::consts::TAU).prop_map(|(t, phi)| polar(t, phi))
}

proptest! {
    // A Monte Carlo comparison: fixed seed, so the z threshold bounds the false-alarm rate of
    // one fixed set of configurations (see RECIPROCITY_Z). The measured standard error is a
    // trustworthy sigma only where the estimators are not dominated by rare paths: on
    // near-specular surfaces (alpha < 0.1) or at grazing angles a one-sided estimate can sit
    // far below its expectation with a small measured error. For example `wang-pt` and `cui`
    // at alpha 0.01 with `wi` = normal and `wo` at 28 degrees give a multi-bounce part of
    // 5e-8 +- 2e-8 from 20 000 evaluations against 1.02e-5 from the other side (and from
    // `bitterli` and `wang-bdpt` both ways); 2e5 evaluations give 1.3e-5 +- 1.3e-5. Those
    // configurations test the estimator's variance, not reciprocity, and are left out.
    #![proptest_config(Config {
        rng_seed: RngSeed::Fixed(6),
        ..config(STOCHASTIC_RECIPROCITY_CASES)
    })]

    #[test]
    fn stochastic_reciprocal_models_are_reciprocal_in_expectation(
        m in reciprocal_stochastic_material(),
        (wi, wo) in (non_grazing_direction(), non_grazing_direction()),
        seed in any::<u64>(),
    ) {
        let brdf = m.brdf();
        let forward = mean_eval(brdf.as_ref(), wi, wo, RECIPROCITY_EVALS, seed);
        let backward = mean_eval(brdf.as_ref(), wo, wi, RECIPROCITY_EVALS, seed ^ 1);
        for c in 0..3 {
            let z = z_score(&forward, &backward, c);
            prop_assert!(z < RECIPROCITY_Z, "z = {z}: {forward:?} vs {backward:?}");
        }
    }
}

//! The batch kernel against the scalar reference: the same renders, and tangents equal to the
//! dual-number derivatives of the scalar kernel, over random and grazing geometry.

use super::*;
use crate::bsdf::registry::differentiable;
use crate::bsdf::testing::random_upper;
use crate::bsdf::BounceCap;
use crate::microfacet::Microfacet;
use crate::render::render_model;
use crate::scalar::{Real, Rgb};
use crate::shading::PhotoSpan;
use rand::{Rng as _, SeedableRng};

/// `pixels` pixels of 4 sub-samples with random directions above the horizon, a quarter of them
/// grazing (z below 1e-3), some with no light and some with a direction below the horizon.
fn random_records(pixels: usize, seed: u64) -> ShadingRecords {
    let spp = 4;
    let mut rng = crate::random::Rng::seed_from_u64(seed);
    let direction = |rng: &mut crate::random::Rng| {
        let mut w = random_upper(rng);
        if rng.random::<f64>() < 0.25 {
            let z = rng.random::<f64>() * 1e-3;
            let s = (1.0 - z * z).sqrt() / (w.x * w.x + w.y * w.y).sqrt();
            w = crate::scalar::Vec3::new(w.x * s, w.y * s, z);
        }
        [w.x, w.y, w.z]
    };
    let n = pixels * spp;
    let mut records = ShadingRecords {
        photos: vec![PhotoSpan {
            stem: "random".into(),
            width: pixels,
            height: 1,
            first_pixel: 0,
        }],
        samples_per_pixel: spp,
        ..ShadingRecords::default()
    };
    for s in 0..n {
        let mut wi = direction(&mut rng);
        let wo = direction(&mut rng);
        if s % 13 == 5 {
            wi[2] = -wi[2];
        }
        let e = if s % 11 == 3 {
            [0.0; 3]
        } else {
            [0.5, 1.0, 2.0].map(|c| c * rng.random::<f64>())
        };
        records.wi.push(wi);
        records.wo.push(wo);
        records.irradiance.push(e);
    }
    records.target = vec![[0.0; 3]; pixels];
    records.weight = vec![1.0; pixels];
    records
}

fn fresnels() -> Vec<Fresnel<f64>> {
    vec![
        Fresnel::White,
        Fresnel::Schlick {
            f0: Rgb([0.04, 0.5, 0.95]),
        },
        Fresnel::Conductor {
            eta: Rgb([0.2378, 1.0066, 1.2404]),
            k: Rgb([3.6264, 2.5823, 2.3929]),
        },
        Fresnel::Dielectric { eta: 1.5 },
    ]
}

fn surfaces() -> Vec<SingleBounce<f64>> {
    let mut out = Vec::new();
    for ndf in [NdfKind::Ggx, NdfKind::Beckmann] {
        for height in [Height::Correlated, Height::Uncorrelated] {
            for (ax, ay) in [
                (1e-4, 1e-4),
                (0.05, 0.05),
                (0.3, 0.3),
                (0.2, 0.7),
                (3.0, 1.5),
            ] {
                for fresnel in fresnels() {
                    out.push(SingleBounce {
                        microfacet: Microfacet::new(ndf, ax, ay),
                        fresnel,
                        height,
                    });
                }
            }
        }
    }
    out
}

/// Largest relative difference over pixels and channels, against the pixel's largest channel
/// (at least `floor`).
fn worst_relative_above(a: &[[f64; 3]], b: &[[f64; 3]], floor: f64) -> f64 {
    a.iter()
        .zip(b)
        .flat_map(|(x, y)| {
            let scale = x.iter().chain(y).fold(floor, |m, v| m.max(v.abs()));
            (0..3).map(move |c| (x[c] - y[c]).abs() / scale)
        })
        .fold(0.0, f64::max)
}

/// [`worst_relative_above`] for `f64` results.
fn worst_relative(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    worst_relative_above(a, b, 1e-300)
}

/// Magnitudes below which a precision has no relative accuracy left to test: `f32`'s smallest
/// normal over its epsilon, 1e-31 (a Beckmann lobe at alpha 0.05 far from the peak is
/// 1e-40 in `f64` and 0 in `f32`).
fn floor(precision: Precision) -> f64 {
    match precision {
        Precision::F64 => 1e-300,
        Precision::F32 => (f32::MIN_POSITIVE / f32::EPSILON) as f64,
    }
}

/// Each lane precision with the largest relative difference from the scalar `f64` kernel its
/// values and its tangents may show. `f64` lanes only reorder the operations. `f32` lanes round
/// the geometry once and carry about 30 roundings of `u = 2^-24 = 6e-8` per record: values
/// within `30 u = 2e-6`; the tangents subtract `d ln D` and `d ln q` terms of opposite sign
/// (`4 h^2 / (a^3 t)` against `1 / a`), which can lose a further factor of 100 where the
/// lobe's derivative passes through zero: the worst measured over these surfaces is 1.7e-4 of
/// the pixel's largest tangent (GGX at alpha 1e-4, uncorrelated, with Turquin's scale), so
/// `5e-4`. A wrong formula differs by order one.
const PRECISIONS: [(Precision, f64, f64); 2] =
    [(Precision::F64, 1e-12, 1e-9), (Precision::F32, 2e-6, 5e-4)];

/// The models whose whole value the batch kernel evaluates, other than `single`.
const ADDED: [Model; 3] = [Model::Turquin, Model::KullaConty, Model::FastMsx];

/// The scalar kernel's render of `model` on `single` (at any scalar type).
fn scalar_render<T: Real>(
    model: Model,
    single: SingleBounce<T>,
    diffuse: [T; 3],
    records: &ShadingRecords,
    pixels: &[usize],
) -> Vec<[T; 3]> {
    let brdf = differentiable(model, single, BounceCap::NONE).expect("an analytic model");
    render_model(brdf.as_ref(), diffuse, records, pixels, 0)
}

#[test]
fn turquin_batch_render_equals_its_scalar_render() {
    check_renders(Model::Turquin, 2000, 9);
}

#[test]
fn kulla_conty_batch_render_equals_its_scalar_render() {
    check_renders(Model::KullaConty, 2000, 5);
}

#[test]
fn fast_msx_batch_render_equals_its_scalar_render() {
    check_renders(Model::FastMsx, 2000, 13);
}

#[test]
fn batch_render_equals_the_scalar_render() {
    check_renders(Model::Single, 3000, 7);
}

/// Batch renders of `model` on every surface over `pixels` random pixels against the scalar
/// kernel's, in both lane precisions: finite, non-negative and within the precision's bound.
fn check_renders(model: Model, pixels: usize, seed: u64) {
    let records = random_records(pixels, seed);
    let pixels: Vec<usize> = (0..records.pixel_count()).collect();
    let diffuse = [0.1, 0.2, 0.3];
    for (precision, tolerance, _) in PRECISIONS {
        let batch = BatchRecords::for_model(&records, &pixels, precision, model);
        let mut worst_of_all: f64 = 0.0;
        for single in surfaces() {
            let reference = scalar_render(model, single, diffuse, &records, &pixels);
            let lobe = Lobe::of(model, &single).expect("served");
            let fast = batch.render(lobe, diffuse);
            assert!(fast.iter().flatten().all(|v| v.is_finite() && *v >= 0.0));
            let worst = worst_relative_above(&reference, &fast, floor(precision));
            worst_of_all = worst_of_all.max(worst);
            assert!(
                worst < tolerance,
                "{model} {precision:?} {single:?}: worst relative difference {worst:e}"
            );
        }
        eprintln!("{model} {precision:?}: worst {worst_of_all:e}");
    }
}

/// The corner of a fit's conductor space, reflectivity at its cap
/// ([`crate::microfacet::fresnel::MAX_REFLECTIVITY`]) with edge tints 0, 0.5 and 1 (`eta` up
/// to 4e4), renders finite and non-negative values and tangents in both lane precisions, for
/// every model the kernel serves, near the scalar kernel's values. The conductor's formula
/// cancels `eta^2 - k^2` of order 1e9 there, so the bound is wider than [`PRECISIONS`]'s
/// (measured: `f64` within 3.2e-12, `f32` within 2.8e-6, `turquin` at alpha 3). Without the
/// cap `eta` reached 4e11 and the `f32` lanes overflowed to NaN.
#[test]
fn the_corner_of_the_conductor_space_renders_finite_in_both_precisions() {
    let records = random_records(500, 17);
    let pixels: Vec<usize> = (0..records.pixel_count()).collect();
    let [(e0, k0), (e1, k1), (e2, k2)] = [0.0, 0.5, 1.0]
        .map(|g| crate::microfacet::fresnel::ior_from_reflectivity_edge_tint(1.0, g));
    let fresnel = Fresnel::Conductor {
        eta: Rgb([e0, e1, e2]),
        k: Rgb([k0, k1, k2]),
    };
    for model in [
        Model::Single,
        Model::Turquin,
        Model::KullaConty,
        Model::FastMsx,
    ] {
        for (precision, bound) in [(Precision::F64, 1e-11), (Precision::F32, 1e-5)] {
            let batch = BatchRecords::for_model(&records, &pixels, precision, model);
            for alpha in [1e-4, 0.3, 3.0] {
                let single = SingleBounce {
                    microfacet: Microfacet::new(NdfKind::Ggx, alpha, alpha),
                    fresnel,
                    height: Height::Correlated,
                };
                let lobe = Lobe::of(model, &single).expect("served");
                let (values, tangents) = batch.render_with_tangents(lobe, [0.1; 3]);
                let reference = scalar_render(model, single, [0.1; 3], &records, &pixels);
                let finite = |v: &[[f64; 3]]| v.iter().flatten().all(|x| x.is_finite());
                assert!(finite(&values) && values.iter().flatten().all(|v| *v >= 0.0));
                for t in [&tangents.ax, &tangents.fresnel_a, &tangents.fresnel_b] {
                    assert!(finite(t), "{model} {precision:?} alpha {alpha}");
                }
                let worst = worst_relative_above(&reference, &values, floor(precision));
                assert!(
                    worst < bound,
                    "{model} {precision:?} alpha {alpha}: {worst:e}"
                );
            }
        }
    }
}

/// The derivatives of the scalar kernel's render of `model` by one of the kernel's parameters:
/// `single` in dual numbers seeded as [`seeded`] seeds it.
fn dual_render(
    model: Model,
    single: SingleBounce<Dual64>,
    records: &ShadingRecords,
    pixels: &[usize],
) -> Vec<[f64; 3]> {
    let render = scalar_render(model, single, [Dual64::c(0.0); 3], records, pixels);
    render.iter().map(|p| p.map(|v| v.eps)).collect()
}

#[test]
fn tangents_equal_the_dual_number_derivatives_of_the_scalar_kernel() {
    check_tangents(Model::Single);
}

#[test]
fn added_lobe_tangents_equal_the_dual_number_derivatives_of_the_scalar_kernel() {
    for model in ADDED {
        check_tangents(model);
    }
}

fn check_tangents(model: Model) {
    for (precision, _, tolerance) in PRECISIONS {
        check_tangents_in(precision, tolerance, model);
    }
}

fn check_tangents_in(precision: Precision, tolerance: f64, model: Model) {
    let records = random_records(1500, 11);
    let pixels: Vec<usize> = (0..records.pixel_count()).collect();
    let batch = BatchRecords::for_model(&records, &pixels, precision, model);
    let worst_of_all = std::cell::Cell::new(0.0_f64);
    for single in surfaces() {
        let lobe = Lobe::of(model, &single).expect("served");
        let (_, t) = batch.render_with_tangents(lobe, [0.0; 3]);
        let check = |name: &str, fast: &[[f64; 3]], exact: Vec<[f64; 3]>| {
            let worst = worst_relative_above(&exact, fast, floor(precision));
            worst_of_all.set(worst_of_all.get().max(worst));
            assert!(
                worst < tolerance,
                "{model} {precision:?} {single:?} d/d{name}: worst {worst:e}"
            );
        };
        let [by_ax, by_ay, by_a, by_b] =
            seeded(&single).map(|s| dual_render(model, s, &records, &pixels));
        check("ax", &t.ax, by_ax);
        check("ay", &t.ay, by_ay);
        match single.fresnel {
            Fresnel::Schlick { .. } => check("F0", &t.fresnel_a, by_a),
            Fresnel::Conductor { .. } => {
                check("eta", &t.fresnel_a, by_a);
                check("k", &t.fresnel_b, by_b);
            }
            Fresnel::White | Fresnel::Dielectric { .. } => {
                assert!(t
                    .fresnel_a
                    .iter()
                    .chain(&t.fresnel_b)
                    .flatten()
                    .all(|&v| v == 0.0));
            }
        }
        let white = render_model(
            &SingleBounce {
                fresnel: Fresnel::White,
                ..single
            },
            [1.0; 3],
            &records,
            &pixels,
            0,
        );
        let no_diffuse = render_model(
            &SingleBounce {
                fresnel: Fresnel::White,
                ..single
            },
            [0.0; 3],
            &records,
            &pixels,
            0,
        );
        let lambert: Vec<[f64; 3]> = white
            .iter()
            .zip(&no_diffuse)
            .map(|(a, b)| [0, 1, 2].map(|c| a[c] - b[c]))
            .collect();
        assert!(worst_relative(&lambert, &t.diffuse) < 1e-9);
    }
    eprintln!(
        "{model} {precision:?}: worst tangent {:e}",
        worst_of_all.get()
    );
}

#[test]
fn batch_render_is_the_same_for_any_thread_count() {
    let records = random_records(5000, 3);
    let pixels: Vec<usize> = (0..records.pixel_count()).collect();
    let batch = BatchRecords::new(&records, &pixels);
    assert_eq!(batch.precision(), Precision::F32);
    let single = surfaces()[17];
    for model in [Model::Single, Model::KullaConty] {
        let lobe = Lobe::of(model, &single).expect("served");
        let in_pool = |threads: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| batch.render_with_tangents(lobe, [0.1; 3]))
        };
        let (one, t1) = in_pool(1);
        let (two, t2) = in_pool(2);
        assert_eq!(one, two);
        for (a, b) in [
            (&t1.ax, &t2.ax),
            (&t1.ay, &t2.ay),
            (&t1.fresnel_a, &t2.fresnel_a),
            (&t1.fresnel_b, &t2.fresnel_b),
        ] {
            assert_eq!(a, b);
        }
    }
}

/// The kernel's `expm1` covers the albedo tables: every `ln E` lies where its series and
/// doublings are accurate (`|x| <= 8`), and there it agrees with `f64::exp_m1` to 1e-14
/// relative (a wrong coefficient or doubling count errs by order one).
#[test]
fn expm1_covers_the_albedo_tables() {
    for ndf in [NdfKind::Ggx, NdfKind::Beckmann] {
        for height in [Height::Correlated, Height::Uncorrelated] {
            let table = AlbedoTable::get(ndf, height);
            for alpha in [1e-4f64, 0.01, 0.3, 1.0, 3.0] {
                for v in table.ln_e_row(alpha) {
                    assert!(v.abs() <= 8.0, "{ndf:?} {height:?} alpha {alpha}: ln E {v}");
                }
            }
        }
    }
    let mut x = -8.0;
    while x <= 8.0 {
        let exact = f64::exp_m1(x);
        let relative = (expm1(x) / exact - 1.0).abs();
        assert!(relative < 1e-14 || x == 0.0, "expm1({x}): {relative:e}");
        x += 0.0137;
    }
    // Near 0, where `e^x - 1` by a subtraction would keep no digits.
    assert!((expm1(1e-9f64) / f64::exp_m1(1e-9) - 1.0).abs() < 1e-15);
}

/// The record-major blocks ([`Block`]) keep the pixels' sums exact: a pixel none of whose
/// sub-samples is a record (all unlit, or all with `wo` below the horizon) gets its Lambertian
/// layer alone and zero tangents from its padded slots; and the fused value pass
/// ([`fused_lanes`]) gives the values of the separate passes of the tangents' render to the
/// bit (GGX, Schlick, both lane precisions), over pixels of 0 to 4 records.
#[test]
fn padded_slots_add_nothing_and_the_fused_pass_is_the_tangent_pass() {
    let mut records = random_records(3000, 5);
    let spp = records.samples_per_pixel;
    // Pixels 7 and 2000: no records (unlit; below the horizon), beside full pixels.
    for s in 7 * spp..8 * spp {
        records.irradiance[s] = [0.0; 3];
    }
    for s in 2000 * spp..2001 * spp {
        records.wo[s][2] = -records.wo[s][2].abs();
    }
    let pixels: Vec<usize> = (0..records.pixel_count()).collect();
    let diffuse = [0.1, 0.2, 0.3];
    let schlick = Fresnel::Schlick {
        f0: Rgb([0.9, 0.6, 0.04]),
    };
    for precision in [Precision::F32, Precision::F64] {
        let batch = BatchRecords::with_precision(&records, &pixels, precision);
        for single in surfaces() {
            if single.microfacet.ndf != NdfKind::Ggx {
                continue;
            }
            let single = SingleBounce {
                fresnel: schlick,
                ..single
            };
            let values = batch.render(&single, diffuse);
            let (with_tangents, tangents) = batch.render_with_tangents(&single, diffuse);
            assert_eq!(values, with_tangents, "{precision:?} {single:?}");
            for p in [7, 2000] {
                let lambert = batch.lambert()[p];
                assert_eq!(values[p], [0, 1, 2].map(|c| diffuse[c] * lambert[c]));
                for lane in [&tangents.ax, &tangents.ay, &tangents.fresnel_a] {
                    assert_eq!(lane[p], [0.0; 3]);
                }
            }
        }
    }
}

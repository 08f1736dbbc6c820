//! The batch kernel against the scalar reference: the same renders, and tangents equal to the
//! dual-number derivatives of the scalar kernel, over random and grazing geometry.

use super::*;
use crate::bsdf::testing::random_upper;
use crate::bsdf::turquin::Turquin;
use crate::microfacet::Microfacet;
use crate::render::render_model;
use crate::scalar::{Real, Rgb};
use crate::shading::PhotoSpan;
use rand::{Rng as _, SeedableRng};

/// `pixels` pixels of 4 sub-samples with random directions above the horizon, a quarter of them
/// grazing (z below 1e-3), some with no light and some with a direction below the horizon.
fn random_records(pixels: usize, seed: u64) -> ShadingRecords {
    let spp = 4;
    let mut rng = crate::bsdf::Rng::seed_from_u64(seed);
    let direction = |rng: &mut crate::bsdf::Rng| {
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

/// The batch lobe of `single`, with Turquin's compensation when `turquin`.
fn lobe(single: &SingleBounce<f64>, turquin: bool) -> Lobe<'_> {
    Lobe {
        single,
        turquin: turquin.then(|| AlbedoTable::get(single.microfacet.ndf, single.height)),
    }
}

#[test]
fn turquin_batch_render_equals_its_scalar_render() {
    check_renders(true, 2000, 9);
}

#[test]
fn batch_render_equals_the_scalar_render() {
    check_renders(false, 3000, 7);
}

/// Batch renders of every surface (Turquin-scaled when `turquin`) over `pixels` random pixels
/// against the scalar kernel's, in both lane precisions: finite, non-negative and within the
/// precision's bound.
fn check_renders(turquin: bool, pixels: usize, seed: u64) {
    let records = random_records(pixels, seed);
    let pixels: Vec<usize> = (0..records.pixel_count()).collect();
    let diffuse = [0.1, 0.2, 0.3];
    for (precision, tolerance, _) in PRECISIONS {
        let batch = BatchRecords::with_precision(&records, &pixels, precision);
        let mut worst_of_all: f64 = 0.0;
        for single in surfaces() {
            let reference = if turquin {
                render_model(&Turquin::new(single), diffuse, &records, &pixels, 0)
            } else {
                render_model(&single, diffuse, &records, &pixels, 0)
            };
            let fast = batch.render(lobe(&single, turquin), diffuse);
            assert!(fast.iter().flatten().all(|v| v.is_finite() && *v >= 0.0));
            let worst = worst_relative_above(&reference, &fast, floor(precision));
            worst_of_all = worst_of_all.max(worst);
            assert!(
                worst < tolerance,
                "{precision:?} {single:?}: worst relative difference {worst:e}"
            );
        }
        eprintln!("{precision:?}: worst {worst_of_all:e}");
    }
}

/// The scalar kernel in dual numbers with the derivative seeded on one parameter.
fn dual_render(
    single: &SingleBounce<f64>,
    turquin: bool,
    records: &ShadingRecords,
    pixels: &[usize],
    seed: impl Fn(&mut SingleBounce<Dual64>),
) -> Vec<[f64; 3]> {
    let lift = |v: f64| Dual64::from_re(v);
    let mut dual = SingleBounce {
        microfacet: Microfacet::new(
            single.microfacet.ndf,
            lift(single.microfacet.ax),
            lift(single.microfacet.ay),
        ),
        fresnel: match single.fresnel {
            Fresnel::White => Fresnel::White,
            Fresnel::Schlick { f0 } => Fresnel::Schlick {
                f0: Rgb(f0.0.map(lift)),
            },
            Fresnel::Conductor { eta, k } => Fresnel::Conductor {
                eta: Rgb(eta.0.map(lift)),
                k: Rgb(k.0.map(lift)),
            },
            Fresnel::Dielectric { eta } => Fresnel::Dielectric { eta: lift(eta) },
        },
        height: single.height,
    };
    seed(&mut dual);
    let zero = [Dual64::c(0.0); 3];
    let render = if turquin {
        render_model(&Turquin::new(dual), zero, records, pixels, 0)
    } else {
        render_model(&dual, zero, records, pixels, 0)
    };
    render.iter().map(|p| p.map(|v| v.eps)).collect()
}

#[test]
fn tangents_equal_the_dual_number_derivatives_of_the_scalar_kernel() {
    check_tangents(false);
}

#[test]
fn turquin_tangents_equal_the_dual_number_derivatives_of_its_scalar_kernel() {
    check_tangents(true);
}

fn check_tangents(turquin: bool) {
    for (precision, _, tolerance) in PRECISIONS {
        check_tangents_in(precision, tolerance, turquin);
    }
}

fn check_tangents_in(precision: Precision, tolerance: f64, turquin: bool) {
    let records = random_records(1500, 11);
    let pixels: Vec<usize> = (0..records.pixel_count()).collect();
    let batch = BatchRecords::with_precision(&records, &pixels, precision);
    let worst_of_all = std::cell::Cell::new(0.0_f64);
    for single in surfaces() {
        let (_, t) = batch.render_with_tangents(lobe(&single, turquin), [0.0; 3]);
        let check = |name: &str, fast: &[[f64; 3]], exact: Vec<[f64; 3]>| {
            let worst = worst_relative_above(&exact, fast, floor(precision));
            worst_of_all.set(worst_of_all.get().max(worst));
            if worst > 2e-5 {
                eprintln!("DEBUG {precision:?} {single:?} {name} {worst:e}");
            }
            assert!(
                worst < tolerance,
                "{precision:?} {single:?} d/d{name}: worst {worst:e}"
            );
        };
        check(
            "ax",
            &t.ax,
            dual_render(&single, turquin, &records, &pixels, |s| {
                s.microfacet.ax = s.microfacet.ax.derivative()
            }),
        );
        check(
            "ay",
            &t.ay,
            dual_render(&single, turquin, &records, &pixels, |s| {
                s.microfacet.ay = s.microfacet.ay.derivative()
            }),
        );
        // Channel c of a pixel depends only on channel c's Fresnel parameters, so seeding all
        // three channels at once gives each channel its own derivative.
        match single.fresnel {
            Fresnel::Schlick { .. } => check(
                "F0",
                &t.fresnel_a,
                dual_render(&single, turquin, &records, &pixels, |s| {
                    if let Fresnel::Schlick { f0 } = &mut s.fresnel {
                        *f0 = f0.map(|v| v.derivative());
                    }
                }),
            ),
            Fresnel::Conductor { .. } => {
                check(
                    "eta",
                    &t.fresnel_a,
                    dual_render(&single, turquin, &records, &pixels, |s| {
                        if let Fresnel::Conductor { eta, .. } = &mut s.fresnel {
                            *eta = eta.map(|v| v.derivative());
                        }
                    }),
                );
                check(
                    "k",
                    &t.fresnel_b,
                    dual_render(&single, turquin, &records, &pixels, |s| {
                        if let Fresnel::Conductor { k, .. } = &mut s.fresnel {
                            *k = k.map(|v| v.derivative());
                        }
                    }),
                );
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
    eprintln!("{precision:?}: worst tangent {:e}", worst_of_all.get());
}

#[test]
fn batch_render_is_the_same_for_any_thread_count() {
    let records = random_records(5000, 3);
    let pixels: Vec<usize> = (0..records.pixel_count()).collect();
    let batch = BatchRecords::new(&records, &pixels);
    assert_eq!(batch.precision(), Precision::F32);
    let single = surfaces()[17];
    let in_pool = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| batch.render_with_tangents(&single, [0.1; 3]))
    };
    let (one, t1) = in_pool(1);
    let (two, t2) = in_pool(2);
    assert_eq!(one, two);
    assert_eq!(t1.ax, t2.ax);
    assert_eq!(t1.fresnel_a, t2.fresnel_a);
}

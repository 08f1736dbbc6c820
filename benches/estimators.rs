//! Time per BRDF evaluation of every model (`Model::ALL`) at equal sample count: one `eval`
//! (for stochastic models one path estimate of the multi-bounce part plus the exact single
//! bounce) on rough copper, alpha 0.5, GGX, over a fixed set of 256 direction pairs per
//! iteration (divide criterion's time by 256). Run: `cargo bench --bench estimators`.
//!
//! Group `bounce_cap`: the stochastic models at alpha 0.3 and 1.0 on the same pairs, free and
//! limited to the reflections the render plan's `bounce-cap` chooses at that roughness.

use bouncefit::bsdf::bounce_tails::BounceTails;
use bouncefit::bsdf::{BounceCap, Brdf, Model};
use bouncefit::material::{FresnelSpec, Material};
use bouncefit::microfacet::{Height, NdfKind};
use bouncefit::random::rng_stream;
use bouncefit::render::plan::BOUNCE_TOLERANCE;
use bouncefit::scalar::Vec3;
use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use rand::Rng;
use std::hint::black_box;

const N: usize = 256;

/// `N` direction pairs above the surface, the same in every group.
fn direction_pairs() -> Vec<(Vec3<f64>, Vec3<f64>)> {
    let mut rng = rng_stream(7, 0);
    let mut unit = || {
        let (z, phi): (f64, f64) = (
            rng.random_range(0.05..1.0),
            rng.random_range(0.0..std::f64::consts::TAU),
        );
        let r = (1.0 - z * z).sqrt();
        Vec3::new(r * phi.cos(), r * phi.sin(), z)
    };
    (0..N).map(|_| (unit(), unit())).collect()
}

fn copper(model: Model, alpha: f64) -> Material {
    Material {
        model,
        ndf: NdfKind::Ggx,
        height: Height::Correlated,
        alpha: [alpha, alpha],
        fresnel: FresnelSpec::Conductor {
            eta: [0.2378, 1.0066, 1.2404],
            k: [3.6264, 2.5823, 2.3929],
        },
        diffuse: [0.0; 3],
    }
}

/// Criterion's timing of `brdf.eval` over every pair of `dirs`.
fn time_eval(
    group: &mut criterion::BenchmarkGroup<'_, criterion::measurement::WallTime>,
    name: &str,
    brdf: &dyn Brdf,
    dirs: &[(Vec3<f64>, Vec3<f64>)],
) {
    let mut rng = rng_stream(1, 0);
    // Build any lazily computed tables before timing.
    brdf.eval(dirs[0].0, dirs[0].1, &mut rng);
    group.bench_function(name, |b| {
        b.iter(|| {
            dirs.iter()
                .map(|(wi, wo)| brdf.eval(black_box(*wi), black_box(*wo), &mut rng).total()[0])
                .sum::<f64>()
        })
    });
}

fn estimators(c: &mut Criterion) {
    let dirs = direction_pairs();
    let mut group = c.benchmark_group("eval");
    group.throughput(Throughput::Elements(N as u64));
    for model in Model::ALL {
        time_eval(
            &mut group,
            model.name(),
            copper(model, 0.5).brdf().as_ref(),
            &dirs,
        );
    }
    group.finish();
}

fn bounce_cap(c: &mut Criterion) {
    let dirs = direction_pairs();
    let mut group = c.benchmark_group("bounce_cap");
    group.throughput(Throughput::Elements(N as u64));
    for model in [
        Model::Heitz,
        Model::Bitterli,
        Model::Cui,
        Model::WangPt,
        Model::WangBdpt,
    ] {
        for alpha in [0.3, 1.0] {
            let material = copper(model, alpha);
            let tails = BounceTails::get(model, material.ndf, material.height).expect("a walk");
            let cap = tails.cap(alpha, BOUNCE_TOLERANCE);
            for (label, cap) in [("free", BounceCap::NONE), ("capped", cap)] {
                let name = format!("{model}/{alpha}/{label}-{:?}", cap.get());
                time_eval(&mut group, &name, material.capped_brdf(cap).as_ref(), &dirs);
            }
        }
    }
    group.finish();
}

criterion_group!(benches, estimators, bounce_cap);
criterion_main!(benches);

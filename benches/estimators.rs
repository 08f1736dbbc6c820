//! Time per BRDF evaluation of every model (`Model::ALL`) at equal sample count: one `eval`
//! (for stochastic models one path estimate of the multi-bounce part plus the exact single
//! bounce) on rough copper, alpha 0.5, GGX, over a fixed set of 256 direction pairs per
//! iteration (divide criterion's time by 256). Run: `cargo bench --bench estimators`.

use bouncefit::albedo::rng_stream;
use bouncefit::bsdf::Model;
use bouncefit::material::{FresnelSpec, Material};
use bouncefit::microfacet::{Height, NdfKind};
use bouncefit::scalar::Vec3;
use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use rand::Rng;
use std::hint::black_box;

const N: usize = 256;

fn estimators(c: &mut Criterion) {
    let mut rng = rng_stream(7, 0);
    let mut unit = || {
        let (z, phi): (f64, f64) = (
            rng.random_range(0.05..1.0),
            rng.random_range(0.0..std::f64::consts::TAU),
        );
        let r = (1.0 - z * z).sqrt();
        Vec3::new(r * phi.cos(), r * phi.sin(), z)
    };
    let dirs: Vec<(Vec3<f64>, Vec3<f64>)> = (0..N).map(|_| (unit(), unit())).collect();
    let mut group = c.benchmark_group("eval");
    group.throughput(Throughput::Elements(N as u64));
    for model in Model::ALL {
        let material = Material {
            model,
            ndf: NdfKind::Ggx,
            height: Height::Correlated,
            alpha: [0.5, 0.5],
            fresnel: FresnelSpec::Conductor {
                eta: [0.2378, 1.0066, 1.2404],
                k: [3.6264, 2.5823, 2.3929],
            },
            diffuse: [0.0; 3],
        };
        let brdf = material.brdf();
        let mut rng = rng_stream(1, 0);
        // Build any lazily computed tables before timing.
        brdf.eval(dirs[0].0, dirs[0].1, &mut rng);
        group.bench_function(model.name(), |b| {
            b.iter(|| {
                dirs.iter()
                    .map(|(wi, wo)| brdf.eval(black_box(*wi), black_box(*wo), &mut rng).total()[0])
                    .sum::<f64>()
            })
        });
    }
    group.finish();
}

criterion_group!(benches, estimators);
criterion_main!(benches);

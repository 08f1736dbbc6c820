//! Criterion benchmarks of the microfacet kernel and the single-bounce model, so regressions show.
//! Run with `cargo bench --bench kernels`. Each benchmark evaluates a fixed set of 1024 random
//! configurations per iteration; criterion reports the time of the whole set, so divide by 1024
//! for the time per call.

use bouncefit::bsdf::single::SingleBounce;
use bouncefit::microfacet::fresnel::conductor;
use bouncefit::microfacet::{Fresnel, Height, Microfacet, NdfKind};
use bouncefit::random::rng_stream;
use bouncefit::scalar::{Rgb, Vec3};
use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use rand::Rng;
use std::hint::black_box;

const N: usize = 1024;

fn directions(seed: u64) -> Vec<(Vec3<f64>, Vec3<f64>)> {
    let mut rng = rng_stream(seed, 0);
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

fn copper<T: bouncefit::scalar::Real>() -> Fresnel<T> {
    Fresnel::Conductor {
        eta: Rgb::from_f64([0.2378, 1.0066, 1.2404]),
        k: Rgb::from_f64([3.6264, 2.5823, 2.3929]),
    }
}

fn kernels(c: &mut Criterion) {
    let dirs = directions(1);
    let mut group = c.benchmark_group("kernel");
    group.throughput(Throughput::Elements(N as u64));
    for ndf in [NdfKind::Ggx, NdfKind::Beckmann] {
        let mf = Microfacet::new(ndf, 0.3, 0.3);
        group.bench_function(format!("D/{}", ndf.name()), |b| {
            b.iter(|| dirs.iter().map(|(w, _)| mf.d(black_box(*w))).sum::<f64>())
        });
        group.bench_function(format!("lambda/{}", ndf.name()), |b| {
            b.iter(|| {
                dirs.iter()
                    .map(|(w, _)| mf.lambda(black_box(*w)))
                    .sum::<f64>()
            })
        });
        group.bench_function(format!("sample_visible/{}", ndf.name()), |b| {
            b.iter(|| {
                dirs.iter()
                    .map(|(w, m)| mf.sample_visible(black_box(*w), [m.x.abs(), m.y.abs()]).z)
                    .sum::<f64>()
            })
        });
    }
    group.bench_function("fresnel/conductor", |b| {
        b.iter(|| {
            dirs.iter()
                .map(|(w, _)| conductor(black_box(w.z), 0.2378, 3.6264))
                .sum::<f64>()
        })
    });
    group.finish();
}

fn single(c: &mut Criterion) {
    let dirs = directions(2);
    let mut group = c.benchmark_group("single_eval");
    group.throughput(Throughput::Elements(N as u64));
    for ndf in [NdfKind::Ggx, NdfKind::Beckmann] {
        let m64 = SingleBounce {
            microfacet: Microfacet::new(ndf, 0.3, 0.3),
            fresnel: copper::<f64>(),
            height: Height::Correlated,
        };
        group.bench_function(format!("f64/{}/copper", ndf.name()), |b| {
            b.iter(|| {
                dirs.iter()
                    .map(|(wi, wo)| m64.eval(black_box(*wi), black_box(*wo)).0[0])
                    .sum::<f64>()
            })
        });
        let m32 = SingleBounce {
            microfacet: Microfacet::new(ndf, 0.3f32, 0.3f32),
            fresnel: copper::<f32>(),
            height: Height::Correlated,
        };
        let dirs32: Vec<(Vec3<f32>, Vec3<f32>)> = dirs
            .iter()
            .map(|(a, b)| {
                (
                    Vec3::new(a.x as f32, a.y as f32, a.z as f32),
                    Vec3::new(b.x as f32, b.y as f32, b.z as f32),
                )
            })
            .collect();
        group.bench_function(format!("f32/{}/copper", ndf.name()), |b| {
            b.iter(|| {
                dirs32
                    .iter()
                    .map(|(wi, wo)| m32.eval(black_box(*wi), black_box(*wo)).0[0])
                    .sum::<f32>()
            })
        });
    }
    let schlick = SingleBounce {
        microfacet: Microfacet::new(NdfKind::Ggx, 0.3, 0.3),
        fresnel: Fresnel::Schlick {
            f0: Rgb([0.9, 0.6, 0.5]),
        },
        height: Height::Correlated,
    };
    group.bench_function("f64/ggx/schlick", |b| {
        b.iter(|| {
            dirs.iter()
                .map(|(wi, wo)| schlick.eval(black_box(*wi), black_box(*wo)).0[0])
                .sum::<f64>()
        })
    });
    group.finish();
}

criterion_group!(benches, kernels, single);
criterion_main!(benches);

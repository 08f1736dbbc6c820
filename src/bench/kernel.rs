//! The kernel figure of `bouncefit bench` (issue #15 item 1): time per evaluation of `single`
//! (GGX, height-correlated, copper conductor, alpha 0.3) by the scalar reference kernel and by
//! the batch kernel ([`crate::render::batch`]) on the same direction pairs, one thread, in the
//! same run; the ratio is the figure to quote.
//!
//! | field | definition |
//! | --- | --- |
//! | `pairs` | direction pairs: the estimator table's configurations ([`super::estimators::configurations`]), as many as the table has times [`PAIRS_PER_CONFIGURATION`] |
//! | `scalar_ns_per_eval` | thread CPU time per [`crate::bsdf::Brdf::eval`] of `single` |
//! | `batch_ns_per_eval` | thread CPU time per pair of [`BatchRecords::render`] (one record per pixel) with `f32` lanes, the fits' default, geometry prepared once as a fit prepares it |
//! | `batch_f64_ns_per_eval` | the same with `f64` lanes |
//! | `batch_fit_layout_ns_per_eval` | `batch_ns_per_eval` with the pairs taken [`FIT_PIXEL_SAMPLES`] to a pixel, as `fit` lays out its sub-samples by default: the kernel's cost per evaluation where a fit spends it, with a quarter of the pixel sums and outputs |
//! | `kulla_conty_ns_per_eval`, `kulla_conty_f64_ns_per_eval` | the same two for `kulla-conty` (single lobe and compensation lobe, [`Lobe::of`]) at the same material: the cost of its added lobe in the kernel |
//! | `fast_msx_ns_per_eval`, `fast_msx_f64_ns_per_eval` | the same two for `fast-msx` (single lobe and its second-bounce lobe) |
//! | `tangents_ns_per_eval`, `tangents_f64_ns_per_eval` | the same two for `single` with the derivatives by roughness, Fresnel and albedo ([`BatchRecords::render_with_tangents`]): what a gradient-based fit evaluates |
//! | `batch_prepare_ns_per_eval` | thread CPU time per pair of [`BatchRecords::new`]: the one-off cost, for comparison with kernels that take raw direction pairs |
//! | `speedup` | `scalar_ns_per_eval / batch_ns_per_eval` |

use super::cpu_time::thread_seconds;
use super::estimators::{configurations, COPPER};
use crate::bsdf::Model;
use crate::material::Material;
use crate::microfacet::{Height, NdfKind};
use crate::random::rng_stream;
use crate::render::batch::{BatchRecords, Lobe, Precision};
use crate::scalar::Vec3;
use crate::shading::ShadingRecords;
use serde::Serialize;
use std::hint::black_box;
use std::time::Instant;

/// Direction pairs per configuration of the estimator table: enough pairs that the batch
/// timing is of the arithmetic, not of one call's overhead.
pub const PAIRS_PER_CONFIGURATION: usize = 256;

/// Sub-samples per pixel of `fit`'s default (`--pixel-samples`).
pub const FIT_PIXEL_SAMPLES: usize = 4;

/// The kernel row of the bench report (see the module table).
#[derive(Clone, Debug, Serialize)]
pub struct KernelRow {
    pub pairs: usize,
    pub scalar_ns_per_eval: f64,
    pub batch_ns_per_eval: f64,
    pub batch_f64_ns_per_eval: f64,
    pub batch_fit_layout_ns_per_eval: f64,
    pub kulla_conty_ns_per_eval: f64,
    pub fast_msx_ns_per_eval: f64,
    pub fast_msx_f64_ns_per_eval: f64,
    pub kulla_conty_f64_ns_per_eval: f64,
    pub tangents_ns_per_eval: f64,
    pub tangents_f64_ns_per_eval: f64,
    pub batch_prepare_ns_per_eval: f64,
    pub speedup: f64,
}

/// The material every kernel timing evaluates.
fn material() -> Material {
    Material {
        model: Model::Single,
        ndf: NdfKind::Ggx,
        height: Height::Correlated,
        alpha: [0.3; 2],
        fresnel: COPPER,
        diffuse: [0.0; 3],
    }
}

/// One pixel per pair, one sub-sample each, unit irradiance.
fn records(pairs: usize, seed: u64) -> ShadingRecords {
    let pairs: Vec<_> = configurations(pairs, seed)
        .iter()
        .map(|c| ([c.wi.x, c.wi.y, c.wi.z], [c.wo.x, c.wo.y, c.wo.z]))
        .collect();
    ShadingRecords::of_pairs("kernel", &pairs)
}

/// `records` of [`records`] with their pairs taken [`FIT_PIXEL_SAMPLES`] to a pixel, each
/// pixel the mean of its pairs' values.
fn in_fit_layout(records: &ShadingRecords) -> ShadingRecords {
    let pixels = records.pixel_count() / FIT_PIXEL_SAMPLES;
    let mut grouped = records.clone();
    grouped.samples_per_pixel = FIT_PIXEL_SAMPLES;
    grouped.photos[0].width = pixels;
    grouped.weight.truncate(pixels);
    grouped.target.truncate(pixels);
    grouped
}

/// Thread CPU ns per pair of `work` over `pairs` pairs, repeated for at least `seconds`.
fn per_pair(pairs: usize, seconds: f64, mut work: impl FnMut()) -> f64 {
    work();
    let (wall, cpu) = (Instant::now(), thread_seconds());
    let mut passes = 0usize;
    while passes == 0 || wall.elapsed().as_secs_f64() < seconds {
        work();
        passes += 1;
    }
    (thread_seconds() - cpu) * 1e9 / (passes * pairs) as f64
}

/// Measure the kernel row on `configurations * PAIRS_PER_CONFIGURATION` pairs, each timing
/// repeated for at least `seconds`, on one thread.
pub fn measure(configurations: usize, seconds: f64, seed: u64) -> KernelRow {
    let pairs = configurations * PAIRS_PER_CONFIGURATION;
    let records = records(pairs, seed);
    let all: Vec<usize> = (0..pairs).collect();
    let material = material();
    let single = material.single::<f64>();
    let brdf = material.brdf();
    let one_thread = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("a one-thread pool");
    one_thread.install(|| {
        let mut rng = rng_stream(seed, 0);
        let scalar = per_pair(pairs, seconds, || {
            for (wi, wo) in records.wi.iter().zip(&records.wo) {
                let (wi, wo) = (
                    Vec3::from_f64(black_box(*wi)),
                    Vec3::from_f64(black_box(*wo)),
                );
                black_box(brdf.eval(wi, wo, &mut rng));
            }
        });
        let batch_ns = |model: Model, precision: Precision, tangents: bool| {
            let batch = BatchRecords::for_model(&records, &all, precision, model);
            let lobe = Lobe::of(model, &single).expect("a model the kernel serves");
            per_pair(pairs, seconds, || {
                if tangents {
                    black_box(batch.render_with_tangents(black_box(lobe), [0.0; 3]));
                } else {
                    black_box(batch.render(black_box(lobe), [0.0; 3]));
                }
            })
        };
        let [batch_ns, batch_f64_ns, kulla_conty_ns, kulla_conty_f64_ns, fast_msx_ns, fast_msx_f64_ns, tangents_ns, tangents_f64_ns] = [
            (Model::Single, Precision::F32, false),
            (Model::Single, Precision::F64, false),
            (Model::KullaConty, Precision::F32, false),
            (Model::KullaConty, Precision::F64, false),
            (Model::FastMsx, Precision::F32, false),
            (Model::FastMsx, Precision::F64, false),
            (Model::Single, Precision::F32, true),
            (Model::Single, Precision::F64, true),
        ]
        .map(|(model, precision, tangents)| batch_ns(model, precision, tangents));
        let fit_layout = {
            let records = in_fit_layout(&records);
            let pixels: Vec<usize> = (0..records.pixel_count()).collect();
            let batch = BatchRecords::for_model(&records, &pixels, Precision::F32, Model::Single);
            per_pair(pairs, seconds, || {
                black_box(batch.render(black_box(&single), [0.0; 3]));
            })
        };
        let prepare = per_pair(pairs, seconds, || {
            black_box(BatchRecords::new(black_box(&records), &all));
        });
        KernelRow {
            pairs,
            scalar_ns_per_eval: scalar,
            batch_ns_per_eval: batch_ns,
            batch_f64_ns_per_eval: batch_f64_ns,
            batch_fit_layout_ns_per_eval: fit_layout,
            kulla_conty_ns_per_eval: kulla_conty_ns,
            kulla_conty_f64_ns_per_eval: kulla_conty_f64_ns,
            fast_msx_ns_per_eval: fast_msx_ns,
            fast_msx_f64_ns_per_eval: fast_msx_f64_ns,
            tangents_ns_per_eval: tangents_ns,
            tangents_f64_ns_per_eval: tangents_f64_ns,
            batch_prepare_ns_per_eval: prepare,
            speedup: scalar / batch_ns,
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_kernel_row_times_the_same_values_both_ways() {
        let records = records(512, 1);
        let all: Vec<usize> = (0..512).collect();
        let material = material();
        let scalar = crate::render::render_pixels(&material, &records, &all, 0);
        // The bounds of `render::batch`'s tests: f64 lanes reorder operations, f32 lanes
        // round about 30 times.
        for (precision, tolerance) in [(Precision::F64, 1e-12), (Precision::F32, 2e-6)] {
            let batch = BatchRecords::with_precision(&records, &all, precision)
                .render(&material.single(), [0.0; 3]);
            assert_eq!(batch.len(), scalar.len());
            for (b, s) in batch.iter().zip(&scalar) {
                for c in 0..3 {
                    assert!((b[c] - s[c]).abs() <= tolerance * s[c].abs().max(1e-300));
                }
            }
        }
        // The fit's layout: each pixel is the mean of its four pairs' values.
        let grouped = in_fit_layout(&records);
        let pixels: Vec<usize> = (0..grouped.pixel_count()).collect();
        let means = BatchRecords::with_precision(&grouped, &pixels, Precision::F64)
            .render(&material.single(), [0.0; 3]);
        for (p, mean) in means.iter().enumerate() {
            let pairs = &scalar[p * FIT_PIXEL_SAMPLES..(p + 1) * FIT_PIXEL_SAMPLES];
            for c in 0..3 {
                let expected = pairs.iter().map(|v| v[c]).sum::<f64>() / FIT_PIXEL_SAMPLES as f64;
                assert!((mean[c] - expected).abs() <= 1e-12 * expected.abs().max(1e-300));
            }
        }
        let row = measure(2, 0.0, 1);
        assert_eq!(row.pairs, 2 * PAIRS_PER_CONFIGURATION);
        assert!(row.batch_ns_per_eval > 0.0 && row.scalar_ns_per_eval > 0.0);
        assert!(row.batch_fit_layout_ns_per_eval > 0.0);
    }
}

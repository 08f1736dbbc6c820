//! Evaluate a material over shading records: the predicted linear radiance of each pixel.
//!
//! A pixel's value is the mean over its stratified sub-pixel samples of
//! `(f_model(wi, wo) + diffuse / pi) * irradiance` (PHYSICS.md "Radiance of a pixel"), i.e. the
//! pixel-footprint average that cameras and renderers such as Mitsuba 3 produce. Pixels are
//! processed in parallel with rayon; a stochastic model draws from the random stream of its
//! pixel index, so the result does not depend on the thread count. One pixel loop serves every
//! scalar type: `f64` for the cost, dual numbers for exact gradients (`fit::objective`).

use crate::albedo::rng_stream;
use crate::bsdf::ScalarBrdf;
use crate::material::Material;
use crate::scalar::{Real, Vec3};
use crate::shading::ShadingRecords;
use rayon::prelude::*;
use std::f64::consts::FRAC_1_PI;

/// Pixels per rayon task: large enough to amortise scheduling, small enough to balance 2 cores.
const PIXELS_PER_TASK: usize = 1024;

/// Predicted radiance of the pixels listed in `pixels` (indices into the per-pixel arrays).
pub fn render_pixels(
    material: &Material,
    records: &ShadingRecords,
    pixels: &[usize],
    seed: u64,
) -> Vec<[f64; 3]> {
    let brdf = material.brdf();
    render_model(brdf.as_ref(), material.diffuse, records, pixels, seed)
}

/// Predicted radiance of `pixels` for the specular model `brdf` plus a Lambertian layer of
/// albedo `diffuse`, at any scalar type: `f64`, or dual numbers whose derivative parts are the
/// derivatives of the prediction (pathwise, at the same random numbers, for stochastic models).
pub fn render_model<T: Real, B: ScalarBrdf<T> + ?Sized>(
    brdf: &B,
    diffuse: [T; 3],
    records: &ShadingRecords,
    pixels: &[usize],
    seed: u64,
) -> Vec<[T; 3]> {
    let diffuse = diffuse.map(|d| d * T::c(FRAC_1_PI));
    let spp = records.samples_per_pixel;
    let mut out = vec![[T::zero(); 3]; pixels.len()];
    out.par_chunks_mut(PIXELS_PER_TASK)
        .zip(pixels.par_chunks(PIXELS_PER_TASK))
        .for_each(|(out, pixels)| {
            for (value, &p) in out.iter_mut().zip(pixels) {
                let mut rng = rng_stream(seed, p as u64);
                let mut sum = [T::zero(); 3];
                for s in p * spp..(p + 1) * spp {
                    let e = records.irradiance[s];
                    if e == [0.0; 3] {
                        continue;
                    }
                    let f = brdf.eval_total(
                        Vec3::from_f64(records.wi[s]),
                        Vec3::from_f64(records.wo[s]),
                        &mut rng,
                    );
                    for c in 0..3 {
                        sum[c] += (f.0[c] + diffuse[c]) * T::c(e[c]);
                    }
                }
                *value = sum.map(|v| v / T::c(spp as f64));
            }
        });
    out
}

/// Radiance of the pixels listed in `pixels` for a white Lambertian surface (albedo 1, `f = 1/pi`):
/// the basis of the diffuse term, which is linear in the albedo.
pub fn lambertian_pixels(records: &ShadingRecords, pixels: &[usize]) -> Vec<[f64; 3]> {
    let spp = records.samples_per_pixel;
    pixels
        .iter()
        .map(|&p| {
            let mut sum = [0.0; 3];
            for e in &records.irradiance[p * spp..(p + 1) * spp] {
                for c in 0..3 {
                    sum[c] += e[c] * FRAC_1_PI;
                }
            }
            sum.map(|v| v / spp as f64)
        })
        .collect()
}

/// Predicted radiance of every pixel of every photo.
pub fn render_all(material: &Material, records: &ShadingRecords, seed: u64) -> Vec<[f64; 3]> {
    let all: Vec<usize> = (0..records.pixel_count()).collect();
    render_pixels(material, records, &all, seed)
}

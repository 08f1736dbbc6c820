//! Evaluate a material over shading records: the predicted linear radiance of each pixel.
//!
//! A pixel's value is the mean over its stratified sub-pixel samples of
//! `(f_model(wi, wo) + diffuse / pi) * irradiance` (PHYSICS.md "Radiance of a pixel"), i.e. the
//! pixel-footprint average that cameras and renderers such as Mitsuba 3 produce. Pixels are
//! processed in parallel with rayon; a stochastic model draws from the random stream of its
//! pixel index, so the result does not depend on the thread count. One pixel loop serves every
//! scalar type: `f64` for the cost, dual numbers for exact gradients (`fit::point::objective`).
//!
//! [`render_planned`] renders through a [`plan::RenderPlan`], which skips the work a scene does
//! not need (issue #5): fits render the same pixels hundreds of times, so the plan is built
//! once per objective. [`render_planned_streams`] renders several random streams at once (the
//! pair loss of the stochastic models) and [`render_planned_split`] returns the part no stream
//! changes separately (variable projection interpolates it across F0 nodes).

pub mod anchors;
pub mod batch;
pub mod plan;
pub mod repeated;

use crate::bsdf::single::SingleBounce;
use crate::bsdf::ScalarBrdf;
use crate::material::Material;
use crate::random::rng_stream;
use crate::scalar::{Real, Rgb, Vec3};
use crate::shading::ShadingRecords;
use plan::{MultiTerm, RenderPlan};
use rayon::prelude::*;
use std::f64::consts::FRAC_1_PI;

/// Pixels per rayon task: large enough to amortise scheduling, small enough to balance 2 cores.
pub const TASK_PIXELS: usize = 1024;

/// Mixed into the stream of an anchor's pixel, so the anchor's estimate is independent of the
/// pixel's own sub-samples.
const ANCHOR_STREAMS: u64 = 0x6A09_E667_F3BC_C909;

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
    accumulate(records, pixels, diffuse, seed, |_, s, rng| {
        brdf.eval_total(
            Vec3::from_f64(records.wi[s]),
            Vec3::from_f64(records.wo[s]),
            rng,
        )
    })
}

/// [`render_model`] through `plan`: `single` is the single-bounce part of `brdf` (the part
/// that stays exact at every sub-sample when the multiple-bounce term is interpolated or
/// skipped). With [`RenderPlan::exact`] the result is [`render_model`]'s, bit for bit.
#[allow(clippy::too_many_arguments)]
pub fn render_planned<T: Real, B: ScalarBrdf<T> + ?Sized>(
    brdf: &B,
    single: &SingleBounce<T>,
    diffuse: [T; 3],
    records: &ShadingRecords,
    pixels: &[usize],
    plan: &RenderPlan,
    seed: u64,
) -> Vec<[T; 3]> {
    let at = |s: usize| (Vec3::from_f64(records.wi[s]), Vec3::from_f64(records.wo[s]));
    let spp = records.samples_per_pixel;
    match (plan.multi_term(single), &plan.repeated) {
        (MultiTerm::Exact, None) => render_model(brdf, diffuse, records, pixels, seed),
        (MultiTerm::Skipped, _) => render_model(single, diffuse, records, pixels, seed),
        (MultiTerm::Exact, Some(repeated)) => {
            let values = shared_values(repeated, seed, |s, rng| {
                let (wi, wo) = at(s);
                brdf.eval_total(wi, wo, rng)
            });
            accumulate(records, pixels, diffuse, seed, |k, s, _| {
                values[repeated.pair_of[k * spp + s % spp] as usize]
            })
        }
        (MultiTerm::Sparse(anchors), _) => {
            let multi = anchor_values(brdf, anchors, plan.stochastic, spp, seed);
            accumulate(records, pixels, diffuse, seed, |k, s, rng| {
                let (wi, wo) = at(s);
                match &anchors.corners[k] {
                    Some(corners) => {
                        single.eval(wi, wo) + anchors::Anchors::interpolate(corners, &multi)
                    }
                    None => brdf.eval_total(wi, wo, rng),
                }
            })
        }
    }
}

/// [`render_planned`] once per seed of `seeds`, computing what does not depend on the seed once:
/// where the multiple-bounce term is interpolated from anchors, the exact single-bounce term
/// and the diffuse term are summed in one pass ([`render_planned_split`]) and each seed adds
/// only its interpolated estimate; where the term is skipped, one render serves every seed. The
/// pair loss of the stochastic models compares two renders (`fit::point::objective`), so this halves
/// their per-pixel work. Equal to the renders of [`render_planned`] up to the rounding of one
/// addition per pixel.
#[allow(clippy::too_many_arguments)]
pub fn render_planned_streams<T: Real, B: ScalarBrdf<T> + ?Sized>(
    brdf: &B,
    single: &SingleBounce<T>,
    diffuse: [T; 3],
    records: &ShadingRecords,
    pixels: &[usize],
    plan: &RenderPlan,
    seeds: &[u64],
) -> Vec<Vec<[T; 3]>> {
    let separately = || {
        seeds
            .iter()
            .map(|&seed| render_planned(brdf, single, diffuse, records, pixels, plan, seed))
            .collect()
    };
    match (plan.multi_term(single), seeds) {
        (_, [] | [_]) | (MultiTerm::Exact, _) => separately(),
        (MultiTerm::Skipped, [first, ..]) => {
            vec![render_model(single, diffuse, records, pixels, *first); seeds.len()]
        }
        (MultiTerm::Sparse(_), _) => {
            let split = render_planned_split(brdf, single, diffuse, records, pixels, plan, seeds);
            let Some(SplitRender {
                shared: Some(shared),
                own,
            }) = split
            else {
                return separately();
            };
            own.into_iter()
                .map(|mut own| {
                    add_to(&mut own, &shared);
                    own
                })
                .collect()
        }
    }
}

/// `target += addend`, pixel by pixel.
pub fn add_to<T: Real>(target: &mut [[T; 3]], addend: &[[T; 3]]) {
    for (t, a) in target.iter_mut().zip(addend) {
        for c in 0..3 {
            t[c] += a[c];
        }
    }
}

/// A render through a plan whose multiple-bounce term is interpolated from anchors (at the
/// roughness of `single`), split into the part no seed changes, the exact single-bounce and
/// diffuse terms at the pixels with anchors (`None` when `diffuse` is `None`: not wanted), and
/// per seed of `seeds` the rest: the interpolated estimate, and the whole value of the pixels
/// without anchors. The parts sum to the render. `None` when the plan does not interpolate at
/// this roughness. Variable projection (`fit::point::projection`) uses the split because the shared
/// part is affine in a Schlick F0 and needs no render at its inner nodes.
#[allow(clippy::too_many_arguments)]
pub fn render_planned_split<T: Real, B: ScalarBrdf<T> + ?Sized>(
    brdf: &B,
    single: &SingleBounce<T>,
    diffuse: impl Into<Option<[T; 3]>>,
    records: &ShadingRecords,
    pixels: &[usize],
    plan: &RenderPlan,
    seeds: &[u64],
) -> Option<SplitRender<T>> {
    let MultiTerm::Sparse(anchors) = plan.multi_term(single) else {
        return None;
    };
    let at = |s: usize| (Vec3::from_f64(records.wi[s]), Vec3::from_f64(records.wo[s]));
    let spp = records.samples_per_pixel;
    let zero = Rgb::splat(T::zero());
    let shared = diffuse.into().map(|diffuse| {
        let seed = seeds.first().copied().unwrap_or(0);
        accumulate(records, pixels, diffuse, seed, |k, s, _| {
            match anchors.corners[k] {
                Some(_) => {
                    let (wi, wo) = at(s);
                    single.eval(wi, wo)
                }
                None => zero,
            }
        })
    });
    let own = seeds
        .iter()
        .map(|&seed| {
            let multi = anchor_values(brdf, anchors, plan.stochastic, spp, seed);
            accumulate(
                records,
                pixels,
                [T::zero(); 3],
                seed,
                |k, s, rng| match &anchors.corners[k] {
                    Some(corners) => anchors::Anchors::interpolate(corners, &multi),
                    None => {
                        let (wi, wo) = at(s);
                        brdf.eval_total(wi, wo, rng)
                    }
                },
            )
        })
        .collect();
    Some(SplitRender { shared, own })
}

/// The parts of [`render_planned_split`]: their sum, pixel by pixel, is the render of each seed.
pub struct SplitRender<T> {
    /// The exact single-bounce and diffuse terms at the pixels with anchors (when asked for).
    pub shared: Option<Vec<[T; 3]>>,
    /// Per seed: the interpolated multiple-bounce estimate, and the pixels without anchors.
    pub own: Vec<Vec<[T; 3]>>,
}

/// The multiple-bounce estimate at every anchor of `anchors`, each from a stream of its own
/// (the mean of `spp` draws for a stochastic model, one evaluation otherwise).
pub fn anchor_values<T: Real, B: ScalarBrdf<T> + ?Sized>(
    brdf: &B,
    anchors: &anchors::Anchors,
    stochastic: bool,
    spp: usize,
    seed: u64,
) -> Vec<Rgb<T>> {
    let draws = if stochastic { spp } else { 1 };
    anchors
        .points
        .par_iter()
        .map(|a| {
            let mut rng = rng_stream(seed ^ ANCHOR_STREAMS, a.pixel as u64);
            let (wi, wo) = (Vec3::from_f64(a.wi), Vec3::from_f64(a.wo));
            let mut sum = Rgb::splat(T::zero());
            for _ in 0..draws {
                sum = sum + brdf.eval_multi(wi, wo, &mut rng);
            }
            sum.scale(T::c(1.0 / draws as f64))
        })
        .collect()
}

/// [`render_pixels`] through `plan`.
pub fn render_material(
    material: &Material,
    records: &ShadingRecords,
    pixels: &[usize],
    plan: &RenderPlan,
    seed: u64,
) -> Vec<[f64; 3]> {
    let mut renders = render_material_streams(material, records, pixels, plan, &[seed]);
    renders.pop().expect("one render per seed")
}

/// [`render_material`] once per seed of `seeds`, sharing what does not depend on the seed
/// ([`render_planned_streams`]).
pub fn render_material_streams(
    material: &Material,
    records: &ShadingRecords,
    pixels: &[usize],
    plan: &RenderPlan,
    seeds: &[u64],
) -> Vec<Vec<[f64; 3]>> {
    let single = material.single::<f64>();
    let brdf = material.capped_brdf(plan.bounce_cap(&single));
    let diffuse = material.diffuse;
    render_planned_streams(
        brdf.as_ref(),
        &single,
        diffuse,
        records,
        pixels,
        plan,
        seeds,
    )
}

/// The multiple-bounce term alone of `material`, exact at every sub-sample (no plan), once per
/// seed of `seeds`: what two models with the same single-bounce lobe differ by, without that
/// lobe's rounding (the defect of `fit::point::corrected`), and without evaluating it
/// ([`crate::bsdf::Brdf::eval_multi`]). Each seed's render draws the same paths as
/// [`render_material_streams`] under [`RenderPlan::exact`].
pub fn render_multi_streams(
    material: &Material,
    records: &ShadingRecords,
    pixels: &[usize],
    seeds: &[u64],
) -> Vec<Vec<[f64; 3]>> {
    let brdf = material.capped_brdf(crate::bsdf::BounceCap::NONE);
    let at = |s: usize| (Vec3::from_f64(records.wi[s]), Vec3::from_f64(records.wo[s]));
    seeds
        .iter()
        .map(|&seed| {
            accumulate(records, pixels, [0.0; 3], seed, |_, s, rng| {
                let (wi, wo) = at(s);
                Rgb(brdf.eval_multi(wi, wo, rng))
            })
        })
        .collect()
}

/// `f` at each distinct direction pair of `repeated`, from a stream of its own.
fn shared_values<T: Real>(
    repeated: &repeated::Repeated,
    seed: u64,
    f: impl Fn(usize, &mut crate::random::Rng) -> Rgb<T> + Sync,
) -> Vec<Rgb<T>> {
    repeated
        .firsts
        .par_iter()
        .with_min_len(TASK_PIXELS)
        .map(|&s| f(s, &mut rng_stream(seed, repeated::STREAM_FLAG | s as u64)))
        .collect()
}

/// The pixel loop every render shares: pixel `k` of `pixels` is the mean over its sub-samples
/// `s` (global indices) of `(f(k, s, rng) + diffuse / pi) * irradiance[s]`, where `rng` is the
/// pixel's own stream; sub-samples without irradiance are not evaluated.
pub(crate) fn accumulate<T: Real>(
    records: &ShadingRecords,
    pixels: &[usize],
    diffuse: [T; 3],
    seed: u64,
    f: impl Fn(usize, usize, &mut crate::random::Rng) -> Rgb<T> + Sync,
) -> Vec<[T; 3]> {
    let diffuse = diffuse.map(|d| d * T::c(FRAC_1_PI));
    let spp = records.samples_per_pixel;
    let mut out = vec![[T::zero(); 3]; pixels.len()];
    out.par_chunks_mut(TASK_PIXELS)
        .zip(pixels.par_chunks(TASK_PIXELS))
        .enumerate()
        .for_each(|(task, (out, pixels))| {
            for (i, (value, &p)) in out.iter_mut().zip(pixels).enumerate() {
                let k = task * TASK_PIXELS + i;
                let mut rng = rng_stream(seed, p as u64);
                let mut sum = [T::zero(); 3];
                for s in p * spp..(p + 1) * spp {
                    let e = records.irradiance[s];
                    if e == [0.0; 3] {
                        continue;
                    }
                    let f = f(k, s, &mut rng);
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

#[cfg(test)]
mod tests;

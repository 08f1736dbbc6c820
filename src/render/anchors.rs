//! Sparse evaluation of the multiple-bounce term: it is evaluated at anchor pixels on a
//! regular grid of every photo and interpolated bilinearly in between, while the single-bounce
//! term stays exact at every sub-sample (issue #5, "smooth terms evaluated sparsely").
//!
//! Why it is accurate: the multiple-bounce lobe is a low-frequency function of `(wi, wo)`
//! (Heitz et al. 2016, Fig. 9; Kulla & Conty 2017, the compensation lobe depends on the two
//! elevations only), and `(wi, wo)` moves smoothly across a photo of a flat sample. The
//! interpolation therefore adds an error of order `stride^2` times the lobe's second derivative
//! along the image, far below the single-bounce peak's own scale.
//!
//! | quantity | value |
//! | --- | --- |
//! | anchors of a `W`-pixel row | columns `0, s, 2s, ...` and `W - 1` (so every pixel lies between two) |
//! | an anchor's geometry | its sub-sample nearest the pixel centre among those that see the sample; for a node off the sample (past its edge), that of the nearest pixel within one stride that sees it |
//! | a pixel's multiple-bounce value | bilinear in its 4 surrounding anchors; exact (no interpolation) only when a node has no pixel seeing the sample within one stride |
//! | stride `s` | the largest of [`CANDIDATE_STRIDES`] whose interpolation error, measured on these records with two proxy lobes over [`PROXY_ALPHAS`], stays below the tolerance (RMS over the loss pixels, relative to the RMS radiance) |
//!
//! The proxies are the analytic multiple-bounce lobes of Kulla & Conty 2017 (smooth in the
//! elevations) and Rosales et al. 2023 (Fast-MSX, a second-bounce lobe with azimuthal
//! structure), evaluated with white Fresnel; the stride is fixed for the whole fit, so the
//! objective stays a smooth function of the parameters.

use super::TASK_PIXELS;
use crate::bsdf::fast_msx::{self, FastMsx};
use crate::bsdf::registry::differentiable;
use crate::bsdf::single::SingleBounce;
use crate::bsdf::{BounceCap, Model};
use crate::microfacet::{Fresnel, Height, Microfacet, NdfKind};
use crate::scalar::{Rgb, Vec3};
use crate::shading::ShadingRecords;
use rayon::prelude::*;

/// Strides tried, largest last.
pub const CANDIDATE_STRIDES: [usize; 7] = [2, 3, 4, 6, 8, 12, 16];

/// Roughness values at which the interpolation error is measured (the multiple-bounce lobe is
/// negligible below 0.05 and the widest, so the easiest to interpolate, at the top).
pub const PROXY_ALPHAS: [f64; 7] = [0.05, 0.1, 0.2, 0.35, 0.6, 1.0, 1.5];

/// The two proxy lobes of the module table: their multiple-bounce terms at every roughness of
/// [`PROXY_ALPHAS`] stand for every model's.
const PROXY_MODELS: [Model; 2] = [Model::KullaConty, Model::FastMsx];

/// One anchor: the pixel whose random stream it uses and the geometry it is evaluated at.
#[derive(Clone, Copy, Debug)]
pub struct Anchor {
    pub pixel: usize,
    pub wi: [f64; 3],
    pub wo: [f64; 3],
}

/// Bilinear weights of a pixel on its 4 anchors (indices into [`Anchors::points`]).
pub type Corners = [(u32, f64); 4];

/// The anchor grid of a pixel list at one stride.
#[derive(Clone, Debug)]
pub struct Anchors {
    pub stride: usize,
    pub points: Vec<Anchor>,
    /// Per pixel of the list: its anchors and weights, or `None` when some surrounding anchor
    /// has no geometry: neither it nor any pixel within one stride of it sees the sample (the
    /// pixel is then evaluated exactly).
    pub corners: Vec<Option<Corners>>,
}

/// The columns (or rows) of the anchors of an axis of `n` pixels at `stride`.
fn axis_nodes(n: usize, stride: usize) -> Vec<usize> {
    let mut nodes: Vec<usize> = (0..n).step_by(stride).collect();
    if nodes.last() != Some(&(n - 1)) {
        nodes.push(n - 1);
    }
    nodes
}

/// The two nodes around `x` and the weight of the second.
fn bracket(nodes: &[usize], stride: usize, x: usize) -> (usize, usize, f64) {
    let i = (x / stride).min(nodes.len().saturating_sub(2));
    let (lo, hi) = (nodes[i], nodes[(i + 1).min(nodes.len() - 1)]);
    let t = if hi > lo {
        (x - lo) as f64 / (hi - lo) as f64
    } else {
        0.0
    };
    (i, (i + 1).min(nodes.len() - 1), t)
}

impl Anchors {
    /// The anchors that the pixels `pixels` of `records` need at `stride`.
    pub fn new(records: &ShadingRecords, pixels: &[usize], stride: usize) -> Anchors {
        let mut points = Vec::new();
        // Per photo: anchor index of each grid node, assigned on first use (u32::MAX: not yet,
        // u32::MAX - 1: neither the node nor a pixel within one stride sees the sample).
        const UNSET: u32 = u32::MAX;
        const BLIND: u32 = u32::MAX - 1;
        let grids: Vec<(Vec<usize>, Vec<usize>)> = records
            .photos
            .iter()
            .map(|span| {
                (
                    axis_nodes(span.width, stride),
                    axis_nodes(span.height, stride),
                )
            })
            .collect();
        let mut slots: Vec<Vec<u32>> = grids
            .iter()
            .map(|(xs, ys)| vec![UNSET; xs.len() * ys.len()])
            .collect();
        let mut photo = 0;
        let corners = pixels
            .iter()
            .map(|&p| {
                while p >= records.photos[photo].pixels().end {
                    photo += 1;
                }
                let span = &records.photos[photo];
                let (xs, ys) = &grids[photo];
                let local = p - span.first_pixel;
                let (c, r) = (local % span.width, local / span.width);
                let (x0, x1, tx) = bracket(xs, stride, c);
                let (y0, y1, ty) = bracket(ys, stride, r);
                let mut corner = |ix: usize, iy: usize| {
                    let slot = &mut slots[photo][iy * xs.len() + ix];
                    if *slot == UNSET {
                        let (x, y) = (xs[ix], ys[iy]);
                        let pixel = span.first_pixel + y * span.width + x;
                        let geometry = reference_geometry(records, pixel)
                            .or_else(|| nearest_geometry(records, span, (x, y), stride));
                        *slot = match geometry {
                            Some((wi, wo)) => {
                                points.push(Anchor { pixel, wi, wo });
                                (points.len() - 1) as u32
                            }
                            None => BLIND,
                        };
                    }
                    *slot
                };
                let nodes = [
                    (corner(x0, y0), (1.0 - tx) * (1.0 - ty)),
                    (corner(x1, y0), tx * (1.0 - ty)),
                    (corner(x0, y1), (1.0 - tx) * ty),
                    (corner(x1, y1), tx * ty),
                ];
                nodes
                    .iter()
                    .all(|&(slot, _)| slot != BLIND)
                    .then_some(nodes)
            })
            .collect();
        Anchors {
            stride,
            points,
            corners,
        }
    }

    /// Pixels of the list evaluated exactly because an anchor around them has no geometry
    /// (no pixel within one stride of it sees the sample).
    pub fn exact_pixels(&self) -> usize {
        self.corners.iter().filter(|c| c.is_none()).count()
    }

    /// The bilinear interpolation of per-anchor `values` at pixel `k` of the list.
    #[inline]
    pub fn interpolate<T: crate::scalar::Real>(corners: &Corners, values: &[Rgb<T>]) -> Rgb<T> {
        let mut sum = Rgb::splat(T::zero());
        for &(anchor, weight) in corners {
            if weight != 0.0 {
                sum = sum + values[anchor as usize].scale(T::c(weight));
            }
        }
        sum
    }

    /// The stride for `pixels` of `records` (see the module table), or `None` when no
    /// candidate stride meets `tolerance`. The strides are tried largest first and the first
    /// within the tolerance is taken, so the smaller grids are never built on a set where a
    /// coarse one serves. The choice is remembered by content ([`remembered_stride`]).
    pub fn choose(
        records: &ShadingRecords,
        pixels: &[usize],
        ndf: NdfKind,
        height: Height,
        tolerance: f64,
    ) -> Option<Anchors> {
        let key = fingerprint(records, pixels, ndf, height, tolerance);
        let stride = remembered_stride(key, || {
            let proxies = ProxyLobes::new(records, pixels, ndf, height);
            CANDIDATE_STRIDES
                .iter()
                .rev()
                .find(|&&stride| proxies.error(&Anchors::new(records, pixels, stride)) <= tolerance)
                .copied()
        });
        stride.map(|stride| Anchors::new(records, pixels, stride))
    }
}

/// For a grid node at `(x, y)` of photo `span` that sees no sample: the reference geometry of
/// the nearest pixel within `stride` in x and y that does (ties: the first in row order), or
/// `None`. The sample plane continues past the sample's edge and the multiple-bounce term is
/// smooth in `(wi, wo)`, so the node stands in for the edge; the stride is chosen with these
/// substitutes in place, so their error is inside the measured tolerance.
fn nearest_geometry(
    records: &ShadingRecords,
    span: &crate::shading::PhotoSpan,
    (x, y): (usize, usize),
    stride: usize,
) -> Option<([f64; 3], [f64; 3])> {
    let rows = y.saturating_sub(stride)..(y + stride + 1).min(span.height);
    let columns = x.saturating_sub(stride)..(x + stride + 1).min(span.width);
    rows.flat_map(|r| columns.clone().map(move |c| (c, r)))
        .filter_map(|(c, r)| {
            let distance = c.abs_diff(x).pow(2) + r.abs_diff(y).pow(2);
            reference_geometry(records, span.first_pixel + r * span.width + c)
                .map(|geometry| (distance, geometry))
        })
        .min_by_key(|&(distance, _)| distance)
        .map(|(_, geometry)| geometry)
}

/// The geometry a pixel's multiple-bounce term is evaluated at: its sub-sample nearest the
/// pixel centre among those that see the sample (nonzero irradiance), `None` if none does.
pub fn reference_geometry(records: &ShadingRecords, pixel: usize) -> Option<([f64; 3], [f64; 3])> {
    let spp = records.samples_per_pixel;
    let k = (spp as f64).sqrt().round() as usize;
    let centre = (k as f64 - 1.0) / 2.0;
    (0..spp)
        .map(|j| pixel * spp + j)
        .filter(|&s| records.irradiance[s] != [0.0; 3])
        .min_by(|&a, &b| {
            let distance = |s: usize| {
                let j = s % spp;
                ((j % k) as f64 - centre).powi(2) + ((j / k) as f64 - centre).powi(2)
            };
            distance(a).total_cmp(&distance(b))
        })
        .map(|s| (records.wi[s], records.wo[s]))
}

/// Strides chosen so far, by [`fingerprint`] of what the choice reads: the objectives of one
/// command often share their records (the rounds of a corrected fit, the models of `compare`,
/// the sampler after the point fit), and each choice evaluates 14 proxy lobes at every loss
/// pixel: 0.5 s of a `heitz` fit of copper-flash, four times over, before this memo. A few
/// entries suffice; the oldest is dropped first.
static CHOSEN_STRIDES: std::sync::Mutex<Vec<(u64, Option<usize>)>> =
    std::sync::Mutex::new(Vec::new());
const REMEMBERED_STRIDES: usize = 16;

/// The stride remembered under `key`, or `choose()`'s, then remembered.
fn remembered_stride(key: u64, choose: impl FnOnce() -> Option<usize>) -> Option<usize> {
    let lookup = || {
        let chosen = CHOSEN_STRIDES.lock().expect("no panic holds the lock");
        chosen
            .iter()
            .find(|(k, _)| *k == key)
            .map(|&(_, stride)| stride)
    };
    if let Some(stride) = lookup() {
        return stride;
    }
    let stride = choose();
    let mut chosen = CHOSEN_STRIDES.lock().expect("no panic holds the lock");
    if chosen.len() == REMEMBERED_STRIDES {
        chosen.remove(0);
    }
    chosen.push((key, stride));
    stride
}

/// A hash of everything [`Anchors::choose`] reads: the photos' layout, the loss pixels and
/// their weights, every sub-sample's directions and irradiance, the NDF, the height model and
/// the tolerance. Hashed in parallel chunks combined in order, so it does not depend on the
/// thread count.
pub(super) fn fingerprint(
    records: &ShadingRecords,
    pixels: &[usize],
    ndf: NdfKind,
    height: Height,
    tolerance: f64,
) -> u64 {
    use std::hash::{Hash, Hasher};
    let chunk_hash = |range: std::ops::Range<usize>| {
        let mut h = std::collections::hash_map::DefaultHasher::new();
        for s in range {
            for v in records.wi[s]
                .iter()
                .chain(&records.wo[s])
                .chain(&records.irradiance[s])
            {
                v.to_bits().hash(&mut h);
            }
        }
        h.finish()
    };
    let samples = records.wi.len();
    let chunk = TASK_PIXELS * records.samples_per_pixel.max(1);
    let chunks: Vec<u64> = (0..samples.div_ceil(chunk))
        .into_par_iter()
        .map(|i| chunk_hash(i * chunk..((i + 1) * chunk).min(samples)))
        .collect();
    let mut h = std::collections::hash_map::DefaultHasher::new();
    chunks.hash(&mut h);
    pixels.hash(&mut h);
    for &p in pixels {
        records.weight[p].to_bits().hash(&mut h);
    }
    for span in &records.photos {
        (span.first_pixel, span.width, span.height).hash(&mut h);
    }
    (records.samples_per_pixel, ndf, height, tolerance.to_bits()).hash(&mut h);
    h.finish()
}

/// The proxy lobes of the module table at every roughness of [`PROXY_ALPHAS`], evaluated once
/// at each loss pixel's reference geometry, against which any anchor grid's interpolation
/// error is measured.
pub struct ProxyLobes {
    lobes: Vec<Box<dyn crate::bsdf::ScalarBrdf<f64>>>,
    /// Per lobe: the multiple-bounce value at each loss pixel (0 where no sub-sample sees the
    /// sample), and the weighted sum of squared radiance (single plus lobe) it is relative to.
    multi: Vec<(Vec<f64>, f64)>,
    /// Per loss pixel: weight times squared mean irradiance (0 where no sub-sample sees the
    /// sample), turning a squared BRDF difference into a squared radiance error.
    scale: Vec<f64>,
}

impl ProxyLobes {
    pub fn new(records: &ShadingRecords, pixels: &[usize], ndf: NdfKind, height: Height) -> Self {
        let spp = records.samples_per_pixel;
        let geometry: Vec<Option<([f64; 3], [f64; 3])>> = pixels
            .par_iter()
            .with_min_len(TASK_PIXELS)
            .map(|&p| reference_geometry(records, p))
            .collect();
        let scale: Vec<f64> = pixels
            .iter()
            .zip(&geometry)
            .map(|(&p, g)| {
                let e = records.irradiance[p * spp..(p + 1) * spp]
                    .iter()
                    .map(|e| e[0])
                    .sum::<f64>()
                    / spp as f64;
                if g.is_some() {
                    records.weight[p] * e * e
                } else {
                    0.0
                }
            })
            .collect();
        let singles = PROXY_ALPHAS.map(|alpha| SingleBounce {
            microfacet: Microfacet::new(ndf, alpha, alpha),
            fresnel: Fresnel::White,
            height,
        });
        // The two proxies at one roughness share their single lobe: evaluated once.
        let single_values: Vec<Vec<f64>> = singles
            .iter()
            .map(|single| {
                geometry
                    .par_iter()
                    .with_min_len(TASK_PIXELS)
                    .map(|g| {
                        g.map_or(0.0, |(wi, wo)| {
                            single.eval(Vec3::from_f64(wi), Vec3::from_f64(wo)).0[0]
                        })
                    })
                    .collect()
            })
            .collect();
        let lobes: Vec<Box<dyn crate::bsdf::ScalarBrdf<f64>>> = PROXY_MODELS
            .into_iter()
            .flat_map(|proxy| {
                singles.map(|single| {
                    differentiable::<f64>(proxy, single, BounceCap::NONE)
                        .expect("the proxies are analytic models")
                })
            })
            .collect();
        // Fast-MSX's direction-only part and `wi.h` do not depend on the roughness: prepared
        // once per pixel, not once per roughness (they were a third of the choice's samples).
        let indirect: Vec<Option<(([f64; 3], f64), f64)>> = geometry
            .par_iter()
            .with_min_len(TASK_PIXELS)
            .map(|g| {
                let (wi, wo) = (*g)?;
                if wi[2] <= 0.0 || wo[2] <= 0.0 {
                    return None;
                }
                let (l, v) = (Vec3::from_f64(wi), Vec3::from_f64(wo));
                let geometry = fast_msx::indirect_geometry(l, v)?;
                Some((geometry, l.dot((l + v).normalize())))
            })
            .collect();
        let multi = lobes
            .iter()
            .enumerate()
            // `lobes` runs over the roughness values once per proxy, as `single_values` does.
            .zip(single_values.iter().cycle())
            .map(|((k, lobe), single)| {
                let values: Vec<f64> = match PROXY_MODELS[k / singles.len()] {
                    Model::FastMsx => {
                        let lobe = FastMsx {
                            single: singles[k % singles.len()],
                        };
                        indirect
                            .par_iter()
                            .with_min_len(TASK_PIXELS)
                            .map(|g| g.map_or(0.0, |(m, cos_d)| lobe.indirect_from(m, cos_d).0[0]))
                            .collect()
                    }
                    _ => geometry
                        .par_iter()
                        .with_min_len(TASK_PIXELS)
                        .map(|g| g.map_or(0.0, |(wi, wo)| multiple(lobe.as_ref(), wi, wo)))
                        .collect(),
                };
                let norm = single
                    .iter()
                    .zip(&values)
                    .zip(&scale)
                    .map(|((s, m), w)| w * (s + m).powi(2))
                    .sum::<f64>();
                (values, norm)
            })
            .collect();
        ProxyLobes {
            lobes,
            multi,
            scale,
        }
    }

    /// The largest, over the lobes, RMS error of interpolating the lobe's radiance from
    /// `anchors` over the loss pixels, relative to the RMS radiance of single plus lobe (loss
    /// weights; channel 0, white Fresnel). Pixels evaluated exactly add no error.
    pub fn error(&self, anchors: &Anchors) -> f64 {
        let mut worst = 0.0f64;
        for (lobe, (multi, norm)) in self.lobes.iter().zip(&self.multi) {
            if *norm <= 0.0 {
                continue;
            }
            let values: Vec<Rgb<f64>> = anchors
                .points
                .par_iter()
                .map(|a| Rgb::splat(multiple(lobe.as_ref(), a.wi, a.wo)))
                .collect();
            // Fixed chunks summed in order: the same sum, so the same stride, on any number
            // of threads.
            let chunk_sums: Vec<f64> = anchors
                .corners
                .par_chunks(TASK_PIXELS)
                .zip(multi.par_chunks(TASK_PIXELS))
                .zip(self.scale.par_chunks(TASK_PIXELS))
                .map(|((corners, multi), scale)| {
                    let mut sum = 0.0;
                    for ((corners, m), w) in corners.iter().zip(multi).zip(scale) {
                        if let (Some(corners), true) = (corners, *w > 0.0) {
                            sum += w * (Anchors::interpolate(corners, &values).0[0] - m).powi(2);
                        }
                    }
                    sum
                })
                .collect();
            let sum: f64 = chunk_sums.iter().sum();
            worst = worst.max((sum / norm).sqrt());
        }
        worst
    }
}

/// The multiple-bounce value of `lobe` at `(wi, wo)`, channel 0.
fn multiple(lobe: &dyn crate::bsdf::ScalarBrdf<f64>, wi: [f64; 3], wo: [f64; 3]) -> f64 {
    let mut unused = crate::random::rng_stream(0, 0);
    lobe.eval_multi(Vec3::from_f64(wi), Vec3::from_f64(wo), &mut unused)
        .0[0]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axis_nodes_cover_both_ends() {
        assert_eq!(axis_nodes(10, 4), vec![0, 4, 8, 9]);
        assert_eq!(axis_nodes(9, 4), vec![0, 4, 8]);
        assert_eq!(axis_nodes(1, 4), vec![0]);
        let nodes = axis_nodes(10, 4);
        assert_eq!(bracket(&nodes, 4, 0), (0, 1, 0.0));
        assert_eq!(bracket(&nodes, 4, 6), (1, 2, 0.5));
        assert_eq!(bracket(&nodes, 4, 9), (2, 3, 1.0));
        assert_eq!(bracket(&[0], 4, 0), (0, 0, 0.0));
    }
}

//! `wang-pt` and `wang-bdpt`: the position-free multiple-bounce microfacet BRDF of Wang, Jin, Fan,
//! Yang, Holzschuch and Yan 2022 ("Position-free Multiple-bounce Computations for Smith Microfacet
//! BSDFs", ACM TOG 41(4); `papers/wang2022-position-free-multiple-bounce.md`), reflection only.
//!
//! | parameter | unit / range | meaning |
//! | --- | --- | --- |
//! | `alpha` (`ax`, `ay`) | > 0, 1e-4 to 3 tested, anisotropy ratio up to 100 | microfacet roughness |
//! | `ndf` | `ggx`, `beckmann` | distribution of normals |
//! | `height` | `correlated`, `uncorrelated` | segment term: eq. 15-23 (correlated) or eq. 6-11 (uncorrelated) |
//! | `fresnel` | white, Schlick, conductor, dielectric (reflection only) | reflectance of a microfacet at every vertex |
//!
//! | property | `wang-pt` | `wang-bdpt` |
//! | --- | --- | --- |
//! | kind | stochastic (`eval` is a one-path estimate) | stochastic |
//! | single bounce | exact, [`SingleBounce`] with the same height model | same |
//! | >= 2 bounces | path tracing with next-event estimation at every vertex, sec. 4.1 eq. 24-26 | bidirectional, every connection, balance heuristic, sec. 4.2 eq. 27-29 |
//! | bias | none w.r.t. eq. 5, except paths longer than [`MAX_SAMPLED`] + 1 bounces (measured below 1e-6 of the energy) | same (paths longer than `2 MAX_SAMPLED + 1` bounces, and strategies needing more than `MAX_SAMPLED` directions on one side) |
//! | energy | conserving for both height models (white furnace = 1) | same |
//! | reciprocal | uncorrelated: yes; correlated: no (paper sec. 3.5) | same |
//! | `sample` | exact analog random walk, weight = product of the Fresnel terms (sec. 4.3) | same sampler |
//! | `pdf` | approximate: exact density of the single-bounce exits plus a cosine lobe carrying the first-bounce non-exit mass (estimated by a 4x4 quadrature), in the spirit of sec. 4.3 | same |
//!
//! # The path integral (sec. 3.2)
//!
//! A path of `n` bounces is `(d_0, b_0, d_1, ..., b_{n-1}, d_n)` in the flow-of-light convention,
//! `d_0 = -wi`, `d_n = wo`. Its contribution (eq. 1) is `s_0 v_0 s_1 v_1 ... v_{n-1} s_n` (the paper
//! prints the last factor as `v_k`; it is the segment `s_k`), with the vertex term (eq. 2)
//! `v_j = F(-d_j . h_j) D(h_j) / (4 |d_j.z|)`, `h_j = normalize(-d_j + d_{j+1})`, and the
//! segment term `s_j = e_j p_j` (eq. 6): `p_j = G1(-d_j, h_j)` (eq. 11) is the full-sphere masking
//! of the direction that arrives at vertex `j` (eq. 9-10), `e_j` the probability that the light
//! leaving along `d_j` hits the microsurface again (middle segments, eq. 7 / eq. 23) or escapes
//! (last segment, eq. 8 / eq. 22).
//!
//! **Difference from PHYSICS.md's conventions:** the paper's `rho` (eq. 5) is the *cosine-weighted*
//! BRDF `f * wo.z` (the vertex term divides by the cosine of the incident side only; for one bounce
//! `rho = F D G2 / (4 wi.z)`). This file returns `f = rho / wo.z`, as every model does.
//!
//! The product is regrouped so that every factor stays finite at grazing angles, with
//! `A(w) = w.z (1 + Lambda(w))` the projected area ([`Microfacet::projected_area`]; `A(w) = |w.z| /
//! G1_dist(w)` on the whole sphere) and `zL(w) = |w.z| Lambda(w_up)` ([`Microfacet::z_lambda`]):
//!
//! `f / ... = prod_j (F_j D(h_j) / 4) * 1/A(wi) * prod_{j=1}^{n-1} K(d_{j-1}, d_j) * X(d_{n-1}, wo) / wo.z`
//!
//! where `p_j v_j = F_j D(h_j) / (4 A(-d_j))` is `F_j` times the visible-normal reflection density
//! of `d_{j+1}`, and `K(d_{j-1}, d_j) = e_j / A(-d_j)` ([`segment`]). With `L(d) = |Lambda(d)|
//! = A(-d) / |d.z|` (note `1 / |Lambda(-w)| = G1_dist(w)`, the identity behind eq. 18):
//!
//! | term | height-uncorrelated (eq. 7, 8, 11) | height-correlated (eq. 17, 18, 22, 23) |
//! | --- | --- | --- |
//! | `e_j`, `d_j` up | `Lambda(d_j) / (1 + Lambda(d_j))` | `Lambda(d_j) / (L(d_{j-1}) + Lambda(d_j))` |
//! | `e_j`, `d_j` down | 1 | 1 |
//! | exit `X(d_{n-1}, d_n)` | `1 / (1 + Lambda(d_n))` | `L(d_{n-1}) / (L(d_{n-1}) + Lambda(d_n))` |
//! | `K(d_{j-1}, d_j)` | `1 / (|d_j.z| + zL(d_j))` (symmetric in `d_j -> -d_j`, hence reciprocity) | `|d_{j-1}.z| / (A(-d_{j-1}) d_j.z + |d_{j-1}.z| zL(d_j))` up, `1 / A(-d_j)` down |
//!
//! Eq. 17 as printed reads `1 / (Lambda(-w_i) + Lambda(w_o))` in both of its cases; it must be
//! `1 / (|Lambda(-w_i)| + Lambda(w_o))` (equal to `1 / (1 + Lambda(w_i) + Lambda(w_o))` for an
//! upward `w_i`), which is what eq. 18 subtracts from `1 / |Lambda(-w_i)|` and what the authors'
//! released code computes. With it, at every vertex the continuation and the exit add up to 1, so
//! the walk is a Markov chain that loses no energy with either height model.
//!
//! # Estimators
//!
//! Both estimators sample directions by reflecting about a visible normal of the direction the
//! light arrives from ([`Microfacet::sample_visible`], exact below the horizon as well: the
//! published code's upper-hemisphere-only GGX sampler loses up to ~7% of the energy at
//! `alpha = 1`, PHYSICS.md). The sampling density of `d_{j+1}` at vertex `j` is
//! `pf = D(h_j) / (4 A(-d_j))` and, walking from the camera side, of `d_j` at vertex `j`,
//! `pb = D(h_j) / (4 A(d_{j+1}))`.
//!
//! - **PT** (eq. 25-26): one walk from `wi`; at every vertex `b_m`, `m >= 1`, a next-event
//!   connection to `wo` closes a path of `m + 1` bounces. The throughput carries the Fresnel
//!   factors and the continuation probabilities `e_j`; Russian roulette on the throughput
//!   (Arvo and Kirk 1990) ends the walk.
//! - **BDPT** (eq. 27-29): a walk from `wi` (directions `d_1, d_2, ...`) and one from `wo`
//!   (directions `d_{n-1}, d_{n-2}, ...`); every prefix pair is joined at one vertex evaluated in
//!   full. A path of `n` bounces has `n` strategies (`a` directions from the light side, `n - 1 - a`
//!   from the camera side), weighted by the balance heuristic over the products of `pf`/`pb`
//!   (computed with the usual running sums, O(1) per connection). Contributions are always
//!   evaluated from `wi` to `wo` (sec. 4.2), so the correlated model stays consistent.
//!
//! Russian-roulette probabilities are left out of the MIS densities; the weights still sum to
//! one over the strategies, so the estimate stays unbiased.

use super::single::SingleBounce;
use super::{Brdf, BrdfSample, BrdfValue, Rng};
use crate::microfacet::{Height, Microfacet};
use crate::scalar::{Real, Rgb, Vec3};
use rand::Rng as _;
use std::f64::consts::FRAC_1_PI;

/// Most directions a walk samples (PT and each BDPT side) before it stops; the sampler's cap on
/// bounces is `MAX_SAMPLED + 1`. The white walk at `alpha = 3` reaches it with probability below
/// 1e-6 (test `long_paths_are_rare`).
pub const MAX_SAMPLED: usize = 100;

/// Which Monte Carlo estimator of the path integral `eval` uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WangEstimator {
    /// Path tracing with next-event estimation at every bounce (sec. 4.1).
    PathTracing,
    /// Bidirectional path tracing with the balance heuristic (sec. 4.2).
    Bidirectional,
}

/// The position-free multiple-bounce BRDF (`wang-pt` / `wang-bdpt`).
#[derive(Clone, Copy, Debug)]
pub struct Wang {
    /// Microsurface, Fresnel and height model; also the exact single-bounce term.
    pub surface: SingleBounce<f64>,
    pub estimator: WangEstimator,
}

// ---------------------------------------------------------------------------------------------
// Path-integral pieces: pure functions of directions (no random numbers), generic over the
// scalar so the estimators can be made differentiable mechanically.
// ---------------------------------------------------------------------------------------------

/// A middle segment `d_j` (`0 < j < n`) reached from `d_{j-1}`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Segment<T> {
    /// `e_j`: probability that light leaving along `d_j` meets the microsurface again
    /// (eq. 7 uncorrelated, eq. 23 correlated), in [0, 1].
    pub cont: T,
    /// `K = e_j / A(-d_j)`: the continuation divided by the projected area that normalises the
    /// visible normals seen from `-d_j`; finite where `A(-d_j)` vanishes.
    pub kernel: T,
}

/// `L(d) A(-d)`-style helpers: `(A(-p), |p.z|)` for the previous direction `p` of a correlated
/// segment, where `L(p) = |Lambda(p)| = A(-p) / |p.z|`.
#[inline]
fn previous_terms<T: Real>(mf: &Microfacet<T>, p: Vec3<T>) -> (T, T) {
    (mf.projected_area(-p), p.z.abs())
}

/// The middle segment term of `d` reached from `p` (eq. 6-7 and 11, or 6, 18 and 23).
pub fn segment<T: Real>(mf: &Microfacet<T>, height: Height, p: Vec3<T>, d: Vec3<T>) -> Segment<T> {
    let zl = mf.z_lambda(d);
    if d.z.re64() <= 0.0 {
        // Downward: the watertight macrosurface is always hit again (eq. 7, second case).
        // A(-d) = |d.z| + zL(d) > 0 for every unit d.
        return Segment {
            cont: T::one(),
            kernel: (d.z.abs() + zl).recip(),
        };
    }
    match height {
        Height::Uncorrelated => {
            // e = 1 - G1_dist(d) = Lambda / (1 + Lambda); A(-d) = zL(d), A(d) = d.z + zL(d).
            let area = d.z + zl;
            Segment {
                cont: zl / area,
                kernel: area.recip(),
            }
        }
        Height::Correlated => {
            // e = Lambda(d) / (L(p) + Lambda(d)) multiplied through by |p.z| d.z.
            let (ap, pz) = previous_terms(mf, p);
            let den = ap * d.z + pz * zl;
            if den.re64() <= 0.0 {
                // Both Lambda(d) and L(p) vanish (p and d vertical): measure zero; escape.
                return Segment {
                    cont: T::zero(),
                    kernel: T::zero(),
                };
            }
            Segment {
                cont: pz * zl / den,
                kernel: pz / den,
            }
        }
    }
}

/// Probability that light leaving along the upward `d`, reached from `p`, escapes: the last
/// segment's `e` (eq. 8 uncorrelated, eq. 22 correlated), `1 - cont` of [`segment`]; 0 for a
/// downward `d`.
pub fn escape_probability<T: Real>(mf: &Microfacet<T>, height: Height, p: Vec3<T>, d: Vec3<T>) -> T {
    if d.z.re64() <= 0.0 {
        return T::zero();
    }
    let zl = mf.z_lambda(d);
    match height {
        Height::Uncorrelated => d.z / (d.z + zl),
        Height::Correlated => {
            let (ap, pz) = previous_terms(mf, p);
            let den = ap * d.z + pz * zl;
            if den.re64() <= 0.0 {
                return T::one();
            }
            ap * d.z / den
        }
    }
}

/// The last segment divided by the outgoing cosine, `X(p, wo) / wo.z` for `wo` above the surface:
/// uncorrelated `1 / A(wo)`, correlated `A(-p) / (A(-p) wo.z + |p.z| zL(wo))`.
pub fn exit_over_cos<T: Real>(mf: &Microfacet<T>, height: Height, p: Vec3<T>, wo: Vec3<T>) -> T {
    match height {
        Height::Uncorrelated => mf.projected_area(wo).recip(),
        Height::Correlated => {
            let (ap, pz) = previous_terms(mf, p);
            let den = ap * wo.z + pz * mf.z_lambda(wo);
            if den.re64() <= 0.0 {
                return T::zero();
            }
            ap / den
        }
    }
}

/// The vertex reflecting the light arriving from `w` (pointing away from the surface, `w = -d_j`)
/// into `d = d_{j+1}`: `(F(w.h), D(h) / 4)`, the vertex term of eq. 2 without its `1 / |w.z|`
/// (moved into the segment terms). `None` when the half vector is not a facet normal.
#[inline]
pub fn vertex<T: Real>(surface: &SingleBounce<T>, w: Vec3<T>, d: Vec3<T>) -> Option<(Rgb<T>, T)> {
    let sum = w + d;
    let len2 = sum.length_squared();
    if len2.re64() <= 0.0 {
        return None;
    }
    let h = sum * len2.sqrt().recip();
    if h.z.re64() <= 0.0 {
        return None;
    }
    let d4 = surface.microfacet.d(h) * T::c(0.25);
    Some((surface.fresnel.eval(w.dot(h)), d4))
}

// ---------------------------------------------------------------------------------------------
// Estimators (f64; random decisions drawn here, weights from the pieces above).
// ---------------------------------------------------------------------------------------------

/// Multiply two non-negative factors of an MIS ratio, saturating instead of overflowing.
#[inline]
fn mul_sat(a: f64, b: f64) -> f64 {
    const BIG: f64 = 1e300;
    (a.min(BIG) * b.min(BIG)).min(BIG)
}

/// `a / b` for non-negative densities, saturating (and 1 for 0 / 0).
#[inline]
fn ratio_sat(a: f64, b: f64) -> f64 {
    if b > 0.0 {
        (a / b).min(1e300)
    } else if a > 0.0 {
        1e300
    } else {
        1.0
    }
}

/// One vertex of a BDPT sub-path: the walk direction `x_m` (in that walk's own flow convention:
/// `x_0 = -start`, `x_{m+1}` = reflection of `-x_m`).
#[derive(Clone, Copy, Debug)]
struct Node {
    x: Vec3<f64>,
    /// Connection throughput of the prefix `x_0..x_m` (see [`Wang::subpath`]).
    beta: [f64; 3],
    /// `A(-x_m)`: normaliser of the visible normals seen from `-x_m` (the walk's own sampling).
    area_in: f64,
    /// `e` of the segment `x_m` in this walk's orientation: the probability with which the walk
    /// goes on to sample `x_{m+1}` (1 at `m = 0`).
    cont: f64,
    /// Density with which this walk sampled `x_m` (m >= 1), survival of `x_{m-1}` included.
    pdf_own: f64,
    /// `D(h_{m-1}) / (4 A(x_m))`: the solid-angle density with which the other walk samples
    /// `x_{m-1}` at the same vertex (m >= 1), before its survival probability.
    geo_rev: f64,
    /// Running MIS sum `P(m-2)` (m >= 2): `P(k) = r_k (1 + P(k-1))`, `P(0) = 0`, with
    /// `r_k = p_other(x_k) / p_own(x_k)` the density ratio of direction `x_k`.
    mis: f64,
}

impl Wang {
    pub fn new(surface: SingleBounce<f64>, estimator: WangEstimator) -> Self {
        Wang { surface, estimator }
    }

    fn height(&self) -> Height {
        self.surface.height
    }

    /// The analog walk's survival: continue past a segment with its continuation probability.
    #[inline]
    fn survives(cont: f64, rng: &mut Rng) -> bool {
        cont >= 1.0 || (cont > 0.0 && rng.random::<f64>() < cont)
    }

    /// Sample the next direction of a walk whose current direction is `x` (light arriving at the
    /// next vertex along `x`). Returns `(next, F, D(h)/4)`.
    #[inline]
    fn scatter(&self, x: Vec3<f64>, rng: &mut Rng) -> Option<(Vec3<f64>, Rgb<f64>, f64)> {
        let mf = &self.surface.microfacet;
        let w = -x;
        if mf.projected_area(w) <= 0.0 {
            return None;
        }
        let u = [rng.random::<f64>(), rng.random::<f64>()];
        let h = mf.sample_visible(w, u);
        let next = w.reflect(h);
        let len = next.length();
        if !(len > 0.0) || !len.is_finite() {
            return None;
        }
        let d4 = mf.d(h) * 0.25;
        Some((next * len.recip(), self.surface.fresnel.eval(w.dot(h)), d4))
    }

    /// PT estimate of the >= 2-bounce part of `f(wi, wo)` (eq. 25): an analog walk from `wi`
    /// (survival with probability `e_m` past each segment, so the throughput is the product of
    /// the Fresnel terms) with a next-event connection to `wo` at every vertex `b_m`, `m >= 1`.
    fn multi_pt(&self, wi: Vec3<f64>, wo: Vec3<f64>, rng: &mut Rng) -> [f64; 3] {
        let mf = &self.surface.microfacet;
        let height = self.height();
        let mut sum = [0.0; 3];
        let mut beta = [1.0; 3];
        let Some((mut d, f, _)) = self.scatter(-wi, rng) else {
            return sum;
        };
        for ch in 0..3 {
            beta[ch] *= f.0[ch];
        }
        let mut prev = -wi;
        for _ in 1..=MAX_SAMPLED {
            let seg = segment(mf, height, prev, d);
            // Next-event estimation at b_m closes a path of m + 1 bounces.
            if let Some((f, d4)) = vertex(&self.surface, -d, wo) {
                let c = d4 * seg.kernel * exit_over_cos(mf, height, d, wo);
                for ch in 0..3 {
                    sum[ch] += beta[ch] * f.0[ch] * c;
                }
            }
            if !Self::survives(seg.cont, rng) {
                break;
            }
            let Some((next, f, _)) = self.scatter(d, rng) else {
                break;
            };
            for ch in 0..3 {
                beta[ch] *= f.0[ch];
            }
            prev = d;
            d = next;
        }
        sum.map(|v| if v.is_finite() && v > 0.0 { v } else { 0.0 })
    }

    /// A BDPT sub-path from `start` (`wi` for the light side, `wo` for the camera side), an
    /// analog walk like PT's.
    ///
    /// Light side: `beta(m) = prod_{j<m} F_j * K(x_{m-1}, x_m)` (`1 / A(wi)` at `m = 0`): the path
    /// contribution over the density of the prefix, including the segment of its last direction.
    ///
    /// Camera side (`x_m = -d_{n-m}`): `beta(0) = 1`, `beta(m+1) = beta(m) F_m A(-x_m) *
    /// [X(-x_1, wo) / wo.z if m = 0, else K(-x_{m+1}, -x_m)] / e_walk(x_m)`: the vertex terms over
    /// their backward densities and the segments of `d_{n-m+1} .. d_n`, evaluated in the
    /// physical (light-to-camera) orientation; the segment of the last direction depends on the
    /// light side and is evaluated at the connection.
    fn subpath(&self, start: Vec3<f64>, camera_side: bool, rng: &mut Rng) -> Vec<Node> {
        let mf = &self.surface.microfacet;
        let height = self.height();
        let a0 = mf.projected_area(start);
        let mut nodes = Vec::with_capacity(8);
        nodes.push(Node {
            x: -start,
            beta: if camera_side { [1.0; 3] } else { [1.0 / a0; 3] },
            area_in: a0,
            cont: 1.0,
            pdf_own: 0.0,
            geo_rev: 0.0,
            mis: 0.0,
        });
        let mut fresnel = [1.0; 3];
        for m in 0..MAX_SAMPLED {
            let node = nodes[m];
            if !Self::survives(node.cont, rng) {
                break;
            }
            let Some((next, f, d4)) = self.scatter(node.x, rng) else {
                break;
            };
            let own = segment(mf, height, node.x, next);
            // The segment of x_m as the other walk sees it: direction -x_m after -x_{m+1}.
            let rev = (m >= 1).then(|| segment(mf, height, -next, -node.x));
            let mis = match rev {
                Some(rev) if m >= 2 => {
                    let r = ratio_sat(rev.cont * node.geo_rev, nodes[m - 1].pdf_own);
                    mul_sat(r, 1.0 + node.mis)
                }
                _ => 0.0,
            };
            let beta = if camera_side {
                let seg = match rev {
                    Some(rev) => rev.kernel,
                    None => exit_over_cos(mf, height, -next, start),
                };
                let s = node.area_in * seg / node.cont;
                [0, 1, 2].map(|ch| node.beta[ch] * f.0[ch] * s)
            } else {
                for ch in 0..3 {
                    fresnel[ch] *= f.0[ch];
                }
                fresnel.map(|p| p * own.kernel)
            };
            if !beta.iter().all(|b| b.is_finite()) {
                break;
            }
            nodes.push(Node {
                x: next,
                beta,
                area_in: mf.projected_area(-next),
                cont: own.cont,
                pdf_own: node.cont * d4 / node.area_in,
                geo_rev: d4 / mf.projected_area(next),
                mis,
            });
        }
        nodes
    }

    /// The balance-heuristic sum of eq. 28 over the strategies that take more of the path from
    /// the other side than this connection does, relative to this connection's density: `own`
    /// is this side's sub-path (last node `k`), `other` the other side's last node, `d4` the
    /// junction's `D(h) / 4`, `e_back` the other walk's continuation of the segment `-x_k` after
    /// its own last direction (needed when `k >= 2`).
    #[inline]
    fn mis_side(own: &[Node], other: &Node, d4: f64, e_back: impl FnOnce() -> f64) -> f64 {
        let k = own.len() - 1;
        if k == 0 {
            return 0.0;
        }
        let last = &own[k];
        // Density with which the other walk would sample x_k at the junction.
        let r_k = ratio_sat(other.cont * d4 / other.area_in, last.pdf_own);
        if k == 1 {
            return r_k;
        }
        let r_prev = ratio_sat(e_back() * last.geo_rev, own[k - 1].pdf_own);
        mul_sat(r_k, 1.0 + mul_sat(r_prev, 1.0 + last.mis))
    }

    /// BDPT estimate of the >= 2-bounce part of `f(wi, wo)` (eq. 29).
    fn multi_bdpt(&self, wi: Vec3<f64>, wo: Vec3<f64>, rng: &mut Rng) -> [f64; 3] {
        let mf = &self.surface.microfacet;
        let height = self.height();
        let light = self.subpath(wi, false, rng);
        let camera = self.subpath(wo, true, rng);
        let mut sum = [0.0; 3];
        for a in 0..light.len() {
            let lf = &light[a];
            for c in 0..camera.len() {
                if a + c == 0 {
                    continue; // the single bounce, computed exactly
                }
                let cm = &camera[c];
                // Join d_a = lf.x (arriving) with d_{a+1} = -cm.x (leaving) at one vertex.
                let Some((f, d4)) = vertex(&self.surface, -lf.x, -cm.x) else {
                    continue;
                };
                let fwd = (c >= 1).then(|| segment(mf, height, lf.x, -cm.x));
                let seg = match fwd {
                    Some(fwd) => fwd.kernel,
                    None => exit_over_cos(mf, height, lf.x, wo),
                };
                let left = Self::mis_side(&light[..=a], cm, d4, || {
                    segment(mf, height, cm.x, -lf.x).cont
                });
                let right = Self::mis_side(&camera[..=c], lf, d4, || {
                    fwd.map_or(1.0, |s| s.cont)
                });
                let s = d4 * seg / (1.0 + left + right);
                for ch in 0..3 {
                    let v = lf.beta[ch] * cm.beta[ch] * f.0[ch] * s;
                    if v.is_finite() && v > 0.0 {
                        sum[ch] += v;
                    }
                }
            }
        }
        sum
    }

    /// First-bounce exit mass of the white walk, `integral over d up of D_wi(h) / (4 d.h) *
    /// X(-wi, d)`, by a 4x4 midpoint rule over the visible-normal sampler's unit square. Only
    /// used by the approximate [`Brdf::pdf`].
    fn first_exit_mass(&self, wi: Vec3<f64>) -> f64 {
        const N: usize = 4;
        let mf = &self.surface.microfacet;
        let mut sum = 0.0;
        for i in 0..N {
            for j in 0..N {
                let u = [(i as f64 + 0.5) / N as f64, (j as f64 + 0.5) / N as f64];
                let d = wi.reflect(mf.sample_visible(wi, u));
                sum += escape_probability(mf, self.height(), -wi, d);
            }
        }
        sum / (N * N) as f64
    }
}

impl Brdf for Wang {
    fn eval(&self, wi: Vec3<f64>, wo: Vec3<f64>, rng: &mut Rng) -> BrdfValue {
        if wi.z <= 0.0 || wo.z <= 0.0 {
            return BrdfValue::default();
        }
        let multi = match self.estimator {
            WangEstimator::PathTracing => self.multi_pt(wi, wo, rng),
            WangEstimator::Bidirectional => self.multi_bdpt(wi, wo, rng),
        };
        BrdfValue {
            single: SingleBounce::eval(&self.surface, wi, wo).0,
            multi,
        }
    }

    /// The analog random walk of sec. 4.3: reflect about a visible normal, then leave with the
    /// exit probability of the segment term (or continue; downward directions always continue).
    /// Its density is exactly the white `f cos`, so the weight is the product of the Fresnel
    /// terms. `None` past [`MAX_SAMPLED`] + 1 bounces.
    fn sample(&self, wi: Vec3<f64>, u: [f64; 2], rng: &mut Rng) -> Option<BrdfSample> {
        if wi.z <= 0.0 {
            return None;
        }
        let mf = &self.surface.microfacet;
        let mut weight = [1.0; 3];
        let (mut prev, mut w) = (-wi, wi);
        for bounce in 1..=(MAX_SAMPLED as u32 + 1) {
            if mf.projected_area(w) <= 0.0 {
                return None;
            }
            let uv = if bounce == 1 {
                u
            } else {
                [rng.random(), rng.random()]
            };
            let h = mf.sample_visible(w, uv);
            let d = w.reflect(h).normalize();
            let f = self.surface.fresnel.eval(w.dot(h));
            for ch in 0..3 {
                weight[ch] *= f.0[ch];
            }
            if d.z > 0.0 {
                let exit = escape_probability(mf, self.height(), prev, d);
                if rng.random::<f64>() < exit {
                    return Some(BrdfSample {
                        wo: d,
                        weight,
                        pdf: self.pdf(wi, d),
                        bounces: bounce,
                    });
                }
            }
            prev = d;
            w = -d;
        }
        None
    }

    /// Approximate density of [`Brdf::sample`]: the exact density of the paths that leave after
    /// one bounce (the white single-bounce `f cos`) plus the remaining mass, estimated by
    /// [`Wang::first_exit_mass`], spread as a cosine lobe (as Heitz et al. 2016 and sec. 4.3 do).
    fn pdf(&self, wi: Vec3<f64>, wo: Vec3<f64>) -> f64 {
        if wi.z <= 0.0 || wo.z <= 0.0 {
            return 0.0;
        }
        let mf = &self.surface.microfacet;
        let single = match vertex(&self.surface, wi, wo) {
            Some((_, d4)) => {
                d4 / mf.projected_area(wi) * exit_over_cos(mf, self.height(), -wi, wo) * wo.z
            }
            None => 0.0,
        };
        let rest = (1.0 - self.first_exit_mass(wi)).max(0.0);
        let p = single + rest * wo.z * FRAC_1_PI;
        if p.is_finite() {
            p
        } else {
            0.0
        }
    }

    fn is_stochastic(&self) -> bool {
        true
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::needless_range_loop)] // channel loops over parallel arrays read best indexed

    use super::*;
    use crate::albedo::rng_stream;
    use crate::bsdf::testing::*;
    use crate::material::FresnelSpec;
    use crate::microfacet::NdfKind;
    use std::time::Instant;

    const COPPER: FresnelSpec = FresnelSpec::Conductor {
        eta: [0.2378, 1.0066, 1.2404],
        k: [3.6264, 2.5823, 2.3929],
    };
    const HEIGHTS: [Height; 2] = [Height::Uncorrelated, Height::Correlated];
    const NDFS: [NdfKind; 2] = [NdfKind::Ggx, NdfKind::Beckmann];
    const ESTIMATORS: [WangEstimator; 2] =
        [WangEstimator::PathTracing, WangEstimator::Bidirectional];

    fn surface(ndf: NdfKind, ax: f64, ay: f64, fresnel: FresnelSpec, height: Height) -> SingleBounce<f64> {
        SingleBounce {
            microfacet: Microfacet::new(ndf, ax, ay),
            fresnel: fresnel.to_fresnel(),
            height,
        }
    }

    fn wang(ndf: NdfKind, ax: f64, ay: f64, fresnel: FresnelSpec, height: Height, e: WangEstimator) -> Wang {
        Wang::new(surface(ndf, ax, ay, fresnel, height), e)
    }

    /// `rho = f(path)` of eq. 1 transcribed literally: vertex terms eq. 2, segment terms eq. 6-8
    /// and 11 (uncorrelated) or eq. 6, 11, 17-18, 22-23 (correlated), with `G1` of eq. 9-10
    /// computed from `Lambda` (so not valid at exactly grazing directions).
    fn literal_rho(s: &SingleBounce<f64>, d: &[Vec3<f64>]) -> [f64; 3] {
        let mf = &s.microfacet;
        let n = d.len() - 1;
        let lam = |w: Vec3<f64>| mf.lambda(w);
        let g1_dist = |w: Vec3<f64>| (1.0 / (1.0 + lam(w))).abs();
        let g1 = |w: Vec3<f64>, m: Vec3<f64>| if w.dot(m) > 0.0 { g1_dist(w) } else { 0.0 };
        let h: Vec<Vec3<f64>> = (0..n).map(|i| (-d[i] + d[i + 1]).normalize()).collect();
        let mut rho = [1.0; 3];
        for i in 0..n {
            let f = s.fresnel.eval((-d[i]).dot(h[i])).0;
            let v = mf.d(h[i]) / (4.0 * d[i].z.abs());
            for c in 0..3 {
                rho[c] *= f[c] * v;
            }
        }
        for i in 0..=n {
            let p = if i < n { g1(-d[i], h[i]) } else { 1.0 };
            let e = if i == 0 {
                1.0
            } else {
                match s.height {
                    Height::Uncorrelated => match (i < n, d[i].z > 0.0) {
                        (true, true) => 1.0 - g1(d[i], h[i - 1]),
                        (true, false) => 1.0,
                        (false, true) => g1(d[i], h[i - 1]),
                        (false, false) => 0.0,
                    },
                    Height::Correlated => {
                        let (w_in, w_out) = (-d[i - 1], d[i]);
                        let l = lam(-w_in).abs();
                        let last = 1.0 / (l + lam(w_out));
                        let g2 = match (i < n, w_out.z > 0.0) {
                            (true, true) => 1.0 / l - last,
                            (true, false) => 1.0 / l,
                            (false, true) => last,
                            (false, false) => 0.0,
                        };
                        g2 / g1_dist(w_in)
                    }
                }
            };
            for c in 0..3 {
                rho[c] *= e * p;
            }
        }
        rho
    }

    /// `f = rho / wo.z` of a whole path through the regrouped pieces the estimators use.
    fn factored_f(s: &SingleBounce<f64>, d: &[Vec3<f64>]) -> [f64; 3] {
        let mf = &s.microfacet;
        let n = d.len() - 1;
        let mut f = [1.0 / mf.projected_area(-d[0]); 3];
        for i in 0..n {
            let Some((fr, d4)) = vertex(s, -d[i], d[i + 1]) else {
                return [0.0; 3];
            };
            let seg = if i + 1 < n {
                segment(mf, s.height, d[i], d[i + 1]).kernel
            } else {
                exit_over_cos(mf, s.height, d[i], d[i + 1])
            };
            for c in 0..3 {
                f[c] *= fr.0[c] * d4 * seg;
            }
        }
        f
    }

    #[test]
    fn calibrate() {
        for e in ESTIMATORS {
            for height in HEIGHTS {
                for ndf in NDFS {
                    for alpha in [0.1, 0.3, 0.6, 1.0, 1.5] {
                        for theta in [0.0, 30.0, 60.0, 80.0] {
                            let m = wang(ndf, alpha, alpha, FresnelSpec::White, height, e);
                            let guide = surface(ndf, alpha, alpha, FresnelSpec::White, height);
                            let wi = unit(theta, 20.0);
                            let n = 20_000;
                            let t = Instant::now();
                            let a = albedo_by_eval(&m, &guide, wi, n, 7);
                            let dt = t.elapsed().as_secs_f64() / n as f64 * 1e9;
                            let s = albedo_by_sampling(&m, wi, 4096, 8);
                            eprintln!(
                                "{e:?} {height:?} {ndf:?} a={alpha} th={theta}: eval {:.4} +- {:.4} ({:.0} ns)  sampling {:.4} +- {:.4}",
                                a.value[0], a.stderr[0], dt, s.value[0], s.stderr[0]
                            );
                        }
                    }
                }
            }
        }
    }
}

//! Variable projection (Golub & Pereyra 1973): at fixed roughness, solve the colour parameters
//! (Schlick F0 and the Lambertian albedo, per channel, within [0, 1]) in closed form, so the
//! search runs over roughness only (ENGINEERING-NOTES.md, "Gradients").
//!
//! | piece | how |
//! | --- | --- |
//! | dependence on F0 | each pixel's prediction is a polynomial in a grey Schlick F0 of degree [`fresnel_degree`]: 1 for `single` (Schlick is linear in F0), 2 for `fast-msx` (`F^2`, eq. 19) and `turquin` (`f_single (1 + F0 k)`); `kulla-conty` is `A + B F0 + W s(F0)`, its lobe an image `W` times the colour `s = F_ms / (pi (1 - E_avg))` (Kulla & Conty 2017), which is rational in F0; `tabulated` is `A + B F0 + sum_g inner_g(F0) Q_g(F0)` per order group `g` (2, 3, >= 4), `Q_g` a quadratic per pixel (the product of its two end weights, each affine in F0) and `inner_g` the same at every pixel (1, `F_mid,3`, and the tail sum over the orders >= 4, a polynomial of degree up to 30; `bsdf::tabulated::SchlickOrders`); the stochastic models are long polynomials (one Fresnel factor per bounce of a walk) and get degree 4 |
//! | basis | monomials: the model rendered at the Chebyshev-Lobatto nodes of F0 in [0, 1] (with the fit's common random numbers), converted to monomial coefficients per pixel; `kulla-conty`: `1, F0, s(F0)`, with `A`, `B` from two value passes of the single bounce and `W` from one of the whole lobe; `tabulated`: `1, F0, F0^2, F0^3, h, F0 h, F0^2 h` with `h` the tail factor (`F_mid,3` is affine and folds into the powers), `A`, `B` from the same two passes and the `Q_g` from one evaluation of the order parts at the anchors ([`Objective::order_parts`]) |
//! | diffuse | linear: the white Lambertian image [`crate::render::lambertian_pixels`] |
//! | solve per channel | the weighted squared error `sum v (P(F0) + rho d - t)^2` from moment sums: `rho` in closed form, clamped to [0, 1] (non-negative least squares in one variable); `F0` by a scan of 201 points and golden-section refinement |
//! | stochastic models | the objective's two renders on independent streams give two polynomials `P1`, `P2` per pixel, and the moments are those of the pair loss `sum v (P1 + rho d - t)(P2 + rho d - t)` ([`crate::loss::Loss::pair_value`]): `sum v A1_j A2_k` symmetrised, `sum v (A1_j + A2_j)/2 t` |
//! | losses | those that are weighted squared errors ([`crate::loss::Loss::quadratic_weights`]): `l2`, `relative-l2` |
//!
//! For degree-1 and degree-2 models, `kulla-conty` and `tabulated` the projected loss is
//! exact; for the stochastic models it is a polynomial approximation in F0. The fitter always finishes with a joint
//! search over all coordinates from the projected optimum.

use super::objective::{interpolate, Objective, OrderParts};
use super::params::{logit, sigmoid, FresnelFamily};
use crate::bsdf::kulla_conty::KullaConty;
use crate::bsdf::Model;
use crate::render::anchors::Anchors;
use crate::render::lambertian_pixels;
use rayon::prelude::*;
use std::sync::atomic::{AtomicUsize, Ordering};

/// Degree in F0 of the prediction's polynomial model (see the module docs).
pub fn fresnel_degree(model: Model) -> usize {
    match model {
        Model::Single => 1,
        Model::FastMsx | Model::Turquin => 2,
        _ => 4,
    }
}

/// Most basis functions of F0 of any model: 7 for `tabulated` ([`NodeRenders::Ordered`]);
/// the F0 nodes of the others number `fresnel_degree + 1`, at most 5.
const MAX_TERMS: usize = 7;

/// Loss pixels per parallel chunk of the moment sums.
const MOMENT_CHUNK: usize = 4096;

/// Grid of the F0 scan before golden-section refinement.
const F0_SCAN: usize = 201;
const GOLDEN_ITERATIONS: usize = 80;

/// The renders of [`Projection::node_renders`], from which each pixel's monomial coefficients
/// in F0 follow ([`NodeRenders::coefficients`]).
enum NodeRenders<'o> {
    /// The whole render at every node, `[node][stream][pixel]`.
    Whole {
        renders: Vec<Vec<Vec<[f64; 3]>>>,
        lagrange: &'o [[f64; MAX_TERMS]],
    },
    /// The render plan interpolates the multiple-bounce term from anchors: the part every
    /// stream shares (exact single bounce, affine in a Schlick F0) as its two monomial
    /// coefficients per pixel, the multiple-bounce term as monomial coefficients per anchor
    /// (the interpolation is linear, so it carries them to the pixels,
    /// [`interpolate`]) and, at the pixels without anchors, per pixel.
    Anchored {
        shared: Vec<[[f64; 2]; 3]>,
        anchors: &'o Anchors,
        lambert: &'o [[f64; 3]],
        /// `[stream][anchor]`, coefficient `j` of channel `c` at `3 j + c`.
        multi: Vec<Vec<[f64; 3 * MAX_TERMS]>>,
        /// `[stream]`: the pixels without anchors in increasing order, with their
        /// coefficients laid out as `multi`.
        exact: Vec<Vec<(usize, [f64; 3 * MAX_TERMS])>>,
        /// Number of F0 nodes (the polynomial's degree plus one).
        nodes: usize,
    },
    /// `kulla-conty`: the single bounce's two coefficients per pixel, and the compensation
    /// lobe as an image `W` that does not depend on F0 times a colour `s(F0)` that depends
    /// on nothing else: `A + B F0 + W s(F0)` ([`Objective::compensation_parts`]), exact in the
    /// basis `1, F0, s(F0)`.
    Compensated {
        single: Vec<[[f64; 2]; 3]>,
        image: Vec<[f64; 3]>,
        /// `s` per channel at a grey F0: Kulla & Conty's `F_ms / (pi (1 - E_avg))` at the
        /// solve's roughness.
        colour: Box<dyn Fn(f64) -> [f64; 3] + Sync + 'o>,
    },
    /// `tabulated` with a Schlick F0 ([`Objective::order_parts`]): the single bounce's two
    /// coefficients per pixel, and the multiple-bounce lobe of each order group as a quadratic
    /// in F0 times an inner factor that does not depend on the pixel: 1, `F_mid,3 = m + (1 -
    /// m) F0` (affine, so it folds into the powers up to `F0^3`) and the tail factor `h(F0)` of
    /// the orders >= 4. Exact in the basis `1, F0, F0^2, F0^3, h, F0 h, F0^2 h`.
    Ordered(OrderParts<'o>),
}

impl NodeRenders<'_> {
    /// Number of streams.
    fn streams(&self) -> usize {
        match self {
            NodeRenders::Whole { renders, .. } => renders[0].len(),
            NodeRenders::Anchored { multi, .. } => multi.len(),
            NodeRenders::Compensated { .. } | NodeRenders::Ordered(_) => 1,
        }
    }

    /// Number of basis functions of F0 ([`NodeRenders::basis`]).
    fn terms(&self) -> usize {
        match self {
            NodeRenders::Whole { lagrange, .. } => lagrange.len(),
            NodeRenders::Anchored { nodes, .. } => *nodes,
            NodeRenders::Compensated { .. } => 3,
            NodeRenders::Ordered(_) => 7,
        }
    }

    /// The basis functions of F0 at `f` for `channel`: monomials `1, f, ..., f^(terms - 1)`,
    /// or `1, f, s(f)` for [`NodeRenders::Compensated`].
    fn basis(&self, channel: usize, f: f64) -> [f64; MAX_TERMS] {
        let mut phi = [0.0; MAX_TERMS];
        match self {
            NodeRenders::Compensated { colour, .. } => {
                phi[..3].copy_from_slice(&[1.0, f, colour(f)[channel]]);
            }
            NodeRenders::Ordered(parts) => {
                let h = parts.orders.tail_factor(f);
                phi.copy_from_slice(&[1.0, f, f * f, f * f * f, h, f * h, f * f * h]);
            }
            _ => {
                let mut power = 1.0;
                for phi in phi.iter_mut().take(self.terms()) {
                    *phi = power;
                    power *= f;
                }
            }
        }
        phi
    }

    /// Coefficients of pixel `p`'s prediction in `stream` in [`NodeRenders::basis`], per
    /// channel.
    fn coefficients(&self, stream: usize, p: usize) -> [[f64; MAX_TERMS]; 3] {
        let mut a = [[0.0; MAX_TERMS]; 3];
        match self {
            NodeRenders::Whole { renders, lagrange } => {
                a = monomials(lagrange, |node| renders[node][stream][p]);
            }
            NodeRenders::Anchored {
                shared,
                anchors,
                lambert,
                multi,
                exact,
                ..
            } => {
                let own = match &anchors.corners[p] {
                    Some(corners) => interpolate(corners, &multi[stream], &lambert[p]),
                    None => {
                        let exact = &exact[stream];
                        let i = exact
                            .binary_search_by_key(&p, |&(k, _)| k)
                            .expect("a pixel without anchors is evaluated exactly");
                        exact[i].1
                    }
                };
                for (c, (a, [c0, c1])) in a.iter_mut().zip(shared[p]).enumerate() {
                    for (j, a) in a.iter_mut().enumerate() {
                        *a = own[3 * j + c];
                    }
                    a[0] += c0;
                    a[1] += c1;
                }
            }
            NodeRenders::Compensated { single, image, .. } => {
                for (c, a) in a.iter_mut().enumerate() {
                    let [intercept, slope] = single[p][c];
                    a[..3].copy_from_slice(&[intercept, slope, image[p][c]]);
                }
            }
            NodeRenders::Ordered(parts) => {
                let raw = match parts
                    .anchors
                    .and_then(|anchors| anchors.corners[p].as_ref())
                {
                    Some(corners) => interpolate(corners, &parts.multi, &parts.lambert[p]),
                    None => {
                        let i = parts
                            .exact
                            .binary_search_by_key(&p, |&(k, _)| k)
                            .expect("a pixel without anchors is evaluated exactly");
                        parts.exact[i].1
                    }
                };
                let m = parts.orders.middle_moment();
                for (c, a) in a.iter_mut().enumerate() {
                    let q = |g: usize, k: usize| raw[3 * (3 * g + k) + c];
                    let [intercept, slope] = parts.single[p][c];
                    a.copy_from_slice(&[
                        intercept + q(0, 0) + m * q(1, 0),
                        slope + q(0, 1) + (1.0 - m) * q(1, 0) + m * q(1, 1),
                        q(0, 2) + (1.0 - m) * q(1, 1) + m * q(1, 2),
                        (1.0 - m) * q(1, 2),
                        q(2, 0),
                        q(2, 1),
                        q(2, 2),
                    ]);
                }
            }
        }
        a
    }
}

/// The projected problem of one objective.
pub struct Projection<'o, 'r> {
    objective: &'o Objective<'r>,
    /// F0 nodes (as the material sees them after the logit map).
    nodes: Vec<f64>,
    /// Monomial coefficients of the Lagrange polynomial of each node (1 there, 0 at the
    /// others): the columns of the inverse Vandermonde matrix of `nodes`.
    lagrange: Vec<[f64; MAX_TERMS]>,
    /// Per loss pixel and channel: weights `v` of the squared error.
    weights: Vec<[f64; 3]>,
    /// Per loss pixel: white Lambertian prediction, when the space fits a diffuse albedo.
    diffuse: Option<Vec<[f64; 3]>>,
    /// Number of roughness coordinates (1 isotropic, 2 anisotropic).
    pub roughness_dim: usize,
    /// Renders made so far (one per F0 node and solve).
    renders: AtomicUsize,
}

/// Moment sums of one channel, from which the squared error at any (F0, rho) follows.
struct Moments {
    /// `sum v A_j A_k`, `sum v A_j t`, `sum v A_j d` over pixels (A = monomial coefficients;
    /// for two renders, `A_j A_k` is `(A1_j A2_k + A2_j A1_k) / 2` and `A_j` is `(A1_j + A2_j) / 2`).
    aa: Vec<Vec<f64>>,
    at: Vec<f64>,
    ad: Vec<f64>,
    tt: f64,
    dd: f64,
    dt: f64,
}

impl Moments {
    /// The moments of two disjoint pixel sets together.
    fn add(mut self, other: Moments) -> Moments {
        for (row, other) in self.aa.iter_mut().zip(&other.aa) {
            row.iter_mut().zip(other).for_each(|(a, b)| *a += b);
        }
        self.at.iter_mut().zip(&other.at).for_each(|(a, b)| *a += b);
        self.ad.iter_mut().zip(&other.ad).for_each(|(a, b)| *a += b);
        self.tt += other.tt;
        self.dd += other.dd;
        self.dt += other.dt;
        self
    }

    /// `(squared error, rho)` at F0 = `f`, with rho optimal in [0, 1]; `basis` gives the
    /// basis functions at `f` ([`NodeRenders::basis`]).
    fn error(&self, f: f64, basis: &impl Fn(f64) -> [f64; MAX_TERMS]) -> (f64, f64) {
        let phi = basis(f);
        let (mut pp, mut pt, mut pd) = (0.0, 0.0, 0.0);
        for j in 0..self.at.len() {
            pt += phi[j] * self.at[j];
            pd += phi[j] * self.ad[j];
            for k in 0..self.at.len() {
                pp += phi[j] * phi[k] * self.aa[j][k];
            }
        }
        let base = pp - 2.0 * pt + self.tt;
        if self.dd <= 0.0 {
            return (base, 0.0);
        }
        let rho = ((self.dt - pd) / self.dd).clamp(0.0, 1.0);
        (base + 2.0 * rho * (pd - self.dt) + rho * rho * self.dd, rho)
    }

    /// F0 in [0, 1] minimising the error, with its rho and error.
    fn minimise(&self, basis: impl Fn(f64) -> [f64; MAX_TERMS]) -> (f64, f64, f64) {
        let grid = |i: usize| i as f64 / (F0_SCAN - 1) as f64;
        let scan: Vec<f64> = (0..F0_SCAN)
            .map(|i| self.error(grid(i), &basis).0)
            .collect();
        let best = (0..F0_SCAN)
            .min_by(|&a, &b| scan[a].total_cmp(&scan[b]))
            .expect("the scan has points");
        let (mut lo, mut hi) = (
            grid(best.saturating_sub(1)),
            grid((best + 1).min(F0_SCAN - 1)),
        );
        let ratio = (5f64.sqrt() - 1.0) / 2.0;
        for _ in 0..GOLDEN_ITERATIONS {
            let a = hi - ratio * (hi - lo);
            let b = lo + ratio * (hi - lo);
            if self.error(a, &basis).0 < self.error(b, &basis).0 {
                hi = b;
            } else {
                lo = a;
            }
        }
        let candidates = [grid(best), 0.5 * (lo + hi)];
        let f = candidates
            .into_iter()
            .min_by(|a, b| {
                self.error(*a, &basis)
                    .0
                    .total_cmp(&self.error(*b, &basis).0)
            })
            .expect("two candidates");
        let (e, rho) = self.error(f, &basis);
        (f, rho, e)
    }
}

/// Monomial coefficients, per channel, of the polynomial through the nodes' values
/// `values(node)`: the values times the inverse Vandermonde matrix, whose columns `lagrange`
/// holds (one per node).
fn monomials(
    lagrange: &[[f64; MAX_TERMS]],
    values: impl Fn(usize) -> [f64; 3],
) -> [[f64; MAX_TERMS]; 3] {
    let mut a = [[0.0; MAX_TERMS]; 3];
    for (node, lagrange) in lagrange.iter().enumerate() {
        for (a, y) in a.iter_mut().zip(values(node)) {
            a.iter_mut().zip(lagrange).for_each(|(a, l)| *a += l * y);
        }
    }
    a
}

/// Solves `V c = y` for the monomial coefficients `c` of the polynomial through `(x_j, y_j)`
/// (Vandermonde by Gaussian elimination with partial pivoting; K <= 5 and well separated
/// nodes).
fn monomial_coefficients(x: &[f64], y: &[f64]) -> Vec<f64> {
    let n = x.len();
    let mut m: Vec<Vec<f64>> = (0..n)
        .map(|i| {
            let mut row: Vec<f64> = (0..n).map(|j| x[i].powi(j as i32)).collect();
            row.push(y[i]);
            row
        })
        .collect();
    for col in 0..n {
        let pivot = (col..n)
            .max_by(|&a, &b| m[a][col].abs().total_cmp(&m[b][col].abs()))
            .expect("rows remain");
        m.swap(col, pivot);
        let pivot_row = m[col].clone();
        for row in m.iter_mut().skip(col + 1) {
            let factor = row[col] / pivot_row[col];
            for (v, p) in row.iter_mut().zip(&pivot_row).skip(col) {
                *v -= factor * p;
            }
        }
    }
    let mut c = vec![0.0; n];
    for row in (0..n).rev() {
        let s: f64 = (row + 1..n).map(|k| m[row][k] * c[k]).sum();
        c[row] = (m[row][n] - s) / m[row][row];
    }
    c
}

impl<'o, 'r> Projection<'o, 'r> {
    /// The projection of `objective`, or `None` when its space or loss does not allow one
    /// (conductor Fresnel, or a loss that is not a weighted squared error).
    pub fn new(objective: &'o Objective<'r>) -> Option<Self> {
        let space = objective.space;
        if space.fresnel != FresnelFamily::Schlick || space.known_fresnel.is_some() {
            return None;
        }
        let weights = objective.image_loss().quadratic_weights()?;
        let degree = fresnel_degree(space.model);
        let nodes: Vec<f64> = (0..=degree)
            .map(|j| {
                let chebyshev =
                    0.5 * (1.0 - (std::f64::consts::PI * j as f64 / degree as f64).cos());
                sigmoid(logit(chebyshev))
            })
            .collect();
        let diffuse = space
            .diffuse
            .then(|| lambertian_pixels(objective.records(), objective.pixels()));
        Some(Projection {
            objective,
            lagrange: (0..nodes.len())
                .map(|i| {
                    let unit: Vec<f64> = (0..nodes.len()).map(|j| f64::from(i == j)).collect();
                    let mut column = [0.0; MAX_TERMS];
                    column[..nodes.len()].copy_from_slice(&monomial_coefficients(&nodes, &unit));
                    column
                })
                .collect(),
            nodes,
            weights,
            diffuse,
            roughness_dim: if space.anisotropic { 2 } else { 1 },
            renders: AtomicUsize::new(0),
        })
    }

    /// Whether the projected loss is exact rather than a polynomial approximation (see the
    /// module table): a prediction polynomial in F0 of degree at most 2, `kulla-conty`'s
    /// `A + B F0 + W s(F0)` ([`NodeRenders::Compensated`]) or `tabulated`'s order groups
    /// ([`NodeRenders::Ordered`]; not with a fitted exposure, whose renders go through the
    /// polynomial). Where the plan drops the lobe as faint the prediction is the single
    /// bounce's, affine in F0, which the polynomial reproduces.
    pub fn is_exact(&self) -> bool {
        let model = self.objective.space.model;
        fresnel_degree(model) <= 2
            || model == Model::KullaConty
            || (model == Model::Tabulated && !self.objective.space.exposure)
    }

    /// Renders made so far: the cost of the projected search in objective evaluations.
    pub fn renders(&self) -> usize {
        self.renders.load(Ordering::Relaxed)
    }

    /// Full coordinates from roughness coordinates, grey F0 and per-channel diffuse.
    fn coordinates(&self, roughness: &[f64], f0: [f64; 3], rho: [f64; 3]) -> Vec<f64> {
        let mut x = roughness.to_vec();
        x.extend(f0.map(logit));
        if self.diffuse.is_some() {
            x.extend(rho.map(logit));
        }
        x
    }

    /// The objective's renders at every F0 node ([`NodeRenders`]). Where the plan interpolates
    /// the multiple-bounce term, the shared part is rendered once as an affine function of F0,
    /// each node's anchors are evaluated, and the anchors' values are turned into monomial
    /// coefficients before one interpolation per pixel. Interpolating every node's render,
    /// as this did before, and adding the affine part to each, took a third of a `tabulated`
    /// fit's projected start, for the same coefficients.
    fn node_renders(&self, roughness: &[f64]) -> NodeRenders<'_> {
        let at = |f: f64| self.coordinates(roughness, [f; 3], [0.0; 3]);
        let whole = || NodeRenders::Whole {
            renders: self
                .nodes
                .iter()
                .map(|&f| self.objective.renders(&at(f)))
                .collect(),
            lagrange: &self.lagrange,
        };
        if let Some(compensated) = self.compensated(roughness) {
            return compensated;
        }
        if let Some(parts) = self.objective.order_parts(&at(self.nodes[0])) {
            return NodeRenders::Ordered(parts);
        }
        let Some(mut nodes) = self
            .nodes
            .iter()
            .enumerate()
            .map(|(j, &f)| self.objective.anchored_values(&at(f), j == 0))
            .collect::<Option<Vec<_>>>()
        else {
            return whole();
        };
        let shared = nodes[0].shared.take().expect("asked for");
        // Monomial coefficients of per-node values, laid out for `interpolate`.
        let coefficients = |values: &dyn Fn(usize) -> [f64; 3]| {
            let m = monomials(&self.lagrange, values);
            std::array::from_fn(|i| m[i % 3][i / 3])
        };
        let (anchors, lambert) = (nodes[0].anchors, nodes[0].lambert);
        let streams = nodes[0].streams.len();
        let multi = (0..streams)
            .map(|s| {
                (0..anchors.points.len())
                    .map(|a| coefficients(&|node| nodes[node].streams[s].multi[a].0))
                    .collect()
            })
            .collect();
        let exact = (0..streams)
            .map(|s| {
                let pixels = nodes[0].streams[s].exact.iter().enumerate();
                pixels
                    .map(|(i, &(k, _))| {
                        (k, coefficients(&|node| nodes[node].streams[s].exact[i].1))
                    })
                    .collect()
            })
            .collect();
        NodeRenders::Anchored {
            shared,
            anchors,
            lambert,
            multi,
            exact,
            nodes: self.nodes.len(),
        }
    }

    /// [`NodeRenders::Compensated`] at `roughness`, or `None` where the objective gives no
    /// [`Objective::compensation_parts`]. The image is taken at the last node, where the lobe
    /// is brightest: `W = (whole - A - B F0) / s(F0)`. Three batch value passes (the single
    /// bounce at F0 = 0 and 1, [`crate::render::batch::BatchRecords::render_affine_in_f0`],
    /// and the whole lobe) instead of five whole renders, one per node (docs/speed.md).
    fn compensated(&self, roughness: &[f64]) -> Option<NodeRenders<'_>> {
        let at = |f: f64| self.coordinates(roughness, [f; 3], [0.0; 3]);
        let last = self.nodes[self.nodes.len() - 1];
        let parts = self.objective.compensation_parts(&at(last))?;
        let roughness = roughness.to_vec();
        let colour = move |f: f64| {
            let x = self.coordinates(&roughness, [f; 3], [0.0; 3]);
            let material = self.objective.space.material(&x);
            KullaConty::new(material.single::<f64>()).lobe_scale().0
        };
        let s_last = colour(last);
        let image = parts
            .single
            .iter()
            .zip(&parts.whole)
            .map(|(single, whole)| {
                [0, 1, 2].map(|c| {
                    let [a, b] = single[c];
                    if s_last[c] > 0.0 {
                        (whole[c] - (a + b * last)) / s_last[c]
                    } else {
                        0.0
                    }
                })
            })
            .collect();
        Some(NodeRenders::Compensated {
            single: parts.single,
            image,
            colour: Box::new(colour),
        })
    }

    /// The moments of the three channels over the loss pixels `pixels` (see [`Moments`]), in
    /// one pass over the renders. Per channel the sums run over the pixels in order, and
    /// `aa`'s products are symmetric in `(j, l)` bit for bit, so its lower triangle is the
    /// upper one's mirror. A single stream (deterministic models) is its own pair: its
    /// coefficients are computed once, and `(a1 a2 + a2 a1) / 2` is `a1 a1` exactly.
    fn moments(
        &self,
        pixels: std::ops::Range<usize>,
        renders: &NodeRenders,
        target: &[[f64; 3]],
    ) -> [Moments; 3] {
        /// One channel's sums in fixed-size arrays (the first `k` entries used).
        #[derive(Default)]
        struct Sums {
            aa: [[f64; MAX_TERMS]; MAX_TERMS],
            at: [f64; MAX_TERMS],
            ad: [f64; MAX_TERMS],
            tt: f64,
            dd: f64,
            dt: f64,
        }
        let k = renders.terms();
        let streams = renders.streams();
        let mut sums: [Sums; 3] = Default::default();
        for p in pixels {
            // Coefficients of the stream's prediction in the basis, per channel.
            let a1 = renders.coefficients(0, p);
            let a2 = (streams > 1).then(|| renders.coefficients(streams - 1, p));
            for (c, m) in sums.iter_mut().enumerate() {
                let v = self.weights[p][c];
                if v == 0.0 {
                    continue;
                }
                let (t, d) = (target[p][c], self.diffuse.as_ref().map_or(0.0, |d| d[p][c]));
                let a1 = &a1[c];
                match &a2 {
                    Some(a2) => {
                        let a2 = &a2[c];
                        for j in 0..k {
                            let a = 0.5 * (a1[j] + a2[j]);
                            m.at[j] += v * a * t;
                            m.ad[j] += v * a * d;
                            for l in j..k {
                                m.aa[j][l] += v * 0.5 * (a1[j] * a2[l] + a2[j] * a1[l]);
                            }
                        }
                    }
                    None => {
                        for j in 0..k {
                            m.at[j] += v * a1[j] * t;
                            m.ad[j] += v * a1[j] * d;
                            for l in j..k {
                                m.aa[j][l] += v * (a1[j] * a1[l]);
                            }
                        }
                    }
                }
                m.tt += v * t * t;
                m.dd += v * d * d;
                m.dt += v * d * t;
            }
        }
        sums.map(|m| Moments {
            aa: (0..k)
                .map(|j| (0..k).map(|l| m.aa[j.min(l)][j.max(l)]).collect())
                .collect(),
            at: m.at[..k].to_vec(),
            ad: m.ad[..k].to_vec(),
            tt: m.tt,
            dd: m.dd,
            dt: m.dt,
        })
    }

    /// The loss minimised over F0 and diffuse at roughness coordinates `roughness`, and the
    /// full coordinates of that minimum.
    pub fn solve(&self, roughness: &[f64]) -> (f64, Vec<f64>) {
        self.renders.fetch_add(self.nodes.len(), Ordering::Relaxed);
        let renders = self.node_renders(roughness);
        let target = self.objective.targets();
        // Pixel chunks in parallel, their moments added in chunk order: the same sums for any
        // thread count.
        let moments = (0..self.weights.len())
            .step_by(MOMENT_CHUNK)
            .collect::<Vec<_>>()
            .par_iter()
            .map(|&start| {
                let end = (start + MOMENT_CHUNK).min(self.weights.len());
                self.moments(start..end, &renders, target)
            })
            .collect::<Vec<_>>()
            .into_iter()
            .reduce(|a, b| {
                let [a0, a1, a2] = a;
                let [b0, b1, b2] = b;
                [a0.add(b0), a1.add(b1), a2.add(b2)]
            })
            .expect("at least one pixel");
        let (mut f0, mut rho, mut loss) = ([0.0; 3], [0.0; 3], 0.0);
        for (c, m) in moments.iter().enumerate() {
            let (f, r, e) = m.minimise(|f| renders.basis(c, f));
            (f0[c], rho[c], loss) = (f, r, loss + e);
        }
        (loss, self.coordinates(roughness, f0, rho))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::point::objective::tests::pinhole_records;
    use crate::fit::point::params::ParamSpace;
    use crate::loss::LossKind;
    use crate::render::batch::Precision;
    use crate::render::plan::Skips;

    /// The split forms predict the whole renders, to rounding (1e-11 of the largest pixel),
    /// at the F0 nodes and between them: `tabulated` as single bounce plus its order groups' quadratics times their inner
    /// factors (interpolated from the anchors), `kulla-conty` as single bounce plus an image
    /// times a colour; both bases are exact. A wrong slope, node order, channel layout, colour
    /// or inner factor moves them by far more (a 0.1% error in the slope fails), and so would
    /// a polynomial basis that only interpolated between the nodes.
    /// `tabulated` also without anchors (`Skips::none`), where every pixel's order parts are
    /// summed over its sub-samples.
    #[test]
    fn split_node_renders_predict_the_whole_renders() {
        for (model, skips) in [
            (Model::Tabulated, Skips::all()),
            (Model::Tabulated, Skips::none()),
            (Model::KullaConty, Skips::all()),
        ] {
            check_split_node_renders(model, skips);
        }
    }

    fn check_split_node_renders(model: Model, skips: Skips) {
        let space = ParamSpace {
            diffuse: true,
            ..ParamSpace::plain(model)
        };
        let truth = space.material(&[0.6f64.ln(), 1.8, 0.3, 0.0, -3.0, -2.0, -1.0]);
        let records = pinhole_records(&truth);
        let objective = Objective::new(space, &records, LossKind::L2, 3)
            .with_precision(Precision::F64)
            .with_skips(skips);
        let projection = Projection::new(&objective).expect("Schlick and L2 project");
        for alpha in [0.25f64, 0.6, 1.2] {
            let roughness = [alpha.ln()];
            let split = projection.node_renders(&roughness);
            match model {
                Model::Tabulated => assert!(matches!(split, NodeRenders::Ordered(_))),
                _ => assert!(matches!(split, NodeRenders::Compensated { .. })),
            }
            let mut f0s = projection.nodes.clone();
            f0s.extend([0.137, 0.55, 0.91]);
            let at = |f: f64| projection.coordinates(&roughness, [f; 3], [0.0; 3]);
            for f in f0s {
                let whole = objective.renders(&at(f)).swap_remove(0);
                let largest = whole.iter().flatten().fold(0.0, |m: f64, v| m.max(v.abs()));
                assert!(largest > 0.0);
                // The albedo of `rho = 0` is the logit's floor, 1e-12: its Lambertian term is
                // in the whole render.
                let floor = objective.space.material(&at(f)).diffuse;
                let lambert = projection
                    .diffuse
                    .as_ref()
                    .expect("the space fits a diffuse");
                for (p, whole) in whole.iter().enumerate() {
                    let a = split.coefficients(0, p);
                    for c in 0..3 {
                        let phi = split.basis(c, f);
                        let predicted: f64 =
                            a[c].iter().zip(phi).map(|(a, phi)| a * phi).sum::<f64>()
                                + floor[c] * lambert[p][c];
                        assert!(
                            (predicted - whole[c]).abs() <= 1e-11 * largest,
                            "{model} (skips {skips:?}) alpha {alpha} F0 {f} pixel {p} channel {c}: {predicted} vs {}",
                            whole[c]
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn monomial_coefficients_reproduce_a_polynomial() {
        let x = [0.0, 0.25, 0.5, 0.75, 1.0];
        let c = [0.3, -1.2, 2.0, 0.5, -0.7];
        let y: Vec<f64> = x
            .iter()
            .map(|&x: &f64| (0..5).map(|j| c[j] * x.powi(j as i32)).sum())
            .collect();
        for (got, want) in monomial_coefficients(&x, &y).iter().zip(c) {
            assert!((got - want).abs() < 1e-10, "{got} vs {want}");
        }
    }

    #[test]
    fn moments_find_the_constrained_minimum() {
        // Pixels with prediction A0 + A1 f and diffuse basis d; targets made with f = 0.7,
        // rho = 0.2 are recovered exactly; targets needing f > 1 clamp to f = 1.
        let pixels: Vec<([f64; 2], f64)> = (0..20)
            .map(|i| {
                (
                    [0.1 + 0.01 * i as f64, 0.5 + 0.03 * i as f64],
                    0.2 + 0.02 * (i % 7) as f64,
                )
            })
            .collect();
        let moments = |f: f64, rho: f64| {
            let mut m = Moments {
                aa: vec![vec![0.0; 2]; 2],
                at: vec![0.0; 2],
                ad: vec![0.0; 2],
                tt: 0.0,
                dd: 0.0,
                dt: 0.0,
            };
            for (a, d) in &pixels {
                let t = a[0] + a[1] * f + rho * d;
                for j in 0..2 {
                    m.at[j] += a[j] * t;
                    m.ad[j] += a[j] * d;
                    for k in 0..2 {
                        m.aa[j][k] += a[j] * a[k];
                    }
                }
                m.tt += t * t;
                m.dd += d * d;
                m.dt += d * t;
            }
            m
        };
        // Moment sums cancel to ~1e-14 of their size, which limits F0 to ~sqrt(1e-14) = 1e-7
        // (the joint search that follows in a fit refines further).
        let basis = |f: f64| {
            let mut phi = [0.0; MAX_TERMS];
            phi[..2].copy_from_slice(&[1.0, f]);
            phi
        };
        let (f, rho, e) = moments(0.7, 0.2).minimise(basis);
        assert!(
            (f - 0.7).abs() < 1e-6 && (rho - 0.2).abs() < 1e-6 && e.abs() < 1e-12,
            "{f} {rho} {e}"
        );
        let (f, _, e) = moments(1.4, 0.0).minimise(basis);
        assert!(f == 1.0 && e > 0.0, "{f} {e}");
    }
}

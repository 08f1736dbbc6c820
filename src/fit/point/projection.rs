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

use super::objective::{interpolate, Objective, OrderParts, ORDER_PARTS};
use super::params::{logit, sigmoid, FresnelFamily};
use crate::bsdf::kulla_conty::KullaConty;
use crate::bsdf::registry::F0Dependence;
use crate::bsdf::tabulated::SchlickOrders;
use crate::bsdf::Model;
use crate::render::anchors::Anchors;
use crate::render::lambertian_pixels;
use rayon::prelude::*;
use std::f64::consts::PI;
use std::sync::atomic::{AtomicUsize, Ordering};

/// Degree in F0 of the prediction's polynomial model (see the module docs): the model's own
/// where its prediction is a polynomial ([`F0Dependence::Polynomial`]), 4 for the others (the
/// bases of `kulla-conty` and `tabulated` replace it where the objective gives their parts).
pub fn fresnel_degree(model: Model) -> usize {
    match model.capabilities().f0 {
        F0Dependence::Polynomial(degree) => degree,
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
    /// The render plan interpolates the multiple-bounce term from anchors (or evaluates it at
    /// every sub-sample, `tabulated` without anchors): the part every stream shares (exact
    /// single bounce, affine in a Schlick F0) as its two coefficients per pixel, the
    /// multiple-bounce term as coefficients per anchor (the interpolation is linear, so it
    /// carries them to the pixels, [`interpolate`]) and, at the pixels without anchors, the
    /// whole prediction's coefficients per pixel (their `shared` is zero). The moments are
    /// taken over the anchors' cells ([`AnchorCells`]).
    Anchored {
        shared: Vec<[[f64; 2]; 3]>,
        anchors: Option<&'o Anchors>,
        lambert: &'o [[f64; 3]],
        /// `[stream][anchor]`, coefficient `j` of channel `c` at `3 j + c`.
        multi: Vec<Vec<[f64; 3 * MAX_TERMS]>>,
        /// `[stream]`: the pixels without anchors in increasing order, with their
        /// coefficients laid out as `multi`.
        exact: Vec<Vec<(usize, [f64; 3 * MAX_TERMS])>>,
        basis: AnchoredBasis,
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
}

/// The basis of F0 of [`NodeRenders::Anchored`].
enum AnchoredBasis {
    /// Monomials `1, F0, ..., F0^(n - 1)` through `n` F0 nodes (the polynomial's degree plus
    /// one).
    Monomials(usize),
    /// `tabulated` with a Schlick F0 ([`Objective::order_parts`]): the multiple-bounce lobe of
    /// each order group is a quadratic in F0 times an inner factor that does not depend on the
    /// pixel: 1, `F_mid,3 = m + (1 - m) F0` (affine, so it folds into the powers up to `F0^3`)
    /// and the tail factor `h(F0)` of the orders >= 4. Exact in the basis `1, F0, F0^2, F0^3,
    /// h, F0 h, F0^2 h`.
    Orders(SchlickOrders),
}

impl NodeRenders<'_> {
    /// Number of streams.
    fn streams(&self) -> usize {
        match self {
            NodeRenders::Whole { renders, .. } => renders[0].len(),
            NodeRenders::Anchored { multi, .. } => multi.len(),
            NodeRenders::Compensated { .. } => 1,
        }
    }

    /// Number of basis functions of F0 ([`NodeRenders::basis`]).
    fn terms(&self) -> usize {
        match self {
            NodeRenders::Whole { lagrange, .. } => lagrange.len(),
            NodeRenders::Anchored {
                basis: AnchoredBasis::Monomials(n),
                ..
            } => *n,
            NodeRenders::Anchored {
                basis: AnchoredBasis::Orders(_),
                ..
            } => 7,
            NodeRenders::Compensated { .. } => 3,
        }
    }

    /// The basis functions of F0 at `f` for `channel`: monomials `1, f, ..., f^(terms - 1)`,
    /// `1, f, s(f)` for [`NodeRenders::Compensated`], or those of [`AnchoredBasis::Orders`].
    fn basis(&self, channel: usize, f: f64) -> [f64; MAX_TERMS] {
        let mut phi = [0.0; MAX_TERMS];
        match self {
            NodeRenders::Compensated { colour, .. } => {
                phi[..3].copy_from_slice(&[1.0, f, colour(f)[channel]]);
            }
            NodeRenders::Anchored {
                basis: AnchoredBasis::Orders(orders),
                ..
            } => {
                let h = orders.tail_factor(f);
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
                let own = match anchors.and_then(|anchors| anchors.corners[p].as_ref()) {
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
    /// The anchors' cells of the moment sums, once an anchored solve has asked for them.
    cells: std::sync::OnceLock<AnchorCells>,
}

/// Cells of anchors per parallel task of the moment sums.
const CELL_CHUNK: usize = 32;

/// One channel's moment sums in fixed-size arrays (the first `k` entries used; `aa` in its
/// upper triangle), added up before they become [`Moments`].
#[derive(Default)]
struct Sums {
    aa: [[f64; MAX_TERMS]; MAX_TERMS],
    at: [f64; MAX_TERMS],
    ad: [f64; MAX_TERMS],
    tt: f64,
    dd: f64,
    dt: f64,
}

impl Sums {
    /// The sums of two disjoint pixel sets together.
    fn add(&mut self, other: Sums) {
        for (row, other) in self.aa.iter_mut().zip(&other.aa) {
            row.iter_mut().zip(other).for_each(|(a, b)| *a += b);
        }
        self.at.iter_mut().zip(&other.at).for_each(|(a, b)| *a += b);
        self.ad.iter_mut().zip(&other.ad).for_each(|(a, b)| *a += b);
        self.tt += other.tt;
        self.dd += other.dd;
        self.dt += other.dt;
    }

    /// The moments of the first `k` basis functions, `aa` mirrored from its upper triangle.
    fn moments(self, k: usize) -> Moments {
        Moments {
            aa: (0..k)
                .map(|j| (0..k).map(|l| self.aa[j.min(l)][j.max(l)]).collect())
                .collect(),
            at: self.at[..k].to_vec(),
            ad: self.ad[..k].to_vec(),
            tt: self.tt,
            dd: self.dd,
            dt: self.dt,
        }
    }
}

/// The loss pixels with anchors grouped by the four anchors they interpolate (a cell of an
/// anchor grid), with each cell's `M_ii' = sum v L^2 w_i w_i'` per channel over its pixels
/// (`v` the loss weight, `L = pi lambert`, `w` the bilinear weights): what
/// [`Projection::cell_sums`] needs that no solve changes. The plan's anchors are fixed for
/// an objective, so one is built per projection, at its first anchored solve.
struct AnchorCells {
    cells: Vec<Cell>,
    /// The loss pixels of every cell, cell after cell, each cell's in increasing order.
    pixels: Vec<u32>,
    /// The loss pixels without anchors, in increasing order.
    exact: Vec<usize>,
}

/// One cell of [`AnchorCells`].
struct Cell {
    /// Its anchors, in the order its pixels' corners list them.
    anchors: [u32; 4],
    /// Its pixels' range in [`AnchorCells::pixels`].
    pixels: std::ops::Range<usize>,
    /// `M` per channel.
    gram: [[[f64; 4]; 4]; 3],
}

impl AnchorCells {
    fn new(anchors: &Anchors, lambert: &[[f64; 3]], weights: &[[f64; 3]]) -> AnchorCells {
        let mut index: std::collections::HashMap<[u32; 4], usize> = Default::default();
        let mut members: Vec<Vec<u32>> = Vec::new();
        let mut exact = Vec::new();
        for (p, corners) in anchors.corners.iter().enumerate() {
            let Some(corners) = corners else {
                exact.push(p);
                continue;
            };
            let key = corners.map(|(a, _)| a);
            let cell = *index.entry(key).or_insert_with(|| {
                members.push(Vec::new());
                members.len() - 1
            });
            members[cell].push(p as u32);
        }
        let mut keys = vec![[0; 4]; members.len()];
        for (key, &cell) in &index {
            keys[cell] = *key;
        }
        let mut pixels = Vec::with_capacity(anchors.corners.len() - exact.len());
        let cells = members
            .iter()
            .zip(keys)
            .map(|(members, key)| {
                let start = pixels.len();
                pixels.extend_from_slice(members);
                let mut gram = [[[0.0; 4]; 4]; 3];
                for &p in members {
                    let p = p as usize;
                    let corners = anchors.corners[p].expect("grouped with anchors");
                    for (c, gram) in gram.iter_mut().enumerate() {
                        let l = PI * lambert[p][c];
                        let vl2 = weights[p][c] * l * l;
                        for (i, &(_, wi)) in corners.iter().enumerate() {
                            for (i2, &(_, wi2)) in corners.iter().enumerate() {
                                gram[i][i2] += vl2 * wi * wi2;
                            }
                        }
                    }
                }
                Cell {
                    anchors: key,
                    pixels: start..pixels.len(),
                    gram,
                }
            })
            .collect();
        AnchorCells {
            cells,
            pixels,
            exact,
        }
    }
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

/// [`NodeRenders::Anchored`] of `tabulated`'s order parts: each anchor's and each exact
/// pixel's nine parts per channel turned into coefficients of [`AnchoredBasis::Orders`] (the
/// exact pixels' with their single bounce, as the other bases lay them out).
fn ordered(parts: OrderParts<'_>) -> NodeRenders<'_> {
    let m = parts.orders.middle_moment();
    // Part `k` of group `g` of channel `c` is at `3 (3 g + k) + c`.
    let to_basis = |raw: &[f64; 3 * ORDER_PARTS]| -> [f64; 3 * MAX_TERMS] {
        let mut out = [0.0; 3 * MAX_TERMS];
        for c in 0..3 {
            let q = |g: usize, k: usize| raw[3 * (3 * g + k) + c];
            let a = [
                q(0, 0) + m * q(1, 0),
                q(0, 1) + (1.0 - m) * q(1, 0) + m * q(1, 1),
                q(0, 2) + (1.0 - m) * q(1, 1) + m * q(1, 2),
                (1.0 - m) * q(1, 2),
                q(2, 0),
                q(2, 1),
                q(2, 2),
            ];
            for (j, a) in a.into_iter().enumerate() {
                out[3 * j + c] = a;
            }
        }
        out
    };
    let mut shared = parts.single;
    let mut exact = Vec::with_capacity(parts.exact.len());
    for (k, raw) in &parts.exact {
        let mut a = to_basis(raw);
        for (c, [intercept, slope]) in shared[*k].into_iter().enumerate() {
            a[c] += intercept;
            a[3 + c] += slope;
        }
        shared[*k] = [[0.0; 2]; 3];
        exact.push((*k, a));
    }
    NodeRenders::Anchored {
        shared,
        anchors: parts.anchors,
        lambert: parts.lambert,
        multi: vec![parts.multi.iter().map(to_basis).collect()],
        exact: vec![exact],
        basis: AnchoredBasis::Orders(parts.orders),
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
            cells: std::sync::OnceLock::new(),
        })
    }

    /// Whether the projected loss is exact rather than a polynomial approximation (see the
    /// module table): a prediction polynomial in F0 of degree at most 2, `kulla-conty`'s
    /// `A + B F0 + W s(F0)` ([`NodeRenders::Compensated`]) or `tabulated`'s order groups
    /// ([`AnchoredBasis::Orders`]; not with a fitted exposure, whose renders go through the
    /// polynomial). Where the plan drops the lobe as faint the prediction is the single
    /// bounce's, affine in F0, which the polynomial reproduces.
    pub fn is_exact(&self) -> bool {
        match self.objective.space.model.capabilities().f0 {
            F0Dependence::Polynomial(_) | F0Dependence::Compensated => true,
            F0Dependence::Orders => !self.objective.space.exposure,
            F0Dependence::PerBounce => false,
        }
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
            return ordered(parts);
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
            anchors: Some(anchors),
            lambert,
            multi,
            exact,
            basis: AnchoredBasis::Monomials(self.nodes.len()),
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

    /// The sums of the three channels over the loss pixels `pixels` (see [`Moments`]), one
    /// pixel at a time from its coefficients ([`NodeRenders::coefficients`]). Per channel the
    /// sums run over the pixels in order, and `aa`'s products are symmetric in `(j, l)` bit for
    /// bit, so its upper triangle stands for it. A single stream (deterministic models) is its
    /// own pair: its coefficients are computed once, and `(a1 a2 + a2 a1) / 2` is `a1 a1`
    /// exactly.
    fn pixel_sums(
        &self,
        pixels: impl Iterator<Item = usize>,
        renders: &NodeRenders,
        target: &[[f64; 3]],
    ) -> [Sums; 3] {
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
        sums
    }

    /// The sums of the three channels over the pixels of `cells`, in anchor space. A pixel
    /// with anchors predicts `a = s + L u` in each channel: `s` its shared part (`A`, `B` on
    /// the first two basis functions), `L = pi lambert` and `u = sum_i w_i Q_i` its anchors'
    /// coefficients `Q_i` under its bilinear weights `w_i`. So over a cell
    /// `sum v a a^T = sum v s s^T + sum_i (h_i Q_i^T + Q_i h_i^T) + sum_ii' M_ii' Q_i Q_i'^T`,
    /// with `h_i = sum v L w_i s` and `M_ii' = sum v L^2 w_i w_i'` ([`AnchorCells`], fixed for
    /// the fit), and `sum v a t = sum v s t + sum_i (sum v L w_i t) Q_i`. The pixel loop then
    /// touches the shared part only, and the coefficients enter once per cell, not once per
    /// pixel. Two streams enter as the pixel sums take them: `(a1 a2^T + a2 a1^T) / 2` and
    /// `(a1 + a2) / 2`.
    fn cell_sums(
        &self,
        cells: &[Cell],
        grouped: &[u32],
        renders: &NodeRenders,
        target: &[[f64; 3]],
    ) -> [Sums; 3] {
        let NodeRenders::Anchored {
            shared,
            anchors: Some(anchors),
            lambert,
            multi,
            ..
        } = renders
        else {
            unreachable!("cells are taken over anchored renders");
        };
        let k = renders.terms();
        let (first, last) = (&multi[0], &multi[multi.len() - 1]);
        let mut sums: [Sums; 3] = Default::default();
        for cell in cells {
            for (c, m) in sums.iter_mut().enumerate() {
                // Per corner: `h` for the intercept and the slope, `sum v L w t`, `sum v L w d`.
                let (mut h, mut r, mut e) = ([[0.0; 2]; 4], [0.0; 4], [0.0; 4]);
                for &p in &grouped[cell.pixels.clone()] {
                    let p = p as usize;
                    let v = self.weights[p][c];
                    if v == 0.0 {
                        continue;
                    }
                    let (t, d) = (target[p][c], self.diffuse.as_ref().map_or(0.0, |d| d[p][c]));
                    let [a, b] = shared[p][c];
                    m.aa[0][0] += v * a * a;
                    m.aa[0][1] += v * a * b;
                    m.aa[1][1] += v * b * b;
                    m.at[0] += v * a * t;
                    m.at[1] += v * b * t;
                    m.ad[0] += v * a * d;
                    m.ad[1] += v * b * d;
                    m.tt += v * t * t;
                    m.dd += v * d * d;
                    m.dt += v * d * t;
                    let corners = anchors.corners[p]
                        .as_ref()
                        .expect("a cell's pixel has anchors");
                    let vl = v * PI * lambert[p][c];
                    for (i, &(_, w)) in corners.iter().enumerate() {
                        let x = vl * w;
                        h[i][0] += x * a;
                        h[i][1] += x * b;
                        r[i] += x * t;
                        e[i] += x * d;
                    }
                }
                let q = |stream: &[[f64; 3 * MAX_TERMS]], i: usize| -> [f64; MAX_TERMS] {
                    let anchor = &stream[cell.anchors[i] as usize];
                    std::array::from_fn(|j| anchor[3 * j + c])
                };
                let q1: [[f64; MAX_TERMS]; 4] = std::array::from_fn(|i| q(first, i));
                let q2: [[f64; MAX_TERMS]; 4] = std::array::from_fn(|i| q(last, i));
                let gram = &cell.gram[c];
                for i in 0..4 {
                    let mean: [f64; MAX_TERMS] =
                        std::array::from_fn(|j| 0.5 * (q1[i][j] + q2[i][j]));
                    for j in 0..k {
                        m.at[j] += r[i] * mean[j];
                        m.ad[j] += e[i] * mean[j];
                        // The cross terms `h Q^T + Q h^T`, upper triangle.
                        for (row, hs) in h[i].iter().enumerate() {
                            if j >= row {
                                m.aa[row][j] += hs * mean[j];
                            }
                            if j <= row {
                                m.aa[j][row] += hs * mean[j];
                            }
                        }
                    }
                }
                // `sum_ii' M_ii' (Q1_i Q2_i'^T + Q2_i Q1_i'^T) / 2`, through `P = M Q`.
                let times_gram = |q: &[[f64; MAX_TERMS]; 4]| -> [[f64; MAX_TERMS]; 4] {
                    std::array::from_fn(|i| {
                        std::array::from_fn(|l| (0..4).map(|i2| gram[i][i2] * q[i2][l]).sum())
                    })
                };
                let (p1, p2) = (times_gram(&q1), times_gram(&q2));
                for i in 0..4 {
                    for j in 0..k {
                        for l in j..k {
                            m.aa[j][l] += 0.5 * (q1[i][j] * p2[i][l] + q2[i][j] * p1[i][l]);
                        }
                    }
                }
            }
        }
        sums
    }

    /// The loss minimised over F0 and diffuse at roughness coordinates `roughness`, and the
    /// full coordinates of that minimum.
    pub fn solve(&self, roughness: &[f64]) -> (f64, Vec<f64>) {
        self.renders.fetch_add(self.nodes.len(), Ordering::Relaxed);
        let renders = self.node_renders(roughness);
        let target = self.objective.targets();
        // Chunks of cells and of pixels in parallel, their sums added in chunk order: the same
        // sums for any thread count.
        let sums = match &renders {
            NodeRenders::Anchored {
                anchors: Some(anchors),
                lambert,
                ..
            } => {
                let cells = self
                    .cells
                    .get_or_init(|| AnchorCells::new(anchors, lambert, &self.weights));
                let by_cells = cells
                    .cells
                    .par_chunks(CELL_CHUNK)
                    .map(|chunk| self.cell_sums(chunk, &cells.pixels, &renders, target));
                let exact = cells
                    .exact
                    .par_chunks(MOMENT_CHUNK)
                    .map(|chunk| self.pixel_sums(chunk.iter().copied(), &renders, target));
                by_cells.chain(exact).collect::<Vec<_>>()
            }
            _ => (0..self.weights.len())
                .step_by(MOMENT_CHUNK)
                .collect::<Vec<_>>()
                .par_iter()
                .map(|&start| {
                    let end = (start + MOMENT_CHUNK).min(self.weights.len());
                    self.pixel_sums(start..end, &renders, target)
                })
                .collect(),
        };
        let k = renders.terms();
        let moments = sums
            .into_iter()
            .reduce(|mut a, b| {
                for (a, b) in a.iter_mut().zip(b) {
                    a.add(b);
                }
                a
            })
            .expect("at least one chunk")
            .map(|sums| sums.moments(k));
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
                Model::Tabulated => assert!(matches!(
                    split,
                    NodeRenders::Anchored {
                        basis: AnchoredBasis::Orders(_),
                        ..
                    }
                )),
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

    /// The moment sums over the anchors' cells equal those taken pixel by pixel, to rounding:
    /// `tabulated` (one stream, its order basis) and `bitterli` (two streams, monomials),
    /// with a diffuse layer. A wrong cross term, a Gram entry off its corner or a stream mixed
    /// up moves them by far more than 1e-10.
    #[test]
    fn cell_sums_equal_the_pixel_sums() {
        for model in [Model::Tabulated, Model::Bitterli] {
            let space = ParamSpace {
                diffuse: true,
                ..ParamSpace::plain(model)
            };
            let truth = space.material(&[0.6f64.ln(), 1.8, 0.3, 0.0, -3.0, -2.0, -1.0]);
            let records = pinhole_records(&truth);
            let objective =
                Objective::new(space, &records, LossKind::L2, 3).with_precision(Precision::F64);
            let projection = Projection::new(&objective).expect("Schlick and L2 project");
            let renders = projection.node_renders(&[0.4f64.ln()]);
            let NodeRenders::Anchored {
                anchors: Some(anchors),
                lambert,
                multi,
                ..
            } = &renders
            else {
                panic!("{model}: anchored renders");
            };
            assert_eq!(multi.len(), if model == Model::Bitterli { 2 } else { 1 });
            let target = objective.targets();
            let cells = AnchorCells::new(anchors, lambert, &projection.weights);
            assert!(cells.cells.len() > 10);
            let mut by_cells = projection.cell_sums(&cells.cells, &cells.pixels, &renders, target);
            let exact = projection.pixel_sums(cells.exact.iter().copied(), &renders, target);
            for (a, b) in by_cells.iter_mut().zip(exact) {
                a.add(b);
            }
            let by_pixels = projection.pixel_sums(0..projection.weights.len(), &renders, target);
            let k = renders.terms();
            for (c, (a, b)) in by_cells.into_iter().zip(by_pixels).enumerate() {
                let (a, b) = (a.moments(k), b.moments(k));
                let close = |x: f64, y: f64, scale: f64| (x - y).abs() <= 1e-10 * scale;
                let scale = b.aa.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
                for j in 0..k {
                    for l in 0..k {
                        assert!(
                            close(a.aa[j][l], b.aa[j][l], scale),
                            "{model} c{c} aa[{j}][{l}]: {} vs {}",
                            a.aa[j][l],
                            b.aa[j][l]
                        );
                    }
                    let scale_t = b.at.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                    assert!(close(a.at[j], b.at[j], scale_t), "{model} c{c} at[{j}]");
                    let scale_d = b.ad.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                    assert!(close(a.ad[j], b.ad[j], scale_d), "{model} c{c} ad[{j}]");
                }
                for (x, y) in [(a.tt, b.tt), (a.dd, b.dd), (a.dt, b.dt)] {
                    assert!(close(x, y, y.abs()), "{model} c{c}: {x} vs {y}");
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

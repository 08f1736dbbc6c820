//! `tabulated`: the multiple-bounce lobe of `heitz` (Heitz, Hanika, d'Eon & Dachsbacher 2016,
//! "Multiple-Scattering Microfacet BSDFs with the Smith Model", ACM TOG 35(4): the explicit
//! random walk on the height-correlated Smith microsurface, its sec. 4-5 as implemented in
//! [`super::heitz`]) tabulated once with white Fresnel, split by order of scattering, and
//! interpolated: a deterministic, analytic model with the reference's lobe.
//!
//! | parameter | unit / range | meaning |
//! | --- | --- | --- |
//! | `alpha` (`ax`, `ay`) | > 0; tabulated on [`ALPHA_MIN`, `ALPHA_MAX`] | microfacet roughness; anisotropic surfaces read the table at `sqrt(ax ay)` (an approximation, as `kulla-conty` makes) |
//! | `ndf` | `ggx`, `beckmann` | one table each |
//! | `fresnel` | white, Schlick, conductor, dielectric | exact in the single bounce; per order in the multiple bounces by the measured distribution of the walks' vertex cosines ([`vertex_fresnel`], below) |
//! | `height` | ignored | as `heitz`: the single bounce is the height-correlated one, the walk's first order |
//!
//! | property | value |
//! | --- | --- |
//! | value | `f = f_single(wi, wo) + sum_k W_k(F, alpha, theta_i, theta_o) T_k(alpha, theta_i, theta_o, phi) f_kc(wi, wo)`, `k` in {2, 3, >= 4}, with `f_kc = (1 - E(mu_i)) (1 - E(mu_o)) / (pi (1 - E_avg))` the white lobe of `kulla-conty` ([`AlbedoTable`]) |
//! | deterministic | yes; generic over the scalar, so the fitter gets exact dual-number derivatives in `alpha` and Fresnel (directions enter as constants, as in `kulla-conty`) |
//! | table | `T_k`, the white-Fresnel `heitz` multiple-bounce BRDF of order 2, 3 and >= 4 divided by `f_kc`, on [`ALPHA_COUNT`] values of `alpha` log-uniform in [[`ALPHA_MIN`], [`ALPHA_MAX`]] x [`THETA_COUNT`]^2 polar angles over [0, [`THETA_MAX_DEG`]] deg, denser toward grazing ([`theta_node`]) x [`PHI_COUNT`] azimuth differences over [0, 180] deg, denser toward 180 ([`phi_node`]); GGX and Beckmann; f32 in `heitz_table.bin` (2.2 MiB). Beside it, for the Fresnel weights, the distributions of the walks' vertex cosines ([`vertex_fresnel`], `vertex_cosines.bin`, 87 kB) |
//! | interpolation | multilinear in (`ln alpha`, `theta_i`, `theta_o`, `phi`), clamped to the grid, times `f_kc` at the true directions and roughness; the derivative in `alpha` is that of this interpolant, exactly. Dividing by `f_kc` takes out the steep growth of the lost energy toward grazing and with roughness; the warped direction grids resolve the narrow forward lobe of smooth surfaces (on uniform 6- and 10-degree grids the white furnace came out 6% high at alpha 0.1 and 80 deg). Below `ALPHA_MIN` the first node's ratio multiplies the true `f_kc`, so the lobe fades with the energy it carries |
//! | reciprocal | exactly: the table is symmetric in (`theta_i`, `theta_o`) by construction (below), and so is its interpolation |
//! | energy | white furnace 1 up to table error (measured in the tests below) |
//! | sampling | [`super::lobe_mixture`] (single-bounce visible normals and cosine) |
//!
//! # How the table is made
//!
//! One walk of `heitz` from `a` serves next-event estimation toward *every* tabulated
//! direction `b` at once (the walk does not depend on `b`, only its connections do;
//! [`Heitz::nee_walk_each`]), and hands each contribution over with its order. For each
//! roughness node and polar node `theta_a` (`a` at azimuth 0), [`WALKS_PER_ROW`] walks with
//! the balance-heuristic weight of `heitz` give `S(theta_a -> theta_b, phi)` for all targets.
//! `heitz`'s value is the forward walk from `wi` plus the backward walk from `wo`; by isotropy
//! and mirror symmetry the backward walk from `wo` toward `wi` is the row of `theta_o` at the
//! target (`theta_i`, `phi`), so `T(theta_i, theta_o, phi) = S(theta_i -> theta_o, phi) +
//! S(theta_o -> theta_i, phi)`: unbiased (the same two strategies as `heitz`) and symmetric.
//! Seeds are fixed ([`crate::random::rng_stream`] with seed [`SEED`], one stream per row).
//! Generation: `cargo test --release --lib regenerate_heitz_table -- --ignored` with
//! `nice -n 10` and `RAYON_NUM_THREADS=1`: 421 s on one core (2^18 walks per row, both
//! distributions). Relative standard error of the stored white multiple-bounce entries: median
//! 0.67% (GGX) and 0.81% (Beckmann); the largest (up to 100%) are at entries whose value is
//! negligible (smooth surfaces far from the forward lobe) or at 89.5 deg, where rare walks
//! leave large contributions.
//!
//! # Fresnel
//!
//! `heitz` multiplies a path of order `k` by `prod_{j=1..k} F(wi_j . h_j)`, the Fresnel factor of
//! each vertex, so the coloured value of order `k` is the white path integral with that
//! product inside. Tabulating it for every Fresnel is impossible (the product depends on each
//! vertex's angle). [`vertex_fresnel`] weighs order `k` by the path-weighted mean `W_k` of the
//! product instead, factored by vertex role (first, inner, last) from the distribution of the
//! cosines at which the walks meet their facets, measured once per roughness, entry angle and
//! order (derivation there). Every weight is 1 for white Fresnel, so the white lobe is
//! `heitz`'s up to table error.
//!
//! Kulla & Conty 2017 ("Revisiting Physically Based Shading at Imageworks", SIGGRAPH course)
//! assume instead that every vertex sees the cosine-weighted hemisphere, `W_k = F_avg^k` with
//! `F_avg = 2 integral_0^1 F(mu) mu dmu`, as `kulla-conty` does. The walks of rough surfaces
//! meet far more grazing facets than that, so `F_avg^k` is too dark for a coloured conductor:
//! it put this model's copper albedo 6.2% below `heitz`'s at alpha 1.5 and biased fits of
//! heitz-rendered copper and gold photos 3.6-9.5% low at alpha 1.2-1.5 (`docs/fidelity.md`).
//!
//! # Measured error (tests in `tabulated/tests.rs`)
//!
//! | check | result |
//! | --- | --- |
//! | against converged `heitz` (2^16 evaluations each) on 128 `bench` configurations (GGX alpha 0.05-1.5, directions to 85 deg), relative error of the total value | white: RMS 0.48% (of which `heitz`'s own noise sigma 0.31%), worst -2.5% (alpha 0.05, `wi` at 82 deg); copper: RMS 0.56% (sigma 0.14%; 0.82% with `F_avg^k`), worst +2.5% (alpha 0.32, `wi` at 80 deg) |
//! | white furnace, alpha 0.1-2.5, incidence 0-80 deg, GGX and Beckmann | within 1.1% of 1 (worst +1.09%, Beckmann alpha 0.1 at 80 deg) |
//! | copper directional albedo against `heitz`'s, alpha 0.3, 0.9, 1.5 at 0, 60, 80 deg | within 0.3% except +1.8% (blue) at alpha 1.5 and normal incidence, the factoring's error (with `F_avg^k`: -1.7% to -6.2%) |
//! | reciprocity | exact (1e-12), value and alpha derivative |

use super::albedo_table::{log_cell, AlbedoTable};
use super::lobe_mixture::AddedLobe;
use super::single::SingleBounce;
use super::ScalarBrdf;

use crate::microfacet::{Height, NdfKind};
use crate::random::Rng;
use crate::scalar::{Real, Rgb, Vec3};
use std::sync::OnceLock;
use vertex_fresnel::OrderFresnel;
pub use vertex_fresnel::SchlickOrders;

mod vertex_fresnel;

pub const ALPHA_COUNT: usize = 20;
pub const ALPHA_MIN: f64 = 0.02;
pub const ALPHA_MAX: f64 = 3.0;
pub const THETA_COUNT: usize = 16;
pub const THETA_MAX_DEG: f64 = 89.5;
pub const PHI_COUNT: usize = 19;
/// Orders 2, 3 and >= 4.
pub const ORDERS: usize = 3;
/// Walks from each `(alpha, theta_a)` node.
pub const WALKS_PER_ROW: usize = 1 << 18;
/// Seed of the table's random streams.
pub const SEED: u64 = 0x7AB1E;

/// Values of one distribution's table.
const TABLE_LEN: usize = ALPHA_COUNT * THETA_COUNT * THETA_COUNT * PHI_COUNT * ORDERS;
const KINDS: [NdfKind; 2] = [NdfKind::Ggx, NdfKind::Beckmann];
static EMBEDDED: &[u8] = include_bytes!("heitz_table.bin");

/// Node `i` of the roughness grid.
pub fn alpha_node(i: usize) -> f64 {
    (ALPHA_MIN.ln() + (ALPHA_MAX / ALPHA_MIN).ln() * i as f64 / (ALPHA_COUNT - 1) as f64).exp()
}

/// Node `j` of `count` nodes over `[0, max]` placed at `max (1 - (1 - x)^1.5)`, `x` uniform:
/// denser toward `max`, where the multiple-bounce lobe of smooth surfaces is narrow (grazing
/// `theta`, forward azimuth `phi = pi`).
fn warped_node(j: usize, count: usize, max: f64) -> f64 {
    let y = 1.0 - j as f64 / (count - 1) as f64;
    max * (1.0 - y * y.sqrt())
}

/// The warped coordinate `x` in [0, 1] of `v` in [0, `max`] (clamped): the nodes of every
/// grid of [`warped_node`] sit at `x = j / (count - 1)`.
fn warped_x(v: f64, max: f64) -> f64 {
    let y = 1.0 - (v / max).clamp(0.0, 1.0);
    1.0 - (y * y).cbrt()
}

/// Lower node and weight of the upper one of `v` (at warped coordinate `x`, [`warped_x`]) on
/// the grid of [`warped_node`], linear in `v` within a cell, clamped to the grid.
fn warped_cell(v: f64, x: f64, count: usize, max: f64) -> (usize, f64) {
    let j = ((x * (count - 1) as f64) as usize).min(count - 2);
    let (lo, hi) = (warped_node(j, count, max), warped_node(j + 1, count, max));
    (j, ((v - lo) / (hi - lo)).clamp(0.0, 1.0))
}

/// Node `j` of the polar grid, radians: steps from 8.7 deg at the normal to 1.4 deg at grazing.
pub fn theta_node(j: usize) -> f64 {
    warped_node(j, THETA_COUNT, THETA_MAX_DEG.to_radians())
}

/// Node `p` of the azimuth-difference grid, radians: steps from 15 deg at 0 (backward) to
/// 0.7 deg at 180 (forward).
pub fn phi_node(p: usize) -> f64 {
    warped_node(p, PHI_COUNT, std::f64::consts::PI)
}

/// Index of `T_k` at nodes (`alpha`, `theta_i`, `theta_o`, `phi`) in one distribution's table;
/// `k` is 0 for order 2, 1 for order 3, 2 for orders >= 4.
fn index(i: usize, ji: usize, jo: usize, p: usize) -> usize {
    (((i * THETA_COUNT + ji) * THETA_COUNT + jo) * PHI_COUNT + p) * ORDERS
}

/// The embedded table of one distribution.
pub struct HeitzTable {
    values: Vec<f32>,
}

impl HeitzTable {
    /// The table of `ndf`, read from the embedded data on first use.
    pub fn get(ndf: NdfKind) -> &'static HeitzTable {
        static TABLES: [OnceLock<HeitzTable>; 2] = [const { OnceLock::new() }; 2];
        let slot = KINDS
            .iter()
            .position(|&k| k == ndf)
            .expect("a table per ndf");
        TABLES[slot].get_or_init(|| HeitzTable {
            values: EMBEDDED[slot * TABLE_LEN * 4..(slot + 1) * TABLE_LEN * 4]
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes(b.try_into().expect("chunks of 4 bytes")))
                .collect(),
        })
    }

    /// `T_k` at roughness node `i`, trilinear in the directions (cells and weights given).
    fn directional(&self, i: usize, cells: [(usize, f64); 3]) -> [f64; ORDERS] {
        let [(ji, ui), (jo, uo), (p, v)] = cells;
        let mut out = [0.0; ORDERS];
        for (di, wi) in [(0, 1.0 - ui), (1, ui)] {
            for (dout, wo) in [(0, 1.0 - uo), (1, uo)] {
                for (dp, wp) in [(0, 1.0 - v), (1, v)] {
                    let weight = wi * wo * wp;
                    let at = index(i, ji + di, jo + dout, p + dp);
                    for (k, o) in out.iter_mut().enumerate() {
                        *o += weight * self.values[at + k] as f64;
                    }
                }
            }
        }
        out
    }
}

/// What the multiple-bounce lobe reads of a direction pair, which does not depend on the
/// material: the table cells of the two polar angles and the azimuth difference, the warped
/// polar coordinates the Fresnel weights are tabulated over, and the albedo table's cells of
/// the two cosines. A caller that evaluates the same directions at many parameters (`fit
/// --maps` over a texel's Levenberg-Marquardt iterations) computes it once per direction pair
/// and calls [`Tabulated::multiple_at`]: that takes the `acos`, `atan2`, `cbrt` and square
/// roots out of every evaluation, with the same value to the last bit.
#[derive(Clone, Copy, Debug)]
pub struct LobeDirections {
    cells: [(usize, f64); 3],
    warped: [f64; 2],
    mu_cells: [(usize, f64); 2],
}

impl LobeDirections {
    /// The pair (`wi`, `wo`), unit vectors in the local frame; `None` where either is at or
    /// below the horizon, where the lobe is 0.
    pub fn new(wi: [f64; 3], wo: [f64; 3]) -> Option<LobeDirections> {
        let ([xi, yi, zi], [xo, yo, zo]) = (wi, wo);
        if zi <= 0.0 || zo <= 0.0 {
            return None;
        }
        let phi = (xi * yo - yi * xo).abs().atan2(xi * xo + yi * yo);
        let theta_max = THETA_MAX_DEG.to_radians();
        let (theta_i, theta_o) = (zi.min(1.0).acos(), zo.min(1.0).acos());
        let warped = [warped_x(theta_i, theta_max), warped_x(theta_o, theta_max)];
        let pi = std::f64::consts::PI;
        Some(LobeDirections {
            cells: [
                warped_cell(theta_i, warped[0], THETA_COUNT, theta_max),
                warped_cell(theta_o, warped[1], THETA_COUNT, theta_max),
                warped_cell(phi, warped_x(phi, pi), PHI_COUNT, pi),
            ],
            warped,
            mu_cells: [AlbedoTable::mu_cell(zi), AlbedoTable::mu_cell(zo)],
        })
    }
}

/// `single` plus the tabulated multiple-bounce lobe of `heitz`.
#[derive(Clone)]
pub struct Tabulated<T> {
    /// The exact single bounce, height-correlated (the first order of `heitz`'s walk).
    pub single: SingleBounce<T>,
    table: &'static HeitzTable,
    albedo: &'static AlbedoTable,
    /// `sqrt(ax ay)` and its cell.
    alpha_cell: (usize, T),
    /// The albedo table's cell of `sqrt(ax ay)`.
    albedo_cell: (usize, T),
    /// `1 / (pi (1 - E_avg))`, the normalisation of `f_kc`.
    scale: T,
    /// The Fresnel weight of each order ([`vertex_fresnel`]).
    fresnel: OrderFresnel<T>,
}

impl<T: Real> Tabulated<T> {
    pub fn new(single: SingleBounce<T>) -> Self {
        let single = SingleBounce {
            height: Height::Correlated,
            ..single
        };
        let ndf = single.microfacet.ndf;
        let alpha = (single.microfacet.ax * single.microfacet.ay).sqrt();
        let albedo = AlbedoTable::get(ndf, Height::Correlated);
        let rho = (T::one() - albedo.e_avg(alpha)).max_c(0.0);
        // As `kulla-conty`: below 1e-9 of lost energy the lobe is nothing, and `f_kc` would
        // divide the table's `1 - E(mu)` (interpolated, not exactly 0 at grazing) by ~0.
        let scale = if rho.re64() < 1e-9 {
            T::zero()
        } else {
            (T::c(std::f64::consts::PI) * rho).recip()
        };
        let alpha_cell = log_cell(alpha, ALPHA_MIN, ALPHA_MAX, ALPHA_COUNT);
        Tabulated {
            single,
            table: HeitzTable::get(ndf),
            albedo,
            alpha_cell,
            albedo_cell: AlbedoTable::alpha_cell(alpha),
            scale,
            fresnel: OrderFresnel::new(&single.fresnel, ndf, alpha_cell),
        }
    }

    /// The multiple-bounce lobe, 1/sr.
    pub fn multiple(&self, wi: Vec3<T>, wo: Vec3<T>) -> Rgb<T> {
        let re = |v: Vec3<T>| [v.x.re64(), v.y.re64(), v.z.re64()];
        LobeDirections::new(re(wi), re(wo)).map_or(Rgb::splat(T::zero()), |directions| {
            self.multiple_at(&directions)
        })
    }

    /// The multiple-bounce lobe, 1/sr, at directions prepared by [`LobeDirections::new`].
    pub fn multiple_at(&self, directions: &LobeDirections) -> Rgb<T> {
        let (values, white) = self.white_orders(directions);
        let [xi, xo] = directions.warped;
        self.fresnel.weigh(xi, xo, values).scale(white)
    }

    /// What the lobe at `directions` is before its Fresnel weights: the table's `T_k` per
    /// order group, interpolated in roughness, and the white lobe `f_kc` they multiply.
    fn white_orders(&self, directions: &LobeDirections) -> ([T; ORDERS], T) {
        let LobeDirections {
            cells,
            mu_cells: [mu_i, mu_o],
            ..
        } = *directions;
        let (i, t) = self.alpha_cell;
        let below = self.table.directional(i, cells);
        let above = self.table.directional(i + 1, cells);
        let values = std::array::from_fn(|k| T::c(below[k]) + T::c(above[k] - below[k]) * t);
        let lost =
            |mu_cell| (T::one() - self.albedo.e_in_cells(mu_cell, self.albedo_cell)).max_c(0.0);
        (values, lost(mu_i) * lost(mu_o) * self.scale)
    }
}

impl Tabulated<f64> {
    /// The Fresnel weights of a Schlick `F0` at this roughness as functions of `F0`, for
    /// [`Tabulated::schlick_orders_at`].
    pub fn schlick_orders(&self) -> SchlickOrders {
        SchlickOrders::new(self.single.microfacet.ndf, self.alpha_cell)
    }

    /// The multiple-bounce lobe at `directions` for a Schlick Fresnel, split so that `F0`
    /// can vary: per order group `g`, the coefficients `[q0, q1, q2]` of a quadratic in `F0`
    /// that does not depend on the channel, so that the lobe of a channel with Schlick `F0`
    /// is `sum_g inner_g(F0) (q0 + q1 F0 + q2 F0^2)` with `inner` = 1, `F_mid,3` and the tail
    /// factor of [`SchlickOrders`] (`orders`, from [`Tabulated::schlick_orders`]). The product
    /// `(m_i + (1 - m_i) F0)(m_o + (1 - m_o) F0)` of the two end weights gives the quadratic
    /// ([`vertex_fresnel`]'s derivation). This lobe's own Fresnel is not read.
    pub fn schlick_orders_at(
        &self,
        directions: &LobeDirections,
        orders: &SchlickOrders,
    ) -> [[f64; 3]; ORDERS] {
        let (values, white) = self.white_orders(directions);
        let [xi, xo] = directions.warped;
        let (mi, mo) = (orders.end_moments(xi), orders.end_moments(xo));
        std::array::from_fn(|g| {
            let v = values[g] * white;
            let (a, b) = (mi[g], mo[g]);
            [
                v * a * b,
                v * (a * (1.0 - b) + b * (1.0 - a)),
                v * (1.0 - a) * (1.0 - b),
            ]
        })
    }
}

impl<T: Real> ScalarBrdf<T> for Tabulated<T> {
    fn eval_split(&self, wi: Vec3<T>, wo: Vec3<T>, _rng: &mut Rng) -> (Rgb<T>, Rgb<T>) {
        (self.single.eval(wi, wo), self.multiple(wi, wo))
    }

    fn eval_multi(&self, wi: Vec3<T>, wo: Vec3<T>, _rng: &mut Rng) -> Rgb<T> {
        self.multiple(wi, wo)
    }
}

impl AddedLobe for Tabulated<f64> {
    fn single_lobe(&self) -> &SingleBounce<f64> {
        &self.single
    }
    fn added_lobe(&self, wi: Vec3<f64>, wo: Vec3<f64>) -> [f64; 3] {
        self.multiple(wi, wo).0
    }
}

#[cfg(test)]
mod tests;

//! Tabulated white directional albedo `E(mu, alpha)` of the single-bounce model and its cosine-
//! weighted average `E_avg(alpha) = 2 integral_0^1 E(mu) mu dmu`, the tables that the energy
//! compensation models (`kulla-conty`, `turquin`) read.
//!
//! | property | value |
//! | --- | --- |
//! | grid | 48 values of `mu = cos(theta)` uniform in `sqrt(mu)` over [1e-5, 1] (dense toward grazing, where `E` changes fastest); 80 values of `alpha` log-uniform in [1e-4, 3] |
//! | entries | `directional_albedo` of `single` with white Fresnel, 96 x 96 node quadrature each (within 5e-5 of 256 x 256) |
//! | interpolation | `ln E` bilinear in (`sqrt(mu)`, `ln alpha`), clamped to the grid: at large roughness `E` falls like a power of `alpha`, so `ln E` is nearly linear in `ln alpha` (interpolating `E` itself on 40 nodes was 2.8% off at `alpha` = 1.5, `mu` = 1; `ln E` on 80 nodes is within 0.21% at every point tested) |
//! | storage | computed once by the quadrature above and embedded in the binary (`albedo_tables.bin`, little-endian f64, 4 tables x 80 x 48); computing them took 3 s (GGX) and 9 s (Beckmann) of CPU at every start. A test recomputes rows of every table and requires agreement to 1e-12; after changing the grid or `single`, regenerate with `cargo test --release --lib regenerate_albedo_tables -- --ignored` |
//! | anisotropy | isotropic tables; an anisotropic surface reads them at `alpha = sqrt(ax ay)` (an approximation, as in Kulla & Conty 2017) |

use crate::microfacet::{Height, NdfKind};
use crate::scalar::Real;
use std::sync::OnceLock;

/// Nodes of the `mu` grid.
pub const MU_COUNT: usize = 48;
const MU_MIN: f64 = 1e-5;
const ALPHA_COUNT: usize = 80;
const ALPHA_MIN: f64 = 1e-4;
const ALPHA_MAX: f64 = 3.0;

/// `E(mu, alpha)` and `E_avg(alpha)` of one distribution and height model, stored as logarithms.
pub struct AlbedoTable {
    /// `ln E`, row-major `[alpha][mu]`.
    ln_e: Vec<f64>,
    ln_e_avg: Vec<f64>,
}

/// Node `j` of the `mu` grid, uniform in `sqrt(mu)`.
fn mu_node(j: usize) -> f64 {
    let root_min = MU_MIN.sqrt();
    (root_min + (1.0 - root_min) * j as f64 / (MU_COUNT - 1) as f64).powi(2)
}

/// The tables as computed by `tests::compute_e`, in slot order (see [`AlbedoTable::get`]).
static EMBEDDED: &[u8] = include_bytes!("albedo_tables.bin");
const TABLE_KINDS: [(NdfKind, Height); 4] = [
    (NdfKind::Ggx, Height::Correlated),
    (NdfKind::Ggx, Height::Uncorrelated),
    (NdfKind::Beckmann, Height::Correlated),
    (NdfKind::Beckmann, Height::Uncorrelated),
];

/// Table `slot` of [`EMBEDDED`]: `ALPHA_COUNT * MU_COUNT` values of `E`.
fn embedded_e(slot: usize) -> Vec<f64> {
    embedded_slot(EMBEDDED, slot, ALPHA_COUNT * MU_COUNT)
}

/// Table `slot` of `len` little-endian f64 values in an embedded file of equal tables.
pub(crate) fn embedded_slot(bytes: &[u8], slot: usize, len: usize) -> Vec<f64> {
    bytes[slot * len * 8..(slot + 1) * len * 8]
        .chunks_exact(8)
        .map(|b| f64::from_le_bytes(b.try_into().expect("chunks of 8 bytes")))
        .collect()
}

/// Cell of `x` on `count` nodes log-uniform in `[min, max]`: the lower node and the weight of
/// the upper one, linear in `ln x` (a dual number carries its derivative). Clamped to the
/// grid, where the weight is a constant.
pub(crate) fn log_cell<T: Real>(x: T, min: f64, max: f64, count: usize) -> (usize, T) {
    let scaled = (x.ln() - T::c(min.ln())) * T::c((count - 1) as f64 / (max.ln() - min.ln()));
    let s = scaled.re64().clamp(0.0, (count - 1) as f64 - 1e-9);
    let i = s as usize;
    let t = if scaled.re64() <= 0.0 || scaled.re64() >= (count - 1) as f64 {
        T::c(s - i as f64)
    } else {
        scaled - T::c(i as f64)
    };
    (i, t)
}

impl AlbedoTable {
    /// The table of `(ndf, height)`, read from the embedded data on first use.
    pub fn get(ndf: NdfKind, height: Height) -> &'static AlbedoTable {
        static TABLES: [OnceLock<AlbedoTable>; 4] = [
            OnceLock::new(),
            OnceLock::new(),
            OnceLock::new(),
            OnceLock::new(),
        ];
        let slot = TABLE_KINDS
            .iter()
            .position(|&kind| kind == (ndf, height))
            .expect("every (ndf, height) pair has a table");
        TABLES[slot].get_or_init(|| AlbedoTable::from_e(&embedded_e(slot)))
    }

    /// The table from `E` at every node; `E_avg` by the trapezoid rule over the `mu` nodes.
    fn from_e(e: &[f64]) -> AlbedoTable {
        // Below MU_MIN, E is taken constant (that sliver weighs 2 * MU_MIN^2 / 2 = 1e-10).
        let e_avg: Vec<f64> = (0..ALPHA_COUNT)
            .map(|i| {
                let row = &e[i * MU_COUNT..(i + 1) * MU_COUNT];
                let mut integral = row[0] * MU_MIN * MU_MIN / 2.0;
                for j in 1..MU_COUNT {
                    let (m0, m1) = (mu_node(j - 1), mu_node(j));
                    integral += 0.5 * (row[j - 1] * m0 + row[j] * m1) * (m1 - m0);
                }
                2.0 * integral
            })
            .collect();
        AlbedoTable {
            ln_e: e.iter().map(|v| v.ln()).collect(),
            ln_e_avg: e_avg.iter().map(|v: &f64| v.ln()).collect(),
        }
    }

    /// Position of `alpha` on the log grid: lower index and weight of the upper node.
    pub fn alpha_cell<T: Real>(alpha: T) -> (usize, T) {
        log_cell(alpha, ALPHA_MIN, ALPHA_MAX, ALPHA_COUNT)
    }

    /// Position of `mu` on the `mu` grid: the lower node `j` and the weight `u` of node
    /// `j + 1` (linear in `sqrt(mu)`, clamped to the grid). It depends on the direction only,
    /// so the batch kernel computes it once per record.
    pub fn mu_cell(mu: f64) -> (usize, f64) {
        let root_min = MU_MIN.sqrt();
        let s = ((mu.clamp(MU_MIN, 1.0).sqrt() - root_min) / (1.0 - root_min)
            * (MU_COUNT - 1) as f64)
            .min((MU_COUNT - 1) as f64 - 1e-9);
        let j = s as usize;
        (j, s - j as f64)
    }

    /// `ln E` at every node of the `mu` grid at roughness `alpha` (interpolated in `ln alpha`
    /// as [`AlbedoTable::e`] does): with [`AlbedoTable::mu_cell`], `ln E(mu, alpha)` is
    /// `row[j] (1 - u) + row[j + 1] u`. The batch kernel reads every record's `E` at one
    /// roughness from this row (a dual number carries `d ln E / d alpha`).
    pub fn ln_e_row<T: Real>(&self, alpha: T) -> [T; MU_COUNT] {
        let (i, t) = Self::alpha_cell(alpha);
        std::array::from_fn(|j| {
            T::c(self.ln_e[i * MU_COUNT + j]) * (T::one() - t)
                + T::c(self.ln_e[(i + 1) * MU_COUNT + j]) * t
        })
    }

    /// `E(mu, alpha)`: white directional albedo of `single` at incidence cosine `mu`.
    pub fn e<T: Real>(&self, mu: f64, alpha: T) -> T {
        self.e_in_cells(Self::mu_cell(mu), Self::alpha_cell(alpha))
    }

    /// [`AlbedoTable::e`] at a [`AlbedoTable::mu_cell`] and an [`AlbedoTable::alpha_cell`]
    /// computed beforehand: a model that reads many directions at one roughness finds the
    /// roughness cell once.
    pub fn e_in_cells<T: Real>(&self, (j, u): (usize, f64), (i, t): (usize, T)) -> T {
        let at = |a: usize| {
            self.ln_e[a * MU_COUNT + j] * (1.0 - u) + self.ln_e[a * MU_COUNT + j + 1] * u
        };
        (T::c(at(i)) * (T::one() - t) + T::c(at(i + 1)) * t).exp()
    }

    /// `E_avg(alpha) = 2 integral E(mu) mu dmu`.
    pub fn e_avg<T: Real>(&self, alpha: T) -> T {
        let (i, t) = Self::alpha_cell(alpha);
        (T::c(self.ln_e_avg[i]) * (T::one() - t) + T::c(self.ln_e_avg[i + 1]) * t).exp()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::albedo::directional_albedo;
    use crate::bsdf::single::SingleBounce;
    use crate::microfacet::{Fresnel, Microfacet};
    use crate::scalar::Vec3;
    use rayon::prelude::*;

    /// Quadrature nodes of every entry.
    const QUADRATURE_NODES: usize = 96 * 96;

    fn alpha_node(i: usize) -> f64 {
        (ALPHA_MIN.ln() + (ALPHA_MAX.ln() - ALPHA_MIN.ln()) * i as f64 / (ALPHA_COUNT - 1) as f64)
            .exp()
    }

    /// `E` at every node, row-major `[alpha][mu]`, by quadrature (what the embedded data holds).
    fn compute_e(ndf: NdfKind, height: Height, alpha_rows: &[usize]) -> Vec<f64> {
        let nodes: Vec<(usize, usize)> = alpha_rows
            .iter()
            .flat_map(|&i| (0..MU_COUNT).map(move |j| (i, j)))
            .collect();
        nodes
            .into_par_iter()
            .map(|(i, j)| {
                let (alpha, mu) = (alpha_node(i), mu_node(j));
                let model = SingleBounce {
                    microfacet: Microfacet::new(ndf, alpha, alpha),
                    fresnel: Fresnel::White,
                    height,
                };
                let wi = Vec3::new((1.0 - mu * mu).sqrt(), 0.0, mu);
                directional_albedo(&model, wi, QUADRATURE_NODES, 0).value[0]
            })
            .collect()
    }

    /// Writes `albedo_tables.bin` from the quadrature (about 4 min of CPU); run by hand after a
    /// change of the grid or of `single`, then commit the file.
    #[test]
    #[ignore = "regenerates the embedded tables"]
    fn regenerate_albedo_tables() {
        let rows: Vec<usize> = (0..ALPHA_COUNT).collect();
        let bytes: Vec<u8> = TABLE_KINDS
            .iter()
            .flat_map(|&(ndf, height)| compute_e(ndf, height, &rows))
            .flat_map(f64::to_le_bytes)
            .collect();
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/src/bsdf/albedo_tables.bin");
        std::fs::write(path, bytes).unwrap();
    }

    #[test]
    fn embedded_tables_match_their_quadrature() {
        assert_eq!(
            EMBEDDED.len(),
            TABLE_KINDS.len() * ALPHA_COUNT * MU_COUNT * 8
        );
        for (slot, &(ndf, height)) in TABLE_KINDS.iter().enumerate() {
            // Two rows per table, different in every table, ends included across the four.
            let rows = [slot * 26, ALPHA_COUNT - 1 - slot * 13];
            let fresh = compute_e(ndf, height, &rows);
            let stored = embedded_e(slot);
            for (k, value) in fresh.iter().enumerate() {
                let (i, j) = (rows[k / MU_COUNT], k % MU_COUNT);
                let embedded = stored[i * MU_COUNT + j];
                assert!(
                    (embedded / value - 1.0).abs() < 1e-12,
                    "{ndf:?} {height:?} alpha {} mu {}: embedded {embedded} vs {value}",
                    alpha_node(i),
                    mu_node(j)
                );
            }
        }
    }

    #[test]
    fn table_reproduces_direct_albedo_between_nodes() {
        for ndf in [NdfKind::Ggx, NdfKind::Beckmann] {
            let table = AlbedoTable::get(ndf, Height::Correlated);
            for (alpha, mu) in [
                (0.07, 0.33),
                (0.45, 0.8),
                (1.1, 0.12),
                (2.2, 0.55),
                (0.3, 1.0),
                (1.5, 1.0),
                (1.5, 0.5),
                (0.8, 0.9),
            ] {
                let model = SingleBounce {
                    microfacet: Microfacet::new(ndf, alpha, alpha),
                    fresnel: Fresnel::White,
                    height: Height::Correlated,
                };
                let direct = directional_albedo(
                    &model,
                    Vec3::new((1.0f64 - mu * mu).sqrt(), 0.0, mu),
                    65_536,
                    0,
                )
                .value[0];
                let tabulated = table.e(mu, alpha);
                // Relative error (what Turquin's division by E sees): measured <= 0.21% for GGX.
                assert!(
                    (tabulated / direct - 1.0).abs() < 5e-3,
                    "{ndf:?} alpha {alpha} mu {mu}: table {tabulated} vs {direct}"
                );
            }
            // E_avg falls with roughness and is 1 for a mirror-like surface.
            assert!((table.e_avg(1e-4f64) - 1.0).abs() < 1e-3);
            assert!(
                table.e_avg(0.3f64) > table.e_avg(1.0f64)
                    && table.e_avg(1.0f64) > table.e_avg(2.5f64)
            );
        }
    }
}

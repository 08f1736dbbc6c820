//! Tabulated white directional albedo `E(mu, alpha)` of the single-bounce model and its cosine-
//! weighted average `E_avg(alpha) = 2 integral_0^1 E(mu) mu dmu`, the tables that the energy
//! compensation models (`kulla-conty`, `turquin`) read.
//!
//! | property | value |
//! | --- | --- |
//! | grid | 32 values of `mu = cos(theta)` uniform in [1e-3, 1]; 80 values of `alpha` log-uniform in [1e-4, 3] |
//! | entries | `directional_albedo` of `single` with white Fresnel, 96 x 96 node quadrature each (within 5e-5 of 256 x 256) |
//! | interpolation | `ln E` bilinear in (`mu`, `ln alpha`), clamped to the grid: at large roughness `E` falls like a power of `alpha`, so `ln E` is nearly linear in `ln alpha` (interpolating `E` itself on 40 nodes was 2.8% off at `alpha` = 1.5, `mu` = 1; `ln E` on 80 nodes is within 0.21% at every point tested) |
//! | when | computed deterministically on first use, once per (distribution, height model) and process, in parallel (about 0.5 s on 2 cores); never written to disk |
//! | anisotropy | isotropic tables; an anisotropic surface reads them at `alpha = sqrt(ax ay)` (an approximation, as in Kulla & Conty 2017) |

use super::single::SingleBounce;
use crate::albedo::directional_albedo;
use crate::microfacet::{Fresnel, Height, Microfacet, NdfKind};
use crate::scalar::{Real, Vec3};
use rayon::prelude::*;
use std::sync::OnceLock;

const MU_COUNT: usize = 32;
const MU_MIN: f64 = 1e-3;
const ALPHA_COUNT: usize = 80;
const ALPHA_MIN: f64 = 1e-4;
const ALPHA_MAX: f64 = 3.0;
const QUADRATURE_NODES: usize = 96 * 96;

/// `E(mu, alpha)` and `E_avg(alpha)` of one distribution and height model, stored as logarithms.
pub struct AlbedoTable {
    /// `ln E`, row-major `[alpha][mu]`.
    ln_e: Vec<f64>,
    ln_e_avg: Vec<f64>,
}

fn mu_node(j: usize) -> f64 {
    MU_MIN + (1.0 - MU_MIN) * j as f64 / (MU_COUNT - 1) as f64
}

fn alpha_node(i: usize) -> f64 {
    (ALPHA_MIN.ln() + (ALPHA_MAX.ln() - ALPHA_MIN.ln()) * i as f64 / (ALPHA_COUNT - 1) as f64).exp()
}

impl AlbedoTable {
    /// The table of `(ndf, height)`, computed on first use.
    pub fn get(ndf: NdfKind, height: Height) -> &'static AlbedoTable {
        static TABLES: [OnceLock<AlbedoTable>; 4] = [
            OnceLock::new(),
            OnceLock::new(),
            OnceLock::new(),
            OnceLock::new(),
        ];
        let slot = match (ndf, height) {
            (NdfKind::Ggx, Height::Correlated) => 0,
            (NdfKind::Ggx, Height::Uncorrelated) => 1,
            (NdfKind::Beckmann, Height::Correlated) => 2,
            (NdfKind::Beckmann, Height::Uncorrelated) => 3,
        };
        TABLES[slot].get_or_init(|| AlbedoTable::compute(ndf, height))
    }

    fn compute(ndf: NdfKind, height: Height) -> AlbedoTable {
        let e: Vec<f64> = (0..ALPHA_COUNT * MU_COUNT)
            .into_par_iter()
            .map(|k| {
                let (alpha, mu) = (alpha_node(k / MU_COUNT), mu_node(k % MU_COUNT));
                let model = SingleBounce {
                    microfacet: Microfacet::new(ndf, alpha, alpha),
                    fresnel: Fresnel::White,
                    height,
                };
                let wi = Vec3::new((1.0 - mu * mu).sqrt(), 0.0, mu);
                directional_albedo(&model, wi, QUADRATURE_NODES, 0).value[0]
            })
            .collect();
        // E_avg = 2 int E(mu) mu dmu by the trapezoid rule on the mu nodes; below MU_MIN, E is
        // taken constant (that sliver weighs 2 * MU_MIN^2 / 2 = 1e-6).
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
    fn alpha_cell<T: Real>(alpha: T) -> (usize, T) {
        let scaled = (alpha.ln() - T::c(ALPHA_MIN.ln()))
            * T::c((ALPHA_COUNT - 1) as f64 / (ALPHA_MAX.ln() - ALPHA_MIN.ln()));
        let s = scaled.re64().clamp(0.0, (ALPHA_COUNT - 1) as f64 - 1e-9);
        let i = s as usize;
        let t = if scaled.re64() <= 0.0 || scaled.re64() >= (ALPHA_COUNT - 1) as f64 {
            T::c(s - i as f64)
        } else {
            scaled - T::c(i as f64)
        };
        (i, t)
    }

    /// `E(mu, alpha)`: white directional albedo of `single` at incidence cosine `mu`.
    pub fn e<T: Real>(&self, mu: f64, alpha: T) -> T {
        let (i, t) = Self::alpha_cell(alpha);
        let s = ((mu.clamp(MU_MIN, 1.0) - MU_MIN) / (1.0 - MU_MIN) * (MU_COUNT - 1) as f64)
            .min((MU_COUNT - 1) as f64 - 1e-9);
        let j = s as usize;
        let u = s - j as f64;
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

//! Tabulated tails of the per-bounce energy of the multiple-scattering walks: `T(K, alpha)`,
//! the fraction of the white directional albedo carried by paths of more than `K` reflections,
//! the largest over a few incidences. The render plan's `bounce-cap` skip reads it to choose
//! the fewest reflections whose dropped tail stays below a tolerance ([`BounceTails::cap`]).
//!
//! | property | value |
//! | --- | --- |
//! | walks | `smith`: the walk on the height-correlated Smith microsurface that `heitz`, `bitterli` and `cui` estimate (one value, so one path-length distribution; measured with the `bitterli` sampler); `wang-correlated` and `wang-uncorrelated`: the path integral of `wang-pt` / `wang-bdpt` with that height model (measured with its analog sampler, sec. 4.3), whose paths are longer (GGX alpha 0.3 at 85 degrees: 4+ bounces carry 1.6e-3 correlated, 2e-4 for `smith`) |
//! | grid | `K` = 1..=[`MAX_TABULATED_BOUNCES`]; [`ALPHA_COUNT`] values of `alpha` log-uniform in [`ALPHA_MIN`], [`ALPHA_MAX`]; GGX and Beckmann |
//! | entry | `max over theta_i in {0, 45, 70, 85} deg of E_{>K}(theta_i) / E(theta_i)`, white Fresnel, isotropic, by stratified sampling ([`crate::albedo::bounce_moments`], [`SAMPLES_PER_ENTRY`] paths per incidence) |
//! | Fresnel | white is the worst case: a conductor's Fresnel factor below 1 at every reflection multiplies a path of `n` bounces by `n` factors, so it shortens the tail relative to the total |
//! | lookup | conservative in `alpha`: between two nodes the larger of the two values; below `ALPHA_MIN` the first node (tails shrink toward a mirror); above `ALPHA_MAX` nothing is known ([`BounceTails::cap`] gives no cap); anisotropic surfaces read it at `max(ax, ay)` |
//! | storage | `bounce_tails.bin`, little-endian f64, 6 tables x `ALPHA_COUNT` x `MAX_TABULATED_BOUNCES`; a test recomputes entries by fresh Monte Carlo and requires agreement within 4 sigma; regenerate with `cargo test --lib regenerate_bounce_tails -- --ignored` (the test profile is optimised; 15 minutes on 2 shared cores) after changing a walk or the grid |
//!
//! The tail bounds energy, not each pixel: dropping the paths of more than `K` reflections lowers
//! the directional albedo by at most `T(K) E`; at a given pair of directions the relative change
//! can be larger where the single-bounce lobe is small.

use super::albedo_table::embedded_slot;
use super::registry::Paths;
use super::{BounceCap, Model};
use crate::microfacet::{Height, NdfKind};
use std::sync::OnceLock;

/// Largest `K` tabulated; a tail above the tolerance at this `K` means no cap.
pub const MAX_TABULATED_BOUNCES: usize = 16;
pub const ALPHA_COUNT: usize = 25;
pub const ALPHA_MIN: f64 = 1e-3;
pub const ALPHA_MAX: f64 = 3.0;
/// Paths sampled per incidence for each entry.
pub const SAMPLES_PER_ENTRY: usize = 1 << 20;
/// Incidences whose largest tail is stored, degrees from the normal.
pub const INCIDENCES_DEG: [f64; 4] = [0.0, 45.0, 70.0, 85.0];

/// Which path-length distribution a model's estimator integrates.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Walk {
    Smith,
    WangCorrelated,
    WangUncorrelated,
}

/// The tables in the order of [`EMBEDDED`].
const TABLE_KINDS: [(NdfKind, Walk); 6] = [
    (NdfKind::Ggx, Walk::Smith),
    (NdfKind::Ggx, Walk::WangCorrelated),
    (NdfKind::Ggx, Walk::WangUncorrelated),
    (NdfKind::Beckmann, Walk::Smith),
    (NdfKind::Beckmann, Walk::WangCorrelated),
    (NdfKind::Beckmann, Walk::WangUncorrelated),
];

static EMBEDDED: &[u8] = include_bytes!("bounce_tails.bin");

/// Node `i` of the roughness grid.
pub fn alpha_node(i: usize) -> f64 {
    let step = (ALPHA_MAX / ALPHA_MIN).ln() / (ALPHA_COUNT - 1) as f64;
    ALPHA_MIN * (step * i as f64).exp()
}

impl Walk {
    /// The walk of a model that integrates `paths` with `height`.
    pub fn of(paths: Paths, height: Height) -> Walk {
        match (paths, height) {
            (Paths::Smith, _) => Walk::Smith,
            (Paths::Wang, Height::Correlated) => Walk::WangCorrelated,
            (Paths::Wang, Height::Uncorrelated) => Walk::WangUncorrelated,
        }
    }
}

/// `T(K, alpha)` of one walk and distribution.
#[derive(Debug)]
pub struct BounceTails {
    /// Row-major `[alpha node][K - 1]`.
    tails: Vec<f64>,
}

impl BounceTails {
    /// The table of `model` (with `ndf`, `height`), `None` for the analytic models.
    pub fn get(model: Model, ndf: NdfKind, height: Height) -> Option<&'static BounceTails> {
        static TABLES: [OnceLock<BounceTails>; 6] = [const { OnceLock::new() }; 6];
        let walk = Walk::of(model.capabilities().paths?, height);
        let slot = TABLE_KINDS
            .iter()
            .position(|&kind| kind == (ndf, walk))
            .expect("every (ndf, walk) pair has a table");
        Some(TABLES[slot].get_or_init(|| BounceTails {
            tails: embedded_slot(EMBEDDED, slot, ALPHA_COUNT * MAX_TABULATED_BOUNCES),
        }))
    }

    /// The stored `T(k, alpha node i)`.
    pub fn node(&self, k: usize, i: usize) -> f64 {
        self.tails[i * MAX_TABULATED_BOUNCES + k - 1]
    }

    /// An upper bound of `T(k, alpha)` from the nodes around `alpha` (see the module table);
    /// `None` above the grid.
    pub fn tail(&self, k: usize, alpha: f64) -> Option<f64> {
        if alpha.is_nan() || alpha > ALPHA_MAX {
            return None;
        }
        let position =
            (alpha / ALPHA_MIN).ln() / (ALPHA_MAX / ALPHA_MIN).ln() * (ALPHA_COUNT - 1) as f64;
        let below = position.floor().clamp(0.0, (ALPHA_COUNT - 1) as f64) as usize;
        let above = position.ceil().clamp(0.0, (ALPHA_COUNT - 1) as f64) as usize;
        Some(self.node(k, below).max(self.node(k, above)))
    }

    /// The fewest reflections whose tail at roughness `alpha` is at most `tolerance`;
    /// [`BounceCap::NONE`] when even [`MAX_TABULATED_BOUNCES`] leave more, or `alpha` is off
    /// the grid.
    pub fn cap(&self, alpha: f64, tolerance: f64) -> BounceCap {
        (1..=MAX_TABULATED_BOUNCES)
            .find(|&k| self.tail(k, alpha).is_some_and(|t| t <= tolerance))
            .map_or(BounceCap::NONE, |k| BounceCap::at(k as u32))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::albedo::bounce_moments;
    use crate::material::{FresnelSpec, Material};
    use crate::scalar::Vec3;

    /// The model whose sampler measures `walk`.
    fn sampler(ndf: NdfKind, walk: Walk, alpha: f64) -> Material {
        let (model, height) = match walk {
            Walk::Smith => (Model::Bitterli, Height::Correlated),
            Walk::WangCorrelated => (Model::WangPt, Height::Correlated),
            Walk::WangUncorrelated => (Model::WangPt, Height::Uncorrelated),
        };
        Material {
            model,
            ndf,
            height,
            alpha: [alpha, alpha],
            fresnel: FresnelSpec::White,
            diffuse: [0.0; 3],
        }
    }

    /// One incidence's tails: `(T(K), standard error of T(K))` for `K` = 1..=MAX.
    struct IncidenceTails {
        tails: Vec<f64>,
        stderr: Vec<f64>,
    }

    fn incidence_tails(
        brdf: &dyn crate::bsdf::Brdf,
        theta: f64,
        samples: usize,
        seed: u64,
    ) -> IncidenceTails {
        let wi = Vec3::new(theta.to_radians().sin(), 0.0, theta.to_radians().cos());
        let m = bounce_moments(brdf, wi, samples, seed, MAX_TABULATED_BOUNCES + 1);
        let total: f64 = m.mean.iter().map(|v| v[0]).sum();
        let n = m.samples as f64;
        let (mut tails, mut stderr) = (Vec::new(), Vec::new());
        for k in 1..=MAX_TABULATED_BOUNCES {
            let mean: f64 = m.mean[k..].iter().map(|v| v[0]).sum();
            let square: f64 = m.mean_square[k..].iter().map(|v| v[0]).sum();
            tails.push(mean / total);
            stderr.push(((square - mean * mean).max(0.0) / (n - 1.0)).sqrt() / total);
        }
        IncidenceTails { tails, stderr }
    }

    /// The tails of every incidence of [`INCIDENCES_DEG`] at alpha node `i`.
    fn row_tails(
        ndf: NdfKind,
        walk: Walk,
        i: usize,
        samples: usize,
        seed: u64,
    ) -> Vec<IncidenceTails> {
        let brdf = sampler(ndf, walk, alpha_node(i)).brdf();
        INCIDENCES_DEG
            .iter()
            .enumerate()
            .map(|(j, &theta)| incidence_tails(brdf.as_ref(), theta, samples, seed + j as u64))
            .collect()
    }

    /// Writes `bounce_tails.bin` (15 minutes on 2 shared cores); run by hand after a change
    /// of a walk or of the grid, then commit the file.
    #[test]
    #[ignore = "regenerates the embedded table"]
    fn regenerate_bounce_tails() {
        let mut bytes = Vec::new();
        for (slot, &(ndf, walk)) in TABLE_KINDS.iter().enumerate() {
            for i in 0..ALPHA_COUNT {
                let seed = (slot * ALPHA_COUNT + i) as u64 * 16;
                let rows = row_tails(ndf, walk, i, SAMPLES_PER_ENTRY, seed);
                for k in 0..MAX_TABULATED_BOUNCES {
                    let worst = rows.iter().map(|r| r.tails[k]).fold(0.0, f64::max);
                    bytes.extend(worst.to_le_bytes());
                }
            }
        }
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/src/bsdf/bounce_tails.bin");
        std::fs::write(path, bytes).unwrap();
    }

    /// Entries of four tables (both NDFs, the three walks, low to high roughness) against a
    /// fresh run on other random numbers with a quarter of the samples. Stored and fresh are
    /// each the largest over the incidences of an estimate, so they differ by at most the
    /// largest per-incidence difference; each of those has standard deviation
    /// `sigma = s sqrt(1 + n_fresh / n_table)` with `s` the fresh standard error, taken at
    /// least as the binomial `sqrt(T / n_fresh)` (white weights are 1: a path is in the tail
    /// or not) so that a tail the fresh run never reaches still has a width. Allowed: 4 sigma.
    #[test]
    fn embedded_tails_match_fresh_monte_carlo() {
        let fresh_samples = SAMPLES_PER_ENTRY / 4;
        let ratio = (1.0 + fresh_samples as f64 / SAMPLES_PER_ENTRY as f64).sqrt();
        for (ndf, walk, i) in [
            (NdfKind::Ggx, Walk::Smith, 15),
            (NdfKind::Beckmann, Walk::Smith, 21),
            (NdfKind::Ggx, Walk::WangUncorrelated, 18),
            (NdfKind::Beckmann, Walk::WangCorrelated, 12),
        ] {
            let table = BounceTails::get(
                match walk {
                    Walk::Smith => Model::Bitterli,
                    _ => Model::WangBdpt,
                },
                ndf,
                match walk {
                    Walk::WangUncorrelated => Height::Uncorrelated,
                    _ => Height::Correlated,
                },
            )
            .unwrap();
            let rows = row_tails(ndf, walk, i, fresh_samples, 0xF2E5 + i as u64);
            for k in 1..=MAX_TABULATED_BOUNCES {
                let fresh = rows.iter().map(|r| r.tails[k - 1]).fold(0.0, f64::max);
                let stored = table.node(k, i);
                let sigma = rows
                    .iter()
                    .map(|r| {
                        let binomial = (stored.max(r.tails[k - 1]) / fresh_samples as f64).sqrt();
                        r.stderr[k - 1].max(binomial) * ratio
                    })
                    .fold(0.0, f64::max);
                assert!(
                    (stored - fresh).abs() <= 4.0 * sigma,
                    "{ndf:?} {walk:?} alpha {} K {k}: stored {stored} fresh {fresh} sigma {sigma}",
                    alpha_node(i)
                );
            }
        }
    }

    /// What the cap claims, checked off the grid and off white: for each walk at a roughness
    /// between nodes, with copper, at the table's grazing incidence and at one it does not
    /// store, the paths longer than the cap carry at most `BOUNCE_TOLERANCE` of the albedo,
    /// within 4 standard errors (measured, at most 4e-5).
    #[test]
    fn the_capped_tail_of_a_conductor_is_within_the_tolerance() {
        use crate::render::plan::BOUNCE_TOLERANCE;
        let copper = FresnelSpec::Conductor {
            eta: [0.2378, 1.0066, 1.2404],
            k: [3.6264, 2.5823, 2.3929],
        };
        for (model, height, alpha) in [
            (Model::Cui, Height::Correlated, 0.7),
            (Model::WangPt, Height::Correlated, 0.45),
            (Model::WangBdpt, Height::Uncorrelated, 0.25),
        ] {
            let k = BounceTails::get(model, NdfKind::Ggx, height)
                .unwrap()
                .cap(alpha, BOUNCE_TOLERANCE)
                .get()
                .expect("a cap at this roughness") as usize;
            let brdf = Material {
                fresnel: copper,
                ..sampler(
                    NdfKind::Ggx,
                    Walk::of(model.capabilities().paths.unwrap(), height),
                    alpha,
                )
            }
            .brdf();
            for theta in [60.0f64, 85.0] {
                let wi = Vec3::new(theta.to_radians().sin(), 0.0, theta.to_radians().cos());
                let m = bounce_moments(brdf.as_ref(), wi, 1 << 19, 3, k + 1);
                for c in 0..3 {
                    let total: f64 = m.mean.iter().map(|v| v[c]).sum();
                    let (tail, square) = (m.mean[k][c], m.mean_square[k][c]);
                    let se = ((square - tail * tail) / (m.samples as f64 - 1.0)).sqrt() / total;
                    assert!(
                        tail / total <= BOUNCE_TOLERANCE + 4.0 * se,
                        "{model} {height:?} alpha {alpha} theta {theta} K {k}: tail {} (se {se})",
                        tail / total
                    );
                }
            }
        }
    }

    /// Tails shrink with `K` and grow with roughness (over the part of the grid where they are
    /// resolved), and so does the cap; it never exceeds the table.
    #[test]
    fn tails_and_caps_grow_with_roughness() {
        for &(ndf, walk) in &TABLE_KINDS {
            let model = if walk == Walk::Smith {
                Model::Heitz
            } else {
                Model::WangPt
            };
            let height = if walk == Walk::WangUncorrelated {
                Height::Uncorrelated
            } else {
                Height::Correlated
            };
            let table = BounceTails::get(model, ndf, height).unwrap();
            for i in 0..ALPHA_COUNT {
                for k in 2..=MAX_TABULATED_BOUNCES {
                    assert!(
                        table.node(k, i) <= table.node(k - 1, i),
                        "{ndf:?} {walk:?} {i} {k}"
                    );
                }
            }
            let caps: Vec<u32> = [0.01, 0.1, 0.3, 1.0, 2.0]
                .iter()
                .map(|&a| table.cap(a, 1e-3).get().unwrap_or(u32::MAX))
                .collect();
            assert!(
                caps.windows(2).all(|w| w[0] <= w[1]),
                "{ndf:?} {walk:?} {caps:?}"
            );
            assert!(caps[0] < caps[4], "{ndf:?} {walk:?} {caps:?}");
            // Between nodes the bound is the larger neighbour: never below either.
            let mid = (alpha_node(10) * alpha_node(11)).sqrt();
            for k in 1..=MAX_TABULATED_BOUNCES {
                let t = table.tail(k, mid).unwrap();
                assert!(t >= table.node(k, 10) && t >= table.node(k, 11));
            }
            assert_eq!(table.cap(3.5, 1e-3), BounceCap::NONE);
        }
    }
}

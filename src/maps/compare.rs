//! What a multi-bounce model changes in fitted maps (issue #17 item 3, `compare --maps`): the
//! per-texel differences of two maps fits of the same photos on the same texel grid, `model`
//! minus `single`, summarised over the sample and over the regions of the basis materials.
//!
//! Single scattering loses the energy of light that bounces more than once between microfacets,
//! the more the rougher and the more reflective the surface (Heitz et al. 2016, "Multiple-
//! scattering microfacet BSDFs with the Smith model", figure 1; Kulla & Conty 2017). A
//! single-bounce fit of a rough metal makes the loss up with the parameters it has: under a
//! flash, which sees each texel near the mirror direction, a narrower lobe (smaller `alpha`)
//! puts more energy there, so the multi-bounce fit's roughness is larger where the metal is
//! rough, and the difference vanishes on smooth or dielectric texels. These are the numbers
//! that show it, and where.
//!
//! | quantity | per texel |
//! | --- | --- |
//! | `alpha` | `alpha_model - alpha_single` (of anisotropic maps, `sqrt(alpha_x alpha_y)`: [`MaterialMaps::alpha`]) |
//! | `diffuse` | mean over RGB of the diffuse albedo difference |
//! | `f0` | mean over RGB of the Schlick F0 difference (0 with a known Fresnel) |
//!
//! Regions are the basis materials of `model`'s fit (its per-texel labels): the fit that
//! carries the multiple scattering is the one whose materials are meant.

use super::fit::{Basis, Kind};
use super::MaterialMaps;
use crate::bsdf::Model;
use serde::Serialize;

/// The roughness change counted as a change: 0.02 in `alpha` is the bound below which the
/// recovery test of `tests/maps.rs` holds a fitted map (RMSE 0.03 at 1% noise; measured 0.0075),
/// so smaller differences are within what one fit recovers.
pub const ALPHA_CHANGE: f64 = 0.02;

/// Summary of one per-texel difference over a set of texels.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct DeltaStats {
    pub mean: f64,
    pub mean_abs: f64,
    /// Percentiles 5, 50 and 95 (nearest rank).
    pub p05: f64,
    pub p50: f64,
    pub p95: f64,
    pub min: f64,
    pub max: f64,
}

impl DeltaStats {
    /// The statistics of `values` (`None` when there are none).
    pub fn of(values: &[f64]) -> Option<DeltaStats> {
        if values.is_empty() {
            return None;
        }
        let mut sorted = values.to_vec();
        sorted.sort_by(f64::total_cmp);
        let n = sorted.len();
        // Nearest rank: the smallest value with at least p of the values at or below it.
        let rank = |p: f64| sorted[((p * n as f64).ceil() as usize).clamp(1, n) - 1];
        Some(DeltaStats {
            mean: values.iter().sum::<f64>() / n as f64,
            mean_abs: values.iter().map(|v| v.abs()).sum::<f64>() / n as f64,
            p05: rank(0.05),
            p50: rank(0.5),
            p95: rank(0.95),
            min: sorted[0],
            max: sorted[n - 1],
        })
    }
}

/// The differences on the texels of one basis material of `model`'s fit.
#[derive(Clone, Debug, Serialize)]
pub struct RegionDelta {
    /// Index into `model`'s bases, its kind, roughness and share of the texels.
    pub basis: usize,
    pub kind: Kind,
    pub basis_alpha: f64,
    pub share: f64,
    /// Mean `alpha` of the region's texels in each fit.
    pub alpha_model: f64,
    pub alpha_single: f64,
    pub alpha: DeltaStats,
    pub diffuse: DeltaStats,
    pub f0: DeltaStats,
    /// Share of the region's texels where `|delta alpha| > ALPHA_CHANGE`.
    pub alpha_changed_fraction: f64,
}

/// What `model`'s maps change against `single`'s maps of the same photos.
#[derive(Clone, Debug, Serialize)]
pub struct MapsDifference {
    pub model: Model,
    /// The model subtracted (always `single`).
    pub minus: Model,
    pub alpha: DeltaStats,
    pub diffuse: DeltaStats,
    pub f0: DeltaStats,
    /// `ALPHA_CHANGE`, and the share of texels whose roughness differs by more.
    pub alpha_change_threshold: f64,
    pub alpha_changed_fraction: f64,
    /// Per basis material of `model`'s fit, in its order.
    pub regions: Vec<RegionDelta>,
}

/// Per-texel differences, `model - single`, row-major over the texel grid.
#[derive(Clone, Debug)]
pub struct TexelDeltas {
    pub alpha: Vec<f64>,
    pub diffuse: Vec<f64>,
    pub f0: Vec<f64>,
}

impl TexelDeltas {
    /// The differences of two maps on one grid; a map either lacks counts as its uniform value.
    pub fn new(model: &MaterialMaps, single: &MaterialMaps) -> TexelDeltas {
        assert_eq!(model.grid, single.grid, "maps compared on one texel grid");
        let n = model.grid.len();
        let mean = |v: [f64; 3]| (v[0] + v[1] + v[2]) / 3.0;
        let f0 = |m: &MaterialMaps, t: usize| m.specular.as_ref().map_or(0.0, |s| mean(s[t]));
        let (mut alpha, mut diffuse, mut f0_delta) = (
            Vec::with_capacity(n),
            Vec::with_capacity(n),
            Vec::with_capacity(n),
        );
        for t in 0..n {
            let (a, b) = (model.texel(t), single.texel(t));
            alpha.push(model.alpha(t) - single.alpha(t));
            diffuse.push(mean(a.diffuse) - mean(b.diffuse));
            f0_delta.push(f0(model, t) - f0(single, t));
        }
        TexelDeltas {
            alpha,
            diffuse,
            f0: f0_delta,
        }
    }
}

fn changed_fraction(alpha: &[f64]) -> f64 {
    alpha.iter().filter(|d| d.abs() > ALPHA_CHANGE).count() as f64 / alpha.len().max(1) as f64
}

impl MapsDifference {
    /// `model`'s maps against `single`'s, with `model`'s basis `labels` (one per texel) and
    /// `bases` as the regions.
    pub fn new(
        (model, model_maps): (Model, &MaterialMaps),
        single_maps: &MaterialMaps,
        labels: &[usize],
        bases: &[Basis],
    ) -> (MapsDifference, TexelDeltas) {
        let deltas = TexelDeltas::new(model_maps, single_maps);
        let stats = |v: &[f64]| DeltaStats::of(v).expect("a texel grid is not empty");
        let regions = bases
            .iter()
            .enumerate()
            .filter_map(|(b, basis)| {
                let texels: Vec<usize> = (0..labels.len()).filter(|&t| labels[t] == b).collect();
                let pick = |v: &[f64]| texels.iter().map(|&t| v[t]).collect::<Vec<f64>>();
                let alpha = pick(&deltas.alpha);
                let mean_alpha = |m: &MaterialMaps| {
                    texels.iter().map(|&t| m.alpha(t)).sum::<f64>() / texels.len().max(1) as f64
                };
                Some(RegionDelta {
                    basis: b,
                    kind: basis.kind,
                    basis_alpha: basis.alpha,
                    share: basis.share,
                    alpha_model: mean_alpha(model_maps),
                    alpha_single: mean_alpha(single_maps),
                    alpha: DeltaStats::of(&alpha)?,
                    diffuse: stats(&pick(&deltas.diffuse)),
                    f0: stats(&pick(&deltas.f0)),
                    alpha_changed_fraction: changed_fraction(&alpha),
                })
            })
            .collect();
        let difference = MapsDifference {
            model,
            minus: Model::Single,
            alpha: stats(&deltas.alpha),
            diffuse: stats(&deltas.diffuse),
            f0: stats(&deltas.f0),
            alpha_change_threshold: ALPHA_CHANGE,
            alpha_changed_fraction: changed_fraction(&deltas.alpha),
            regions,
        };
        (difference, deltas)
    }

    /// One sentence: how much and where the roughness changes.
    pub fn summary(&self) -> String {
        let regions: Vec<String> = self
            .regions
            .iter()
            .map(|r| {
                format!(
                    "{:?} basis {} ({:.0}% of the texels, alpha {:.3}): {:+.4} on average, {:.0}% of its texels beyond +-{ALPHA_CHANGE}",
                    r.kind,
                    r.basis,
                    100.0 * r.share,
                    r.basis_alpha,
                    r.alpha.mean,
                    100.0 * r.alpha_changed_fraction
                )
                .to_lowercase()
            })
            .collect();
        format!(
            "{} minus single: roughness differs by more than {ALPHA_CHANGE} on {:.0}% of the texels (mean {:+.4}, 5-95% {:+.4} to {:+.4}); diffuse albedo {:+.4}, F0 {:+.4} on average; per basis of {}: {}.",
            self.model,
            100.0 * self.alpha_changed_fraction,
            self.alpha.mean,
            self.alpha.p05,
            self.alpha.p95,
            self.diffuse.mean,
            self.f0.mean,
            self.model,
            regions.join("; ")
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::maps::TexelGrid;
    use crate::material::{FresnelSpec, Material};

    fn maps(alpha: Vec<f64>, diffuse: f64) -> MaterialMaps {
        let n = alpha.len();
        MaterialMaps {
            base: Material {
                model: Model::Single,
                ndf: Default::default(),
                height: Default::default(),
                alpha: [0.3; 2],
                fresnel: FresnelSpec::Schlick { f0: [0.04; 3] },
                diffuse: [0.0; 3],
            },
            grid: TexelGrid {
                width: n,
                height: 1,
            },
            diffuse: Some(vec![[diffuse; 3]; n]),
            specular: None,
            roughness: Some(alpha.into_iter().map(|a| [a; 2]).collect()),
            normal: None,
        }
    }

    #[test]
    fn percentiles_are_nearest_rank_and_the_mean_is_signed() {
        let values: Vec<f64> = (1..=20).map(f64::from).collect();
        let s = DeltaStats::of(&values).unwrap();
        assert_eq!((s.p05, s.p50, s.p95), (1.0, 10.0, 19.0));
        assert_eq!((s.min, s.max, s.mean), (1.0, 20.0, 10.5));
        let s = DeltaStats::of(&[-3.0, 1.0]).unwrap();
        assert_eq!((s.mean, s.mean_abs), (-1.0, 2.0));
        assert!(DeltaStats::of(&[]).is_none());
    }

    /// Four texels, two per basis: the metal basis gains 0.1 in alpha, the paint 0.01 (below
    /// the change threshold); the albedo falls by 0.05 everywhere. Each region sees only its
    /// own texels, and the uniform F0 gives zero F0 difference.
    #[test]
    fn differences_are_model_minus_single_per_texel_and_per_basis() {
        let single = maps(vec![0.5, 0.1, 0.55, 0.12], 0.3);
        let multi = maps(vec![0.6, 0.11, 0.65, 0.13], 0.25);
        let basis = |kind, alpha| Basis {
            kind,
            alpha,
            alpha_xy: None,
            f0: None,
            share: 0.5,
        };
        let bases = [basis(Kind::Metal, 0.62), basis(Kind::Dielectric, 0.12)];
        let (d, texels) =
            MapsDifference::new((Model::KullaConty, &multi), &single, &[0, 1, 0, 1], &bases);
        assert!((texels.alpha[0] - 0.1).abs() < 1e-12 && (texels.alpha[1] - 0.01).abs() < 1e-12);
        assert_eq!(d.alpha_changed_fraction, 0.5);
        assert!((d.diffuse.mean + 0.05).abs() < 1e-12 && d.f0.mean == 0.0);
        let [metal, paint] = &d.regions[..] else {
            panic!("two regions")
        };
        assert_eq!((metal.kind, paint.kind), (Kind::Metal, Kind::Dielectric));
        assert!((metal.alpha.mean - 0.1).abs() < 1e-12 && metal.alpha_changed_fraction == 1.0);
        assert!((paint.alpha.mean - 0.01).abs() < 1e-12 && paint.alpha_changed_fraction == 0.0);
        assert!((metal.alpha_model - 0.625).abs() < 1e-12);
        assert!((metal.alpha_single - 0.525).abs() < 1e-12);
        assert!(
            d.summary().contains("on 50% of the texels"),
            "{}",
            d.summary()
        );
    }
}

//! Where a fit starts: the global phase before the local search.
//!
//! | method | when | what |
//! | --- | --- | --- |
//! | `projection` | Schlick Fresnel and a squared-error loss (the default fits) | the projected loss ([`super::projection`]) over roughness only: its [`Profile`] over the whole roughness range, then Brent's method (isotropic) or Nelder-Mead (anisotropic) in every competing basin |
//! | `pso` | `--optimizer pso` | argmin's particle swarm over the box [`search_box`] of all coordinates, with a seeded generator |
//! | `scan` | otherwise | the [`Profile`] of a white Fresnel whose per-channel scale is solved in closed form; a start at every competing basin; conductors start at edge tint [`START_EDGE_TINT`]; with a known Fresnel, the scan renders it and one scale common to the channels is the start exposure |
//! | random | `--starts N`, for starts 2..N | uniform draws in [`search_box`], seeded |
//!
//! A fit runs one local search from each start the global phase returns (the competing basins
//! of the profile, at most [`MAX_BASINS`]), and the fit reports the basins it did not choose
//! when they end close to the chosen one (`crate::fit::point::Alternative`).

use super::local::simplex_around;
use super::objective::Objective;
use super::params::{FresnelFamily, ParamSpace};
use super::projection::Projection;
use crate::material::{FresnelSpec, Material};
use crate::microfacet::fresnel::ior_from_reflectivity_edge_tint;
use crate::random::rng_stream;
use argmin::core::{CostFunction, Error as ArgminError, Executor, State};
use argmin::solver::brent::BrentOpt;
use argmin::solver::neldermead::NelderMead;
use argmin::solver::particleswarm::ParticleSwarm;
use rand::Rng;
use serde::{Deserialize, Serialize};

/// How the start point of a local search was found.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum StartMethod {
    Projection,
    Pso,
    Scan,
    Random,
    /// The result of the previous (coarser) pyramid level.
    Coarser,
}

/// Roughness values of the coarse profile: a geometric grid (ratio 1.8) from 0.00114 to 2.38,
/// and 2.95 below the top of the fitted range ([`super::params::ALPHA_BOUNDS`]), that avoids
/// round values, so fits of synthetic sets made at round roughness exercise the optimiser
/// rather than land on a node.
const COARSE_ALPHAS: [f64; 15] = [
    0.00114, 0.00206, 0.0037, 0.00667, 0.012, 0.0216, 0.0389, 0.07, 0.126, 0.227, 0.408, 0.735,
    1.32, 2.38, 2.95,
];

/// The profile is refined by halving (in `ln alpha`) every interval wider than this ratio of
/// roughness that has an end within [`REFINE_LOSS_RATIO`] of the lowest loss: three halvings of
/// the coarse grid's 1.8. A basin of the loss over roughness can be narrower than 1.8: on a
/// ring of point lights around a pinhole camera (`heitz` photos of copper at alpha 0.5) the
/// projected loss was 1.95e-2 and 1.87e-2 at the nodes 0.408 and 0.735, 1.75e-2 in a rough
/// basin at 1.32, and 1.33e-2 at 0.51 between them: the coarse grid saw only the rough basin,
/// and the fit returned alpha 1.58.
const PROFILE_RATIO: f64 = 1.16;

/// Intervals of the profile with an end within this factor of the lowest loss are refined.
const REFINE_LOSS_RATIO: f64 = 2.5;

/// An interval whose ends differ by less than this fraction of the lowest loss is a plateau
/// and is not refined: smooth enough, a flash capture's samples reflect no highlight into the
/// camera, and the loss no longer depends on the roughness (on the real bath_tile the 17 nodes
/// below alpha 0.03 all read 2.19 times the lowest loss, and halving them took 40 solves).
const PLATEAU: f64 = 1e-3;

/// Neighbouring nodes whose losses differ by less than this fraction of the lowest loss are
/// equal for the choice of local minima (exactly flat: no highlight reaches the camera).
/// Finer than [`PLATEAU`]: at the bottom of a basin under 2% noise, neighbouring nodes of
/// a dielectric over a diffuse albedo differed by less than 1e-3 of the loss, and a minimum
/// with both sides flat at that tolerance left the profile without one.
const FLAT: f64 = 1e-9;

/// A basin of the profile is searched when its lowest node's loss is within this factor of the
/// lowest node's. On the ring-light set above the true basin's profile was 1.33e-2 against the
/// rough basin's 1.66e-2 (both include the photos' noise): close enough that only a local
/// search tells them apart. A basin many times worse cannot win.
const BASIN_LOSS_RATIO: f64 = 1.5;

/// At most this many basins are searched.
pub const MAX_BASINS: usize = 3;

/// At most this many local minima of the profile are refined and, with a projection, searched
/// by Brent's method before the basins are chosen.
const MAX_MINIMA: usize = 4;

/// Start edge tint of conductor fits (Gulbrandsen's g): measured metals lie between 0.85 and
/// 0.99 (Cu, Au, Ag, Al at 450-650 nm), and for F0 above ~0.9 photos constrain g only weakly, so
/// the start is where an unconstrained g should stay.
const START_EDGE_TINT: f64 = 0.9;

/// Brent's tolerance in `ln alpha` when the projected loss is only an approximation (degree 4
/// in F0: `kulla-conty` and the stochastic models): the joint search that follows refines the
/// roughness anyway, and each of Brent's steps costs five renders. With the exact projection's
/// 1.5e-8 the start of a bitterli fit of copper-flash took 28 steps; with this, 9.
const APPROXIMATE_LN_ALPHA_TOLERANCE: f64 = 1e-4;

/// Particles and iterations of the swarm (600 evaluations).
const PSO_PARTICLES: usize = 20;
const PSO_ITERATIONS: u64 = 30;

/// The box of the global phases, in coordinates: alpha in [0.005, 2.5], colour logits in
/// [-5, 5] (F0 in [0.007, 0.993]), diffuse logits in [-7, 0] (albedo in [0.001, 0.5]),
/// exposure in [0.01, 100].
pub fn search_box(space: &ParamSpace) -> (Vec<f64>, Vec<f64>) {
    let roughness = if space.anisotropic { 2 } else { 1 };
    let colour = match (space.known_fresnel, space.fresnel) {
        (Some(_), _) => 0,
        (None, FresnelFamily::Schlick) => 3,
        (None, FresnelFamily::Conductor) => 6,
    };
    let mut lower = vec![0.005f64.ln(); roughness];
    let mut upper = vec![2.5f64.ln(); roughness];
    lower.extend(vec![-5.0; colour]);
    upper.extend(vec![5.0; colour]);
    if space.diffuse {
        lower.extend([-7.0; 3]);
        upper.extend([0.0; 3]);
    }
    if space.exposure {
        lower.push(0.01f64.ln());
        upper.push(100.0f64.ln());
    }
    (lower, upper)
}

/// `count` uniform draws in the search box, from the seed's own stream.
pub fn random_points(space: &ParamSpace, seed: u64, count: usize) -> Vec<Vec<f64>> {
    let (lower, upper) = search_box(space);
    let mut rng = rng_stream(seed, u64::MAX - 1);
    (0..count)
        .map(|_| {
            lower
                .iter()
                .zip(&upper)
                .map(|(lo, hi)| rng.random_range(*lo..*hi))
                .collect()
        })
        .collect()
}

/// The loss over roughness that the global phase reads, at the nodes it has evaluated: the
/// coarse grid [`COARSE_ALPHAS`] over the whole fitted range, refined by halving wherever the
/// loss comes within [`REFINE_LOSS_RATIO`] of its lowest value, down to [`PROFILE_RATIO`],
/// except on plateaus ([`PLATEAU`]).
pub struct Profile {
    /// `(ln alpha, loss)`, in increasing `ln alpha`.
    pub nodes: Vec<(f64, f64)>,
}

impl Profile {
    /// The profile of `loss` (a function of `ln alpha`).
    pub fn of(loss: impl Fn(f64) -> f64) -> Profile {
        let mut profile = Profile {
            nodes: COARSE_ALPHAS
                .iter()
                .map(|a| (a.ln(), loss(a.ln())))
                .collect(),
        };
        let finest = PROFILE_RATIO.ln();
        loop {
            let nodes = &profile.nodes;
            let lowest = nodes.iter().map(|n| n.1).fold(f64::INFINITY, f64::min);
            let minima = profile.local_minima();
            let mut refined = Vec::with_capacity(2 * nodes.len());
            for (i, pair) in nodes.windows(2).enumerate() {
                refined.push(pair[0]);
                let (a, b) = (pair[0], pair[1]);
                let plateau = (a.1 - b.1).abs() <= PLATEAU * lowest.abs();
                let near_lowest = a.1.min(b.1) <= REFINE_LOSS_RATIO * lowest;
                let beside_minimum = minima.contains(&i) || minima.contains(&(i + 1));
                if b.0 - a.0 > finest && !plateau && (near_lowest || beside_minimum) {
                    let mid = 0.5 * (a.0 + b.0);
                    refined.push((mid, loss(mid)));
                }
            }
            refined.push(nodes[nodes.len() - 1]);
            if refined.len() == nodes.len() {
                return profile;
            }
            profile.nodes = refined;
        }
    }

    /// The nodes lower than both neighbours (or than their one neighbour at an end), except
    /// on an exactly flat stretch ([`FLAT`]: a sample so smooth that no highlight reaches the
    /// camera), lowest first, at most [`MAX_MINIMA`]; the lowest node at least.
    pub fn local_minima(&self) -> Vec<usize> {
        let n = self.nodes.len();
        let loss = |i: usize| self.nodes[i].1;
        let lowest = (0..n).map(loss).fold(f64::INFINITY, f64::min);
        let flat = |i: usize, j: usize| (loss(i) - loss(j)).abs() <= FLAT * lowest.abs();
        let mut minima: Vec<usize> = (0..n)
            .filter(|&i| {
                let left = i == 0 || loss(i) <= loss(i - 1);
                let right = i + 1 == n || loss(i) < loss(i + 1);
                let steep = (i > 0 && !flat(i, i - 1)) || (i + 1 < n && !flat(i, i + 1));
                left && right && steep
            })
            .collect();
        minima.sort_by(|&a, &b| loss(a).total_cmp(&loss(b)));
        minima.truncate(MAX_MINIMA);
        if minima.is_empty() {
            let argmin = (0..n).min_by(|&a, &b| loss(a).total_cmp(&loss(b)));
            minima.extend(argmin);
        }
        minima
    }

    /// The basins worth a local search: the [`Profile::local_minima`] whose loss is within
    /// [`BASIN_LOSS_RATIO`] of the lowest node's, lowest first, at most [`MAX_BASINS`].
    pub fn basins(&self) -> Vec<usize> {
        let lowest = self.nodes.iter().map(|n| n.1).fold(f64::INFINITY, f64::min);
        let mut basins = self.local_minima();
        basins.retain(|&i| self.nodes[i].1 <= BASIN_LOSS_RATIO * lowest);
        basins.truncate(MAX_BASINS);
        basins
    }

    /// `[alpha, loss]` of every node, for the fit file.
    pub fn table(&self) -> Vec<[f64; 2]> {
        self.nodes
            .iter()
            .map(|&(ln, loss)| [ln.exp(), loss])
            .collect()
    }

    /// The `ln alpha` of the neighbours of node `i` (the node itself at an end).
    fn bracket(&self, i: usize) -> (f64, f64) {
        let last = self.nodes.len() - 1;
        (
            self.nodes[i.saturating_sub(1)].0,
            self.nodes[(i + 1).min(last)].0,
        )
    }
}

/// The scan's squared error at roughness `alpha` and the per-channel scale that minimises it:
/// the white-Fresnel prediction (or the known Fresnel's), scaled per channel by the
/// least-squares factor `sum p t / sum p^2`. With a known Fresnel one factor common to the
/// channels is the exposure when it is fitted (`--fit-exposure`), none otherwise.
fn scan_error(objective: &Objective, alpha: f64) -> (f64, [f64; 3]) {
    let space = objective.space;
    let records = objective.records();
    let pixels = objective.pixels();
    let probe = Material {
        model: space.model,
        ndf: space.ndf,
        height: space.height,
        alpha: [alpha; 2],
        fresnel: space.known_fresnel.unwrap_or(FresnelSpec::White),
        diffuse: [0.0; 3],
    };
    let predicted = objective.render(&probe, objective.seed());
    let mut sums = [[0.0; 3]; 3];
    for (c, [pt, pp, tt]) in sums.iter_mut().enumerate() {
        for (k, &p) in pixels.iter().enumerate() {
            let (w, t, q) = (records.weight[p], records.target[p][c], predicted[k][c]);
            *pt += w * q * t;
            *pp += w * q * q;
            *tt += w * t * t;
        }
    }
    let ratio = |pt: f64, pp: f64| if pp > 0.0 { pt / pp } else { 0.0 };
    let scale = if space.known_fresnel.is_some() && !space.exposure {
        // The Fresnel and the exposure are both known: the probe's brightness is the
        // prediction's. (A free factor here let a rough probe stand in for a smooth one:
        // `tabulated` on heitz photos of white alpha 0.5 started at 2.38 and stopped in a
        // local minimum at 1.06.)
        [1.0; 3]
    } else if space.known_fresnel.is_some() {
        let common = ratio(
            sums.iter().map(|s| s[0]).sum(),
            sums.iter().map(|s| s[1]).sum(),
        );
        [common; 3]
    } else {
        sums.map(|[pt, pp, _]| ratio(pt, pp))
    };
    let err = (0..3)
        .map(|c| {
            let [pt, pp, tt] = sums[c];
            tt - 2.0 * scale[c] * pt + scale[c] * scale[c] * pp
        })
        .sum();
    (err, scale)
}

/// The scan's start coordinates at roughness `alpha` with the channel scales `scale`: a
/// Schlick F0 (or a conductor of edge tint [`START_EDGE_TINT`]) of the scales, or the known
/// Fresnel with the common scale as the exposure.
fn scan_point(objective: &Objective, alpha: f64, scale: [f64; 3]) -> Vec<f64> {
    let space = objective.space;
    let f0 = scale.map(|s| s.clamp(0.02, 0.98));
    let fresnel = match (space.known_fresnel, space.fresnel) {
        (Some(known), _) => known,
        (None, FresnelFamily::Schlick) => FresnelSpec::Schlick { f0 },
        (None, FresnelFamily::Conductor) => {
            let ior = f0.map(|r| ior_from_reflectivity_edge_tint(r, START_EDGE_TINT));
            FresnelSpec::Conductor {
                eta: ior.map(|p| p.0),
                k: ior.map(|p| p.1),
            }
        }
    };
    let material = Material {
        model: space.model,
        ndf: space.ndf,
        height: space.height,
        alpha: [alpha; 2],
        fresnel,
        diffuse: if space.diffuse { [0.02; 3] } else { [0.0; 3] },
    };
    let exposure = if space.known_fresnel.is_some() && scale[0] > 0.0 {
        scale[0]
    } else {
        1.0
    };
    space.point(&material, exposure)
}

/// The scan starts: the [`Profile`] of [`scan_error`], and a start at each of its basins.
pub fn scan_starts(objective: &Objective) -> (Vec<Vec<f64>>, Profile) {
    let profile = Profile::of(|ln| scan_error(objective, ln.exp()).0);
    let starts = profile
        .basins()
        .into_iter()
        .map(|i| {
            let alpha = profile.nodes[i].0.exp();
            scan_point(objective, alpha, scan_error(objective, alpha).1)
        })
        .collect();
    (starts, profile)
}

/// The projected loss as an argmin cost over roughness coordinates (a vector, or one scalar).
struct Projected<'p, 'o, 'r>(&'p Projection<'o, 'r>);

impl CostFunction for Projected<'_, '_, '_> {
    type Param = Vec<f64>;
    type Output = f64;
    fn cost(&self, roughness: &Vec<f64>) -> Result<f64, ArgminError> {
        Ok(self.0.solve(roughness).0)
    }
}

/// The projected loss on the diagonal of the roughness coordinates, as a function of one
/// `ln alpha`.
struct ProjectedScalar<'p, 'o, 'r>(&'p Projection<'o, 'r>);

impl CostFunction for ProjectedScalar<'_, '_, '_> {
    type Param = f64;
    type Output = f64;
    fn cost(&self, ln_alpha: &f64) -> Result<f64, ArgminError> {
        Ok(self.0.solve(&vec![*ln_alpha; self.0.roughness_dim]).0)
    }
}

/// `ln alpha` tolerance of the Brent search that screens every local minimum of the profile
/// before the competing ones are searched to the projection's own tolerance.
const SCREENING_LN_ALPHA_TOLERANCE: f64 = 1e-3;

/// The minimum of the projected loss over isotropic roughness (the diagonal, when anisotropic)
/// between `lo` and `hi`, around the node `(ln, loss)`, to `tolerance` in `ln alpha`:
/// `(loss, ln alpha)`. A node at an end of the range is its own answer: the loss falls toward
/// the end, and the local search goes on from there (the box holds it at the bound).
fn brent_in(
    projection: &Projection,
    (lo, hi): (f64, f64),
    (ln, loss): (f64, f64),
    tolerance: f64,
) -> Result<(f64, f64), ArgminError> {
    if !(lo < ln && ln < hi) {
        return Ok((loss, ln));
    }
    let solver = BrentOpt::new(lo, hi).set_tolerance(tolerance, 1e-10);
    let res = Executor::new(ProjectedScalar(projection), solver)
        .configure(|s| s.max_iters(100))
        .run()?;
    Ok(match res.state.get_best_param() {
        Some(&x) if res.state.get_best_cost() < loss => (res.state.get_best_cost(), x),
        _ => (loss, ln),
    })
}

/// The projected starts: the [`Profile`] of the projected loss (isotropic roughness); every
/// local minimum of it screened by Brent's method between its neighbours; in each screened
/// minimum within [`BASIN_LOSS_RATIO`] of the lowest (at most [`MAX_BASINS`]) the projected
/// minimum to the projection's tolerance (isotropic) or by Nelder-Mead from it (anisotropic);
/// full coordinates, the lowest basin first.
///
/// Every local minimum is screened, not only the nodes near the lowest: on `heitz` flash
/// photos of copper at alpha 0.5 (32x32, Schlick F0) the true basin is so narrow that its
/// nodes 0.408 and 0.735 read 5.9 and 6.3 times the loss at 2.95, whose rough basin ends 18%
/// above the true optimum; Brent between 0.408's neighbours finds the true one.
pub fn projected_starts(projection: &Projection) -> Result<(Vec<Vec<f64>>, Profile), ArgminError> {
    let dim = projection.roughness_dim;
    let profile = Profile::of(|ln| projection.solve(&vec![ln; dim]).0);
    let lowest_node = profile
        .nodes
        .iter()
        .map(|n| n.1)
        .fold(f64::INFINITY, f64::min);
    let mut screened = Vec::new();
    for node in profile.local_minima() {
        let bracket = profile.bracket(node);
        let (ln, loss) = profile.nodes[node];
        // A minimum whose node already competes is searched to the full tolerance below
        // anyway; only the others are screened, since only Brent can show them deeper.
        let (loss, ln) = if loss <= BASIN_LOSS_RATIO * lowest_node {
            (loss, ln)
        } else {
            brent_in(
                projection,
                bracket,
                (ln, loss),
                SCREENING_LN_ALPHA_TOLERANCE,
            )?
        };
        screened.push((loss, ln, bracket));
    }
    screened.sort_by(|a, b| a.0.total_cmp(&b.0));
    let lowest = screened.first().map_or(f64::INFINITY, |s| s.0);
    screened.retain(|s| s.0 <= BASIN_LOSS_RATIO * lowest);
    screened.truncate(MAX_BASINS);
    let tolerance = if projection.is_exact() {
        1.5e-8
    } else {
        APPROXIMATE_LN_ALPHA_TOLERANCE
    };
    let mut starts = Vec::new();
    for (loss, ln, (lo, hi)) in screened {
        let roughness = if dim == 1 {
            // A screened minimum is refined within the screening's tolerance of its answer.
            let near = (
                (ln - 4.0 * SCREENING_LN_ALPHA_TOLERANCE).max(lo),
                (ln + 4.0 * SCREENING_LN_ALPHA_TOLERANCE).min(hi),
            );
            let on_node = profile.nodes.iter().any(|n| n.0 == ln);
            let inner = if !on_node && near.0 < ln && ln < near.1 {
                near
            } else {
                (lo, hi)
            };
            vec![brent_in(projection, inner, (ln, loss), tolerance)?.1]
        } else {
            let centre = vec![ln; dim];
            let solver = NelderMead::new(simplex_around(&centre)).with_sd_tolerance(1e-12)?;
            let res = Executor::new(Projected(projection), solver)
                .configure(|s| s.max_iters(200))
                .run()?;
            res.state.get_best_param().cloned().unwrap_or(centre)
        };
        starts.push(projection.solve(&roughness).1);
    }
    Ok((starts, profile))
}

/// The particle swarm start over all coordinates, seeded by the fit's seed.
pub fn swarm_start(objective: &Objective, seed: u64) -> Result<Vec<f64>, ArgminError> {
    let solver = ParticleSwarm::new(search_box(&objective.space), PSO_PARTICLES)
        .with_rng_generator(rng_stream(seed, u64::MAX - 2));
    let res = Executor::new(objective, solver)
        .configure(|s| s.max_iters(PSO_ITERATIONS))
        .run()?;
    let best = res
        .state
        .get_best_param()
        .map(|p| p.position.clone())
        .expect("the swarm has particles");
    Ok(best)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A loss over `ln alpha` with a broad, shallow basin at `broad` and a narrow, deep one at
    /// `narrow` (width `width` in `ln alpha`), above a floor of 1.
    fn two_basins(broad: f64, narrow: f64, width: f64) -> impl Fn(f64) -> f64 {
        move |ln: f64| {
            2.0 - 0.8 * (-((ln - broad.ln()) / 1.0).powi(2)).exp()
                - 1.0 * (-((ln - narrow.ln()) / width).powi(2)).exp()
        }
    }

    /// The ring-light case's shape: a narrow basin between two coarse nodes (0.408 and 0.735)
    /// that both lie above a broad, rough basin. The coarse grid alone sees only the rough one;
    /// the refined profile finds the narrow one and ranks it first.
    #[test]
    fn the_profile_finds_a_basin_narrower_than_the_coarse_grid() {
        let loss = two_basins(1.4, 0.52, 0.12);
        let coarse: Vec<f64> = COARSE_ALPHAS.iter().map(|a| loss(a.ln())).collect();
        let lowest = (0..coarse.len())
            .min_by(|&a, &b| coarse[a].total_cmp(&coarse[b]))
            .unwrap();
        assert!(
            COARSE_ALPHAS[lowest] > 1.0,
            "the coarse grid alone picks the rough basin"
        );
        let profile = Profile::of(&loss);
        let basins = profile.basins();
        let first = profile.nodes[basins[0]].0.exp();
        assert!((first / 0.52 - 1.0).abs() < 0.1, "first basin at {first}");
        assert!(
            basins
                .iter()
                .any(|&b| (profile.nodes[b].0.exp() / 1.4 - 1.0).abs() < 0.2),
            "the rough basin is kept as a second start: {:?}",
            basins
                .iter()
                .map(|&b| profile.nodes[b].0.exp())
                .collect::<Vec<_>>()
        );
        // Nodes stay sorted, and the refinement reached the finest spacing near the best.
        assert!(profile.nodes.windows(2).all(|w| w[0].0 < w[1].0));
        let (lo, hi) = profile.bracket(basins[0]);
        assert!(hi - lo <= 2.0 * PROFILE_RATIO.ln() + 1e-12);
    }

    /// The `heitz` flash case's shape: a narrow, deep basin at 0.5 whose coarse nodes read more
    /// than 2.5 times the loss of a rough basin near the top of the range. The coarse node
    /// 0.408 is a local minimum, so its intervals are refined, and a node within 10% of 0.5
    /// becomes a competing basin (Brent's method then screens it, [`projected_starts`]).
    #[test]
    fn the_profile_refines_around_every_local_minimum() {
        let loss = |ln: f64| {
            let broad = 1.0 + 2.0 * (ln - 2.9f64.ln()).powi(2);
            let narrow = 0.85 + 60.0 * (ln - 0.5f64.ln()).powi(2);
            broad.min(narrow)
        };
        let at = |a: f64| loss(a.ln());
        assert!(at(0.408) > REFINE_LOSS_RATIO * at(2.95) && at(0.735) > at(0.408));
        let profile = Profile::of(loss);
        let minima: Vec<f64> = profile
            .local_minima()
            .iter()
            .map(|&i| profile.nodes[i].0.exp())
            .collect();
        assert!(
            minima.iter().any(|a| (a / 0.5 - 1.0).abs() < 0.1),
            "the deep basin is a local minimum to screen: {minima:?}"
        );
        assert!(profile.basins().len() >= 2, "and competes after refinement");
    }

    /// A basin far worse than the best is not searched, and the number of searched basins is
    /// bounded.
    #[test]
    fn only_competing_basins_are_searched() {
        let far = |ln: f64| {
            let d = (ln - 0.3f64.ln()).powi(2);
            // Deep minimum at 0.3; ripples elsewhere that never come within 1.5x of it.
            0.01 + d + 0.2 * (5.0 * ln).cos().abs()
        };
        let profile = Profile::of(far);
        let basins = profile.basins();
        let lowest = profile
            .nodes
            .iter()
            .map(|n| n.1)
            .fold(f64::INFINITY, f64::min);
        assert!(!basins.is_empty() && basins.len() <= MAX_BASINS);
        for &b in &basins {
            assert!(profile.nodes[b].1 <= BASIN_LOSS_RATIO * lowest);
        }
        // A flat profile is a plateau: nothing to refine, one basin at its end.
        let flat = Profile::of(|_| 1.0);
        assert_eq!(flat.nodes.len(), COARSE_ALPHAS.len());
        assert_eq!(
            flat.basins().len(),
            1,
            "a flat profile still gives one start"
        );
        // A basin whose bottom changes by less than the plateau tolerance between nodes (a
        // noisy dielectric over a diffuse albedo) is still a minimum: the coarse node nearest
        // it, from which Brent's method searches.
        let gentle_bottom = Profile::of(|ln: f64| 1.0 + 1e-5 * (ln - 0.3f64.ln()).powi(2));
        let first = gentle_bottom.nodes[gentle_bottom.basins()[0]].0.exp();
        assert!((first / 0.3).ln().abs() <= 0.5 * 1.8f64.ln(), "{first}");
        // A profile that keeps falling gently is refined near its lowest end only, and every
        // interval at most three times: bounded work.
        let gentle = Profile::of(|ln: f64| 2.0 - 0.05 * ln);
        assert!(gentle.nodes.len() <= 8 * COARSE_ALPHAS.len());
    }

    /// The coarse grid spans the fitted range and avoids round values.
    #[test]
    fn the_coarse_grid_spans_the_fitted_range() {
        let (lo, hi) = super::super::params::ALPHA_BOUNDS;
        assert!(COARSE_ALPHAS[0] < 1.2e-3 && COARSE_ALPHAS[0] > lo);
        assert!(COARSE_ALPHAS[COARSE_ALPHAS.len() - 1] < hi);
        assert!(COARSE_ALPHAS[COARSE_ALPHAS.len() - 1] > 0.95 * hi);
        for a in COARSE_ALPHAS {
            for round in [
                0.01, 0.05, 0.1, 0.2, 0.25, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0, 1.5, 2.0,
            ] {
                assert!((a / round - 1.0).abs() > 1e-3, "{a} is a round value");
            }
        }
    }
}

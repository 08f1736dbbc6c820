//! Where a fit starts: the global phase before the local search.
//!
//! | method | when | what |
//! | --- | --- | --- |
//! | `projection` | Schlick Fresnel and a squared-error loss (the default fits) | the projected loss ([`super::projection`]) over roughness only: the roughness scan below, then Brent's method (isotropic) or Nelder-Mead (anisotropic) around the best node |
//! | `pso` | `--optimizer pso` | argmin's particle swarm over the box [`search_box`] of all coordinates, with a seeded generator |
//! | `scan` | otherwise | the roughness scan with a white Fresnel whose per-channel scale is solved in closed form; conductors start at edge tint [`START_EDGE_TINT`]; with a known Fresnel, the scan renders it and one scale common to the channels is the start exposure |
//! | random | `--starts N`, for starts 2..N | uniform draws in [`search_box`], seeded |

use super::local::simplex_around;
use super::objective::Objective;
use super::params::{FresnelFamily, ParamSpace};
use super::projection::Projection;
use crate::albedo::rng_stream;
use crate::material::{FresnelSpec, Material};
use crate::microfacet::fresnel::ior_from_reflectivity_edge_tint;
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

/// Roughness values of the coarse start scan: a geometric grid (ratio 1.8) from 0.012 to 2.4
/// that avoids round values, so fits of synthetic sets made at round roughness exercise the
/// optimiser rather than land on a scan node.
const SCAN_ALPHAS: [f64; 10] = [
    0.012, 0.0216, 0.0389, 0.07, 0.126, 0.227, 0.408, 0.735, 1.32, 2.38,
];

/// [`SCAN_ALPHAS`], with their geometric midpoints when `fine` (ratio 1.34).
fn scan_alphas(fine: bool) -> Vec<f64> {
    if fine {
        SCAN_ALPHAS
            .windows(2)
            .flat_map(|w| [w[0], (w[0] * w[1]).sqrt()])
            .chain([SCAN_ALPHAS[SCAN_ALPHAS.len() - 1]])
            .collect()
    } else {
        SCAN_ALPHAS.to_vec()
    }
}

/// Start edge tint of conductor fits (Gulbrandsen's g): measured metals lie between 0.85 and
/// 0.99 (Cu, Au, Ag, Al at 450-650 nm), and for F0 above ~0.9 photos constrain g only weakly, so
/// the start is where an unconstrained g should stay.
const START_EDGE_TINT: f64 = 0.9;

/// Brent's tolerance in `ln alpha` when the projected loss is only an approximation (degree 4
/// in F0: `kulla-conty` and the stochastic models): the joint search that follows refines the
/// roughness anyway, and each of Brent's steps costs five renders. With the exact projection's
/// 1.5e-8 the start of a bitterli fit of copper-flash took 28 steps; with this, 9.
const APPROXIMATE_LN_ALPHA_TOLERANCE: f64 = 1e-4;

/// The second-lowest basin of the projected start's scan is searched only when its node's
/// loss is within this factor of the lowest node's. The case it is searched for had the two
/// within 3% (see [`projected_start`]); a basin many times worse cannot win, and searching it
/// is not free: on copper-flash, `turquin`'s second basin was the scan's last node (loss 0.61
/// against 3.5e-7), and Brent's method crawled 36 steps toward the end of its bracket, 108 of
/// the fit's 177 renders.
const SECOND_BASIN_LOSS_RATIO: f64 = 2.0;

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

/// The scan start and its exposure: the node alpha whose white-Fresnel prediction, scaled per
/// channel by the least-squares factor `sum p t / sum p^2`, has the lowest squared error. With
/// a known Fresnel the probe has it, and one factor common to the channels is the exposure when
/// it is fitted (`--fit-exposure`), none otherwise.
pub fn scan_start(objective: &Objective) -> (Material, f64) {
    let space = objective.space;
    let records = objective.records();
    let pixels = objective.pixels();
    let mut best: Option<(f64, f64, [f64; 3])> = None;
    // Known Fresnel and exposure fix the probe's brightness, which makes the error sharper in
    // alpha: on the 1.8x grid a node next to the truth can lose to a much rougher one of the
    // same energy (`kulla-conty` on heitz photos of white alpha 0.5 picked 1.32 and stopped at
    // 1.58), so the grid gains its geometric midpoints (ratio 1.34).
    let fixed_brightness = space.known_fresnel.is_some() && !space.exposure;
    for alpha in scan_alphas(fixed_brightness) {
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
        let scale = if fixed_brightness {
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
        let err: f64 = (0..3)
            .map(|c| {
                let [pt, pp, tt] = sums[c];
                tt - 2.0 * scale[c] * pt + scale[c] * scale[c] * pp
            })
            .sum();
        if best.is_none_or(|b| err < b.0) {
            best = Some((err, alpha, scale));
        }
    }
    let (_, alpha, scale) = best.expect("the scan has points");
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
    (material, exposure)
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

struct ProjectedScalar<'p, 'o, 'r>(&'p Projection<'o, 'r>);

impl CostFunction for ProjectedScalar<'_, '_, '_> {
    type Param = f64;
    type Output = f64;
    fn cost(&self, ln_alpha: &f64) -> Result<f64, ArgminError> {
        Ok(self.0.solve(&[*ln_alpha]).0)
    }
}

/// Whether the projected loss halfway from the edge node `node` of the scan to its inner
/// neighbour is below the node's, so that a minimum lies inside the grid's end interval.
///
/// An edge node is a basin of the scan only in that the loss falls toward the end of the grid,
/// and where it keeps falling Brent's method crawls to the interval's end in golden sections:
/// on the three real captures in `../shared/data/real` (`--depth 0.1`) the scan's last node,
/// alpha 2.38, was a basin for `tabulated` and `kulla-conty`, and Brent spent 17 steps (51
/// renders, 0.6-0.9 s) to return a loss no lower than the node's. One probe tells the cases
/// apart.
fn dips_inside(projection: &Projection, ln: &[f64], scan: &[f64], node: usize) -> bool {
    let inner = if node == 0 { 1 } else { node - 1 };
    let halfway = 0.5 * (ln[node] + ln[inner]);
    let dim = projection.roughness_dim;
    projection.solve(&vec![halfway; dim]).0 < scan[node]
}

/// The projected start: full coordinates of the best projected solve.
pub fn projected_start(projection: &Projection) -> Result<Vec<f64>, ArgminError> {
    let ln: Vec<f64> = SCAN_ALPHAS.iter().map(|a| a.ln()).collect();
    let dim = projection.roughness_dim;
    let scan: Vec<f64> = ln
        .iter()
        .map(|&l| projection.solve(&vec![l; dim]).0)
        .collect();
    let best = (0..ln.len())
        .min_by(|&a, &b| scan[a].total_cmp(&scan[b]))
        .expect("the scan has points");
    let roughness = if dim == 1 {
        // The two lowest basins of the scan are searched (the second only when it competes,
        // [`SECOND_BASIN_LOSS_RATIO`]): with F0 solved at every
        // node a flash set can hold a rough basin within a few percent of the true one
        // (`tabulated` on heitz photos of copper at alpha 0.5: 0.0304 at alpha 2.38 against
        // 0.0296 near 0.5), and the nodes beside the truth, 1.8x off it, lost to the rough one.
        let mut basins: Vec<usize> = (0..ln.len())
            .filter(|&i| {
                (i == 0 || scan[i] <= scan[i - 1]) && (i + 1 == ln.len() || scan[i] <= scan[i + 1])
            })
            .collect();
        basins.sort_by(|&a, &b| scan[a].total_cmp(&scan[b]));
        let mut found: Option<(f64, f64)> = None;
        let competes = |node: usize| {
            scan[node] - scan[best] <= (SECOND_BASIN_LOSS_RATIO - 1.0) * scan[best].abs()
        };
        for &node in basins.iter().take(2).filter(|&&node| competes(node)) {
            let (lo, hi) = (ln[node.saturating_sub(1)], ln[(node + 1).min(ln.len() - 1)]);
            if (node == 0 || node + 1 == ln.len()) && !dips_inside(projection, &ln, &scan, node) {
                // The loss falls toward the end of the grid: Brent's interval ends at the node
                // and it would crawl to that end; the local search goes on from the node.
                if found.is_none_or(|f| scan[node] < f.0) {
                    found = Some((scan[node], ln[node]));
                }
                continue;
            }
            let solver = if projection.is_exact() {
                BrentOpt::new(lo, hi).set_tolerance(1.5e-8, 1e-10)
            } else {
                BrentOpt::new(lo, hi).set_tolerance(APPROXIMATE_LN_ALPHA_TOLERANCE, 0.0)
            };
            let res = Executor::new(ProjectedScalar(projection), solver)
                .configure(|s| s.max_iters(100))
                .run()?;
            let x = *res.state.get_best_param().unwrap_or(&ln[node]);
            let candidate = if scan[node] < res.state.get_best_cost() {
                (scan[node], ln[node])
            } else {
                (res.state.get_best_cost(), x)
            };
            if found.is_none_or(|f| candidate.0 < f.0) {
                found = Some(candidate);
            }
        }
        vec![found.map_or(ln[best], |f| f.1)]
    } else {
        let centre = vec![ln[best]; dim];
        let solver = NelderMead::new(simplex_around(&centre)).with_sd_tolerance(1e-12)?;
        let res = Executor::new(Projected(projection), solver)
            .configure(|s| s.max_iters(200))
            .run()?;
        res.state.get_best_param().cloned().unwrap_or(centre)
    };
    Ok(projection.solve(&roughness).1)
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

/// Start coordinates of the scan start.
pub fn scan_point(objective: &Objective) -> Vec<f64> {
    let (material, exposure) = scan_start(objective);
    objective.space.point(&material, exposure)
}

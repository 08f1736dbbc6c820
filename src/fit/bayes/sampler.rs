//! A product-space Markov chain over (model, coordinates): preconditioned MALA within a model,
//! Metropolis-Hastings (reversible jump where dimensions differ) between models.
//!
//! | move | proposal | acceptance |
//! | --- | --- | --- |
//! | within model `m` | `x' = x + h^2/2 S g(x) + h R^-T xi`, `xi ~ N(0, I)`, `S = H^-1` of the model's [`Laplace`] approximation, `g = grad ln p` (Roberts and Tweedie 1996; Girolami and Calderhead 2011, eq. 9, constant metric) | `p(x') q(x given x') / (p(x) q(x' given x))` |
//! | between modes of one model | from the mode `i` nearest to `x` ([`Laplace::nearest`]), mode `j` uniform among the others; `x' = mu_j + R_j^-T R_i^T (x - mu_i)` (a deterministic Laplace-matched jump between modes, after the mode-jumping proposals of Tjelmeland and Hegstad 2001) | `p_m(x') / p_m(x) * det(R_i) / det(R_j)` if `j` is the mode nearest to `x'` (so the reverse jump is proposed with the same probability), else rejected |
//! | between models | `m'` uniform among the other candidates; `z = R_m^T (x - mu_m)`, padded with `u ~ N(0, I)` or cut to the new dimension, `x' = mu_m' + R_m'^-T z'`, through each model's first mode (Green 1995; the Laplace-matched jump of Hastie and Green 2012, section 3) | `p_m'(x') / p_m(x) * det(R_m) / det(R_m')`, times `N(u)` of the dropped and divided by `N(u)` of the drawn standard coordinates |
//!
//! Model priors are uniform over the candidates (so `p_m` is the unnormalised joint density of
//! data and parameters under model `m`). Each iteration makes one within-model move, with more
//! than one mode one between-mode move, and with more than one candidate one between-model move.
//!
//! Modes: a candidate may carry Laplace approximations at several modes of its density (the
//! basins the point fit found, [`crate::fit::point::Alternative`]); MALA alone would stay in
//! the basin it starts in. MALA is preconditioned by the mode nearest to its current point, and
//! its reverse proposal by the mode nearest to the proposed one (with the normalisers of both
//! proposal densities), so the metric depends on the point and the move stays reversible.

//! Step size `h` per model and chain: during warm-up `ln h += (a - 0.574) / (t + 3)^0.6` after
//! each within-model move with acceptance probability `a` (Robbins-Monro toward the optimal MALA
//! acceptance of Roberts and Rosenthal 1998), then frozen, so the kept draws come from a
//! time-homogeneous chain. Starting `h = 1` (optimal for a perfectly preconditioned Gaussian is
//! about `1.65 d^-1/6`).
//!
//! Why MALA rather than HMC: with finite-difference gradients a gradient costs `2d` image
//! evaluations, so a MALA iteration costs `2d + 1` and an HMC trajectory of `L` leapfrog steps
//! `L (2d + 1)`. Preconditioned by the Laplace covariance, the posteriors here are close to
//! Gaussian and MALA already keeps 0.38 effective draws per draw (copper-flash: bulk ESS 768 of
//! 2000 draws, acceptance 0.55); HMC cannot exceed about 1 per draw, so with `L >= 3` it would
//! give fewer effective draws per second. (Not measured with an HMC implementation.)
//!
//! Random numbers: iteration `i` of chain `c` draws from its own stream
//! `rng_stream(seed, c 2^40 + i)`, so the chain state alone (no generator state) determines the
//! rest of the run, and a run resumed from a checkpoint repeats an uninterrupted one exactly.

use super::laplace::Laplace;
use super::target::Target;
use crate::random::rng_stream;
use crate::random::Rng;
use rand::Rng as _;
use rand_distr::StandardNormal;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Target acceptance probability of MALA during warm-up.
pub const TARGET_ACCEPTANCE: f64 = 0.574;

/// One candidate model of the product space: its density and its Laplace approximations, at
/// its MAP first and then at any other mode.
pub struct Candidate<'t> {
    pub target: &'t dyn Target,
    pub modes: Vec<Laplace>,
}

impl Candidate<'_> {
    /// The approximation at the MAP: the one between-model jumps use.
    pub fn laplace(&self) -> &Laplace {
        &self.modes[0]
    }
}

/// A kept draw.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Draw {
    pub model: usize,
    pub x: Vec<f64>,
}

/// Proposed and accepted moves (counted after warm-up).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Counts {
    pub proposed: u64,
    pub accepted: u64,
}

impl Counts {
    fn record(&mut self, accepted: bool) {
        self.proposed += 1;
        self.accepted += accepted as u64;
    }

    pub fn rate(&self) -> Option<f64> {
        (self.proposed > 0).then(|| self.accepted as f64 / self.proposed as f64)
    }

    pub fn add(&mut self, other: Counts) {
        self.proposed += other.proposed;
        self.accepted += other.accepted;
    }
}

/// Everything a chain needs to continue: its point, its adaptation and its draws.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ChainState {
    pub model: usize,
    pub x: Vec<f64>,
    pub log_density: f64,
    /// Gradient at `x`, computed when a within-model move needs it.
    pub gradient: Option<Vec<f64>>,
    /// MALA step size per model.
    pub step: Vec<f64>,
    /// Warm-up moves made in each model (the adaptation clock).
    pub adapted: Vec<u64>,
    pub within: Counts,
    pub between: Counts,
    #[serde(default)]
    pub between_modes: Counts,
    /// Completed iterations (warm-up included).
    pub iterations: u64,
    pub draws: Vec<Draw>,
}

/// Run lengths of the sampler.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Schedule {
    pub chains: usize,
    pub warmup: u64,
    /// Kept iterations per chain.
    pub samples: u64,
    pub seed: u64,
}

impl Schedule {
    pub fn total(&self) -> u64 {
        self.warmup + self.samples
    }
}

fn rng(seed: u64, chain: usize, iteration: u64) -> Rng {
    rng_stream(seed, ((chain as u64) << 40) + iteration)
}

fn normals(rng: &mut Rng, n: usize) -> Vec<f64> {
    (0..n).map(|_| rng.sample(StandardNormal)).collect()
}

/// Start of chain `chain`: model `chain mod candidates`, its mode `(chain / candidates) mod
/// modes`, a draw from that mode's Laplace approximation with its standard deviation multiplied
/// by `dispersion`.
pub fn start(candidates: &[Candidate], chain: usize, seed: u64, dispersion: f64) -> ChainState {
    let model = chain % candidates.len();
    let mode = (chain / candidates.len()) % candidates[model].modes.len();
    let mut rng = rng(seed, chain, u64::MAX >> 24);
    let laplace = &candidates[model].modes[mode];
    let z: Vec<f64> = normals(&mut rng, laplace.dim())
        .iter()
        .map(|v| v * dispersion)
        .collect();
    let x = laplace.from_standard(&z);
    ChainState {
        model,
        log_density: candidates[model].target.log_density(&x),
        x,
        gradient: None,
        step: vec![1.0; candidates.len()],
        adapted: vec![0; candidates.len()],
        within: Counts::default(),
        between: Counts::default(),
        between_modes: Counts::default(),
        iterations: 0,
        draws: Vec::new(),
    }
}

/// `ln q(to given from)` of the MALA proposal preconditioned by `laplace`, up to its normaliser
/// (`ln det R - d ln h` plus a constant, which the caller adds when the two directions' metrics
/// differ).
fn mala_log_proposal(laplace: &Laplace, from: &[f64], gradient: &[f64], to: &[f64], h: f64) -> f64 {
    let drift = laplace.precision.solve(gradient);
    let offset: Vec<f64> = (0..from.len())
        .map(|i| to[i] - from[i] - 0.5 * h * h * drift[i])
        .collect();
    let z = laplace.precision.transpose_times(&offset);
    -z.iter().map(|v| v * v).sum::<f64>() / (2.0 * h * h)
}

/// One within-model MALA move; returns the acceptance probability.
fn mala_move(candidate: &Candidate, state: &mut ChainState, rng: &mut Rng) -> (f64, bool) {
    let laplace = &candidate.modes[Laplace::nearest(&candidate.modes, &state.x)];
    let h = state.step[state.model];
    let gradient = state
        .gradient
        .take()
        .unwrap_or_else(|| candidate.target.gradient(&state.x));
    let drift = laplace.precision.solve(&gradient);
    let noise = laplace
        .precision
        .solve_transpose(&normals(rng, laplace.dim()));
    let proposal: Vec<f64> = (0..state.x.len())
        .map(|i| state.x[i] + 0.5 * h * h * drift[i] + h * noise[i])
        .collect();
    let u: f64 = rng.random();
    let proposal_density = candidate.target.log_density(&proposal);
    if !proposal_density.is_finite() {
        state.gradient = Some(gradient);
        return (0.0, false);
    }
    let proposal_gradient = candidate.target.gradient(&proposal);
    let back = &candidate.modes[Laplace::nearest(&candidate.modes, &proposal)];
    let mut log_ratio = proposal_density - state.log_density
        + mala_log_proposal(back, &proposal, &proposal_gradient, &state.x, h)
        - mala_log_proposal(laplace, &state.x, &gradient, &proposal, h);
    if !std::ptr::eq(back, laplace) {
        log_ratio += laplace.log_det_sqrt_covariance() - back.log_det_sqrt_covariance();
    }
    let accept_probability = if log_ratio.is_nan() {
        0.0
    } else {
        log_ratio.min(0.0).exp()
    };
    if u < accept_probability {
        state.x = proposal;
        state.log_density = proposal_density;
        state.gradient = Some(proposal_gradient);
        (accept_probability, true)
    } else {
        state.gradient = Some(gradient);
        (accept_probability, false)
    }
}

/// Uniformly one of `0..n` other than `current`.
fn other_than(current: usize, n: usize, rng: &mut Rng) -> usize {
    let pick = rng.random_range(0..n - 1);
    if pick >= current {
        pick + 1
    } else {
        pick
    }
}

/// One between-mode move within the current model; returns whether it was accepted.
fn mode_jump_move(candidate: &Candidate, state: &mut ChainState, rng: &mut Rng) -> bool {
    let modes = &candidate.modes;
    let from_mode = Laplace::nearest(modes, &state.x);
    let to_mode = other_than(from_mode, modes.len(), rng);
    let (from, to) = (&modes[from_mode], &modes[to_mode]);
    let x = to.from_standard(&from.to_standard(&state.x));
    let density = candidate.target.log_density(&x);
    let log_ratio =
        density - state.log_density + to.log_det_sqrt_covariance() - from.log_det_sqrt_covariance();
    let u: f64 = rng.random();
    let accepted =
        density.is_finite() && u.ln() < log_ratio && Laplace::nearest(modes, &x) == to_mode;
    if accepted {
        state.x = x;
        state.log_density = density;
        state.gradient = None;
    }
    accepted
}

/// One between-model move; returns whether it was accepted.
fn jump_move(candidates: &[Candidate], state: &mut ChainState, rng: &mut Rng) -> bool {
    let target_model = other_than(state.model, candidates.len(), rng);
    let (from, to) = (
        candidates[state.model].laplace(),
        candidates[target_model].laplace(),
    );
    let mut z = from.to_standard(&state.x);
    let log_normal = |u: &[f64]| {
        -u.iter()
            .map(|v| 0.5 * v * v + 0.5 * (2.0 * std::f64::consts::PI).ln())
            .sum::<f64>()
    };
    let mut log_ratio = to.log_det_sqrt_covariance() - from.log_det_sqrt_covariance();
    let (d_from, d_to) = (from.dim(), to.dim());
    if d_to > d_from {
        let u = normals(rng, d_to - d_from);
        log_ratio -= log_normal(&u);
        z.extend(u);
    } else {
        log_ratio += log_normal(&z[d_to..]);
        z.truncate(d_to);
    }
    let x = to.from_standard(&z);
    let density = candidates[target_model].target.log_density(&x);
    log_ratio += density - state.log_density;
    let u: f64 = rng.random();
    let accepted = density.is_finite() && u.ln() < log_ratio;
    if accepted {
        state.model = target_model;
        state.x = x;
        state.log_density = density;
        state.gradient = None;
    }
    accepted
}

/// Advance one chain by one iteration.
pub fn advance(
    candidates: &[Candidate],
    state: &mut ChainState,
    chain: usize,
    schedule: &Schedule,
) {
    let mut rng = rng(schedule.seed, chain, state.iterations);
    let warming = state.iterations < schedule.warmup;
    let model = state.model;
    let (probability, accepted) = mala_move(&candidates[model], state, &mut rng);
    if warming {
        let t = state.adapted[model] as f64;
        state.step[model] *= ((probability - TARGET_ACCEPTANCE) / (t + 3.0).powf(0.6)).exp();
        state.adapted[model] += 1;
    } else {
        state.within.record(accepted);
    }
    if candidates[model].modes.len() > 1 {
        let jumped = mode_jump_move(&candidates[model], state, &mut rng);
        if !warming {
            state.between_modes.record(jumped);
        }
    }
    if candidates.len() > 1 {
        let jumped = jump_move(candidates, state, &mut rng);
        if !warming {
            state.between.record(jumped);
        }
    }
    state.iterations += 1;
    if !warming {
        state.draws.push(Draw {
            model: state.model,
            x: state.x.clone(),
        });
    }
}

/// Advance all chains (in parallel) until `until` iterations or the schedule's end; after each
/// iteration `after` sees the states and may stop the run by returning `false`.
pub fn run(
    candidates: &[Candidate],
    states: &mut [ChainState],
    schedule: &Schedule,
    until: u64,
    mut after: impl FnMut(&[ChainState]) -> bool,
) {
    let end = until.min(schedule.total());
    while states.iter().any(|s| s.iterations < end) {
        states
            .par_iter_mut()
            .enumerate()
            .for_each(|(chain, state)| {
                if state.iterations < end {
                    advance(candidates, state, chain, schedule);
                }
            });
        if !after(states) {
            break;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::bayes::diagnostics::{bulk_ess, split_rhat};

    /// An unnormalised Gaussian `c exp(-(x - m)^T P (x - m) / 2)` with precision `P`.
    struct Gaussian {
        mean: Vec<f64>,
        precision: Vec<f64>,
        log_c: f64,
    }

    impl Target for Gaussian {
        fn dim(&self) -> usize {
            self.mean.len()
        }
        fn log_density(&self, x: &[f64]) -> f64 {
            let g = self.gradient(x);
            self.log_c
                + 0.5
                    * g.iter()
                        .zip(x)
                        .zip(&self.mean)
                        .map(|((g, x), m)| g * (x - m))
                        .sum::<f64>()
        }
        fn gradient(&self, x: &[f64]) -> Vec<f64> {
            let d = self.dim();
            (0..d)
                .map(|i| {
                    -(0..d)
                        .map(|j| self.precision[i * d + j] * (x[j] - self.mean[j]))
                        .sum::<f64>()
                })
                .collect()
        }
    }

    fn sample(candidates: &[Candidate], schedule: &Schedule) -> Vec<ChainState> {
        let mut states: Vec<ChainState> = (0..schedule.chains)
            .map(|c| start(candidates, c, schedule.seed, 2.0))
            .collect();
        run(candidates, &mut states, schedule, u64::MAX, |_| true);
        states
    }

    #[test]
    fn mala_reproduces_mean_and_intervals_of_a_correlated_gaussian() {
        // Covariance [[1, 0.9 * 0.5], [0.9 * 0.5, 0.25]] (sd 1 and 0.5, correlation 0.9).
        let (s1, s2, rho) = (1.0f64, 0.5f64, 0.9f64);
        let det = s1 * s1 * s2 * s2 * (1.0 - rho * rho);
        let target = Gaussian {
            mean: vec![1.0, -2.0],
            precision: vec![
                s2 * s2 / det,
                -rho * s1 * s2 / det,
                -rho * s1 * s2 / det,
                s1 * s1 / det,
            ],
            log_c: 0.0,
        };
        // The Laplace approximation is built by finite differences from a point off the mode, so
        // the Newton step and the Hessian are exercised too; it is then deliberately spoilt
        // (a wrong scale and no correlation), so the sampler has to do the work.
        let mut laplace = Laplace::at_mode(&target, &[0.5, -1.5]);
        assert!((laplace.mean[0] - 1.0).abs() < 1e-6 && (laplace.mean[1] + 2.0).abs() < 1e-6);
        laplace.precision = crate::fit::cholesky::Cholesky::new(&[0.5, 0.0, 0.0, 2.0], 2).unwrap();
        let candidates = [Candidate {
            target: &target,
            modes: vec![laplace],
        }];
        let schedule = Schedule {
            chains: 4,
            warmup: 500,
            samples: 6000,
            seed: 7,
        };
        let states = sample(&candidates, &schedule);
        let acceptance: f64 = states.iter().map(|s| s.within.rate().unwrap()).sum::<f64>() / 4.0;
        assert!(
            (acceptance - TARGET_ACCEPTANCE).abs() < 0.1,
            "acceptance {acceptance}"
        );
        for (i, (mean, sd)) in [(1.0, s1), (-2.0, s2)].into_iter().enumerate() {
            let chains: Vec<Vec<f64>> = states
                .iter()
                .map(|s| s.draws.iter().map(|d| d.x[i]).collect())
                .collect();
            let ess = bulk_ess(&chains);
            assert!(split_rhat(&chains) < 1.02);
            assert!(ess > 500.0, "ESS {ess}");
            let mut all: Vec<f64> = chains.concat();
            let m = all.iter().sum::<f64>() / all.len() as f64;
            // MC standard error of the mean: sd / sqrt(ESS); 4 sigma.
            assert!(
                (m - mean).abs() < 4.0 * sd / ess.sqrt(),
                "mean {m} vs {mean}"
            );
            all.sort_by(f64::total_cmp);
            let q = |p: f64| all[(p * (all.len() - 1) as f64).round() as usize];
            // The 2.5% quantile of N(mean, sd) is mean - 1.96 sd; its MC standard error is
            // sqrt(p (1 - p) / ESS) / density = 0.156 / 0.0584 / sqrt(ESS) sd = 2.67 sd / sqrt(ESS).
            let tolerance = 4.0 * 2.67 * sd / ess.sqrt();
            assert!(
                (q(0.025) - (mean - 1.96 * sd)).abs() < tolerance,
                "2.5%: {}",
                q(0.025)
            );
            assert!(
                (q(0.975) - (mean + 1.96 * sd)).abs() < tolerance,
                "97.5%: {}",
                q(0.975)
            );
        }
    }

    /// `w N(x; -3, 0.5^2) + (1 - w) N(x; 4, 1)` in one dimension: two modes far apart.
    struct TwoModes {
        w: f64,
    }

    impl TwoModes {
        fn parts(&self, x: f64) -> [(f64, f64); 2] {
            // (weighted density, its derivative) of each component.
            [(self.w, -3.0, 0.5), (1.0 - self.w, 4.0, 1.0)].map(|(w, m, s)| {
                let d = w * (-0.5 * ((x - m) / s).powi(2)).exp()
                    / (s * (2.0 * std::f64::consts::PI).sqrt());
                (d, -d * (x - m) / (s * s))
            })
        }
    }

    impl Target for TwoModes {
        fn dim(&self) -> usize {
            1
        }
        fn log_density(&self, x: &[f64]) -> f64 {
            self.parts(x[0]).iter().map(|p| p.0).sum::<f64>().ln()
        }
        fn gradient(&self, x: &[f64]) -> Vec<f64> {
            let p = self.parts(x[0]);
            vec![(p[0].1 + p[1].1) / (p[0].0 + p[1].0)]
        }
    }

    #[test]
    fn jumps_between_modes_weigh_two_basins_by_their_mass() {
        let target = TwoModes { w: 0.3 };
        let left = Laplace::at_mode(&target, &[-2.9]);
        let right = Laplace::at_mode(&target, &[4.1]);
        let schedule = Schedule {
            chains: 4,
            warmup: 300,
            samples: 3000,
            seed: 11,
        };
        let share_left = |modes: Vec<Laplace>| {
            let candidates = [Candidate {
                target: &target,
                modes,
            }];
            let states = sample(&candidates, &schedule);
            let indicator: Vec<Vec<f64>> = states
                .iter()
                .map(|s| {
                    s.draws
                        .iter()
                        .map(|d| (d.x[0] < 0.5) as u8 as f64)
                        .collect()
                })
                .collect();
            let ess = bulk_ess(&indicator);
            let all = indicator.concat();
            (all.iter().sum::<f64>() / all.len() as f64, ess)
        };
        // With both modes the chains visit each in proportion to its mass, 0.3 on the left:
        // binomial standard error with the indicator's ESS, 4 sigma.
        let (p, ess) = share_left(vec![left.clone(), right.clone()]);
        assert!(ess > 500.0, "ESS {ess}");
        assert!(
            (p - 0.3).abs() < 4.0 * (0.21 / ess).sqrt(),
            "p(left) {p}, ESS {ess}"
        );
        // Without the jumps MALA rarely crosses the barrier between them (6 nats high at
        // x = 0.5), and the shares are far off.
        for (only, starts_left) in [(left, true), (right, false)] {
            let (p, _) = share_left(vec![only]);
            assert!((p - 0.3).abs() > 0.2, "one mode, p(left) {p}");
            assert_eq!(p > 0.3, starts_left);
        }
    }

    #[test]
    fn model_probabilities_follow_the_evidence_across_dimensions() {
        // Model A: 2-D Gaussian with integral e^0 * 2 pi sd1 sd2; model B: 3-D with a different
        // normaliser and shape, chosen so that p(B) = 0.7 exactly.
        let a = Gaussian {
            mean: vec![0.0, 1.0],
            precision: vec![1.0, 0.3, 0.3, 2.0],
            log_c: 0.0,
        };
        let precision_b = vec![4.0, 0.0, 0.5, 0.0, 1.0, 0.0, 0.5, 0.0, 0.5];
        let log_integral = |p: &[f64], d: usize| {
            let c = crate::fit::cholesky::Cholesky::new(p, d).unwrap();
            0.5 * d as f64 * (2.0 * std::f64::consts::PI).ln() - c.log_det()
        };
        let log_za = log_integral(&a.precision, 2);
        let log_c_b = log_za + (0.7f64 / 0.3).ln() - log_integral(&precision_b, 3);
        let b = Gaussian {
            mean: vec![0.5, 1.0, -1.0],
            precision: precision_b,
            log_c: log_c_b,
        };
        let candidates = [
            Candidate {
                modes: vec![Laplace::at_mode(&a, &[0.1, 0.9])],
                target: &a,
            },
            Candidate {
                modes: vec![Laplace::at_mode(&b, &[0.4, 1.2, -0.8])],
                target: &b,
            },
        ];
        // The Laplace evidence is exact for Gaussians.
        let laplace_b = 1.0
            / (1.0
                + (candidates[0].laplace().log_evidence()
                    - candidates[1].laplace().log_evidence())
                .exp());
        assert!((laplace_b - 0.7).abs() < 1e-6, "{laplace_b}");
        let schedule = Schedule {
            chains: 4,
            warmup: 200,
            samples: 2500,
            seed: 3,
        };
        let states = sample(&candidates, &schedule);
        let indicator: Vec<Vec<f64>> = states
            .iter()
            .map(|s| s.draws.iter().map(|d| d.model as f64).collect())
            .collect();
        // The Laplace-matched jump is exact for Gaussians, so jumps are accepted with
        // probability min(1, ratio of evidences) and consecutive models are nearly independent;
        // the ESS of the indicator measures that.
        let ess = bulk_ess(&indicator);
        let p_b = indicator.concat().iter().sum::<f64>() / 10000.0;
        // Binomial standard error with the ESS: sqrt(0.7 * 0.3 / ESS); 4 sigma.
        let sigma = (0.21 / ess).sqrt();
        assert!((p_b - 0.7).abs() < 4.0 * sigma, "p(B) = {p_b}, ESS {ess}");
        assert!(ess > 1000.0, "ESS {ess}");
        // Within model B the draws have B's mean.
        let b_draws: Vec<&Draw> = states
            .iter()
            .flat_map(|s| &s.draws)
            .filter(|d| d.model == 1)
            .collect();
        let m2 = b_draws.iter().map(|d| d.x[2]).sum::<f64>() / b_draws.len() as f64;
        assert!((m2 + 1.0).abs() < 0.1, "{m2}");
    }
}

//! The `posterior` object of a fit file and its summary from the sampler's draws.
//!
//! Contract (DESIGN.md, issue "--mcmc"), which tools may rely on:
//!
//! ```json
//! {"params": {"alpha": {"mean": m, "ci95": [lo, hi]}, "f0": {"mean": [r, g, b], "ci95": [[lo, hi], [lo, hi], [lo, hi]]}, ...},
//!  "models": {"single": p, "kulla-conty": p}, "rhat_max": r, "ess_min": e, "samples": n}
//! ```
//!
//! | field | meaning |
//! | --- | --- |
//! | `params` | model-averaged (pooled over all kept draws of all chains and models) mean and central 95% interval (2.5% and 97.5% sample quantiles) of each material parameter, named as in the material file: `alpha` (isotropic) or `alpha_x`, `alpha_y`; `f0` (every Fresnel family); `eta`, `k` (conductors); `diffuse` (when any candidate fits it; 0 in draws of models without it); `exposure` (`--fit-exposure`). Each entry also carries `ess` and `rhat` |
//! | `models` | posterior probability of each model name: the share of kept draws in it (summed over with and without diffuse) |
//! | `diffuse_probability` | share of draws in a candidate with diffuse, when diffuse is a choice |
//! | `rhat_max`, `ess_min` | worst rank-normalised split R-hat and smallest bulk ESS over the entries of `params` |
//! | `samples` | kept draws over all chains |
//! | `laplace_models` | the model probabilities from the Laplace evidence of each candidate: a cross-check that needs no mixing between models (if the two disagree, either the jumps did not mix or a posterior is far from Gaussian) |
//! | `per_model` | probability, draws and parameter summary within each candidate (no diagnostics: the draws of one model are not a Markov chain) |
//! | `acceptance` | within-model (MALA) and between-model acceptance rates after warm-up |
//! | `modes` | present when a candidate's point fit found another basin almost as good (its `alternatives`) and the chains jumped between them ([`super::sampler`]): per mode, the candidate's label, alpha at the mode, the share of all kept draws nearest to it (by its Laplace density) and its share by Laplace evidence |
//! | `noise` | the likelihood's reading, noise level and whether it was estimated |
//! | `model_error` | per candidate (labels as in `per_model`): the model-error adjustment's method, the photos it compared, each coordinate's widening (adjusted over model-only standard deviation) and, with `--model-error discrepancy`, the fitted discrepancy's most likely scales `discrepancy.photo` and `discrepancy.lobe` and their posterior root-mean-square `photo_rms`, `lobe_rms` ([`super::discrepancy`]); absent with `--model-error none` ([`super::model_error`]) |

use super::diagnostics::{bulk_ess, split_rhat};
use super::laplace::Laplace;
use super::log_posterior::Noise;
use super::sampler::{ChainState, Counts, Draw};
use crate::fit::point::params::{FresnelFamily, ParamSpace};
use crate::material::FresnelSpec;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// Summary of one scalar parameter.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ScalarSummary {
    pub mean: f64,
    pub ci95: [f64; 2],
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ess: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rhat: Option<f64>,
}

/// Summary of an RGB parameter, one entry per channel.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ChannelSummary {
    pub mean: [f64; 3],
    pub ci95: [[f64; 2]; 3],
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ess: Option<[f64; 3]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rhat: Option<[f64; 3]>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum ParamSummary {
    Scalar(ScalarSummary),
    Channels(ChannelSummary),
}

/// Draws and parameters of one candidate.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ModelSummary {
    pub probability: f64,
    pub samples: usize,
    pub params: BTreeMap<String, ParamSummary>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Acceptance {
    pub within_model: Option<f64>,
    pub between_models: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub between_modes: Option<f64>,
}

/// One mode of a candidate's posterior that the chains jumped between.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ModeSummary {
    /// The candidate's label, as in `per_model`.
    pub model: String,
    /// Roughness at the mode (`[alpha_x, alpha_y]`).
    pub alpha: [f64; 2],
    /// Share of all kept draws nearest to this mode.
    pub probability: f64,
    /// Share by the Laplace evidence of each mode of each candidate.
    pub laplace_probability: f64,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Posterior {
    pub params: BTreeMap<String, ParamSummary>,
    pub models: BTreeMap<String, f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub diffuse_probability: Option<f64>,
    pub rhat_max: f64,
    pub ess_min: f64,
    pub samples: usize,
    pub laplace_models: BTreeMap<String, f64>,
    pub per_model: BTreeMap<String, ModelSummary>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub modes: Vec<ModeSummary>,
    pub acceptance: Acceptance,
    pub sampler: String,
    pub chains: usize,
    pub warmup: u64,
    /// Kept iterations per chain.
    pub kept: u64,
    pub noise: Noise,
    /// The model-error adjustment of each candidate (labels as in `per_model`); empty with
    /// `--model-error none` or too few photos ([`super::model_error`]).
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub model_error: BTreeMap<String, ModelErrorSummary>,
    /// Pixels in the likelihood.
    pub pixels: usize,
    /// Wall time of the optimiser runs (MAP starts).
    pub map_seconds: f64,
    /// Wall time of the Laplace approximations and the chains.
    pub seconds: f64,
    pub ess_per_second: f64,
}

/// How far the photo-clustered adjustment widened one candidate's posterior.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ModelErrorSummary {
    pub method: String,
    /// Photos whose scores were compared.
    pub photos: usize,
    /// Per coordinate of the parameter space (`ln_alpha`, `logit_f0_r`, ...): adjusted
    /// posterior standard deviation over the model's, at least 1.
    pub widening: BTreeMap<String, f64>,
    /// The fitted discrepancy term's prior scales (`--model-error discrepancy`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub discrepancy: Option<DiscrepancyScales>,
}

/// Prior standard deviations of the fitted discrepancy term ([`super::discrepancy`]), as
/// relative radiance: the most likely ones and their root-mean-square under their posterior
/// (what the intervals were widened with).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct DiscrepancyScales {
    /// Of one photo's offset (an exposure or light power error).
    pub photo: f64,
    /// Of one lobe-shape coefficient.
    pub lobe: f64,
    pub photo_rms: f64,
    pub lobe_rms: f64,
}

/// Label of a candidate in `per_model`: the model name, `+diffuse` when diffuse is a choice.
pub fn candidate_label(spaces: &[ParamSpace], index: usize) -> String {
    let space = spaces[index];
    let diffuse_is_choice = spaces.iter().any(|s| s.diffuse != space.diffuse);
    if diffuse_is_choice && space.diffuse {
        format!("{}+diffuse", space.model.name())
    } else {
        space.model.name().to_string()
    }
}

/// Material parameters of a draw, by file name: (name, one value or three channels).
type NamedValues = Vec<(&'static str, Vec<f64>)>;

fn named_values(spaces: &[ParamSpace], draw: &Draw) -> NamedValues {
    let space = spaces[draw.model];
    let material = space.material(&draw.x);
    let mut values = if space.anisotropic {
        vec![
            ("alpha_x", vec![material.alpha[0]]),
            ("alpha_y", vec![material.alpha[1]]),
        ]
    } else {
        vec![("alpha", vec![material.alpha[0]])]
    };
    values.push(("f0", material.fresnel.f0().to_vec()));
    if let (FresnelFamily::Conductor, FresnelSpec::Conductor { eta, k }) =
        (space.fresnel, material.fresnel)
    {
        values.push(("eta", eta.to_vec()));
        values.push(("k", k.to_vec()));
    }
    if spaces.iter().any(|s| s.diffuse) {
        values.push(("diffuse", material.diffuse.to_vec()));
    }
    if spaces.iter().any(|s| s.exposure) {
        values.push(("exposure", vec![space.exposure(&draw.x)]));
    }
    values
}

/// Sample quantile with linear interpolation (Hyndman and Fan 1996, type 7) of sorted values.
fn quantile(sorted: &[f64], p: f64) -> f64 {
    let h = p * (sorted.len() - 1) as f64;
    let (lo, frac) = (h.floor() as usize, h - h.floor());
    let hi = (lo + 1).min(sorted.len() - 1);
    sorted[lo] + frac * (sorted[hi] - sorted[lo])
}

/// (mean, ci95, ess, rhat) of one scalar over chains; diagnostics only when asked.
fn scalar(chains: &[Vec<f64>], diagnostics: bool) -> (f64, [f64; 2], Option<f64>, Option<f64>) {
    let mut all: Vec<f64> = chains.concat();
    all.sort_by(f64::total_cmp);
    let mean = all.iter().sum::<f64>() / all.len() as f64;
    let ci = [quantile(&all, 0.025), quantile(&all, 0.975)];
    let (ess, rhat) = if diagnostics {
        (Some(bulk_ess(chains)), Some(split_rhat(chains)))
    } else {
        (None, None)
    };
    (mean, ci, ess, rhat)
}

/// Parameter summaries of draws grouped by chain (all candidates share the parameter names).
fn summarise_params(
    spaces: &[ParamSpace],
    chains: &[Vec<&Draw>],
    diagnostics: bool,
) -> BTreeMap<String, ParamSummary> {
    let Some(first) = chains.iter().flatten().next() else {
        return BTreeMap::new();
    };
    let mut out = BTreeMap::new();
    let names = named_values(spaces, first);
    let per_draw: Vec<Vec<NamedValues>> = chains
        .iter()
        .map(|c| c.iter().map(|d| named_values(spaces, d)).collect())
        .collect();
    for (slot, (name, first_value)) in names.iter().enumerate() {
        let channel = |k: usize| {
            let series: Vec<Vec<f64>> = per_draw
                .iter()
                .map(|c| c.iter().map(|v| v[slot].1[k]).collect())
                .collect();
            scalar(&series, diagnostics)
        };
        let summary = if first_value.len() == 1 {
            let (mean, ci95, ess, rhat) = channel(0);
            ParamSummary::Scalar(ScalarSummary {
                mean,
                ci95,
                ess,
                rhat,
            })
        } else {
            let parts = [0, 1, 2].map(channel);
            ParamSummary::Channels(ChannelSummary {
                mean: parts.map(|p| p.0),
                ci95: parts.map(|p| p.1),
                ess: diagnostics.then(|| parts.map(|p| p.2.unwrap_or(f64::NAN))),
                rhat: diagnostics.then(|| parts.map(|p| p.3.unwrap_or(f64::NAN))),
            })
        };
        out.insert(name.to_string(), summary);
    }
    out
}

/// What the summary needs besides the chains.
pub struct RunFacts {
    pub sampler: &'static str,
    pub warmup: u64,
    pub kept: u64,
    pub noise: Noise,
    pub model_error: BTreeMap<String, ModelErrorSummary>,
    pub pixels: usize,
    /// Laplace approximations of each candidate at its modes, the MAP's first.
    pub modes: Vec<Vec<Laplace>>,
    pub map_seconds: f64,
    pub seconds: f64,
}

/// `ln` of the sum of `exp` of `values`.
fn log_sum_exp(values: impl Iterator<Item = f64> + Clone) -> f64 {
    let top = values.clone().fold(f64::NEG_INFINITY, f64::max);
    if !top.is_finite() {
        return top;
    }
    top + values.map(|v| (v - top).exp()).sum::<f64>().ln()
}

/// Each mode's share of the draws and of the Laplace evidence, when a candidate has more than one.
fn summarise_modes(
    spaces: &[ParamSpace],
    draws: &[&Draw],
    modes: &[Vec<Laplace>],
) -> Vec<ModeSummary> {
    if modes.iter().all(|m| m.len() < 2) {
        return Vec::new();
    }
    let evidence = || modes.iter().flatten().map(Laplace::log_evidence);
    let total = log_sum_exp(evidence());
    let mut counts: Vec<Vec<usize>> = modes.iter().map(|m| vec![0; m.len()]).collect();
    for draw in draws {
        counts[draw.model][Laplace::nearest(&modes[draw.model], &draw.x)] += 1;
    }
    let mut out = Vec::new();
    for (index, candidate) in modes.iter().enumerate() {
        for (mode, laplace) in candidate.iter().enumerate() {
            out.push(ModeSummary {
                model: candidate_label(spaces, index),
                alpha: spaces[index].material(&laplace.mean).alpha,
                probability: counts[index][mode] as f64 / draws.len().max(1) as f64,
                laplace_probability: (laplace.log_evidence() - total).exp(),
            });
        }
    }
    out
}

/// The posterior object from finished chains over the candidates `spaces`.
pub fn summarise(spaces: &[ParamSpace], states: &[ChainState], facts: RunFacts) -> Posterior {
    let all: Vec<Vec<&Draw>> = states.iter().map(|s| s.draws.iter().collect()).collect();
    let samples: usize = all.iter().map(Vec::len).sum();
    let params = summarise_params(spaces, &all, true);
    let (mut rhat_max, mut ess_min) = (f64::NEG_INFINITY, f64::INFINITY);
    for summary in params.values() {
        let (ess, rhat) = match summary {
            ParamSummary::Scalar(s) => (vec![s.ess], vec![s.rhat]),
            ParamSummary::Channels(c) => (
                c.ess.map_or(vec![], |e| e.map(Some).to_vec()),
                c.rhat.map_or(vec![], |r| r.map(Some).to_vec()),
            ),
        };
        ess_min = ess.into_iter().flatten().fold(ess_min, f64::min);
        rhat_max = rhat.into_iter().flatten().fold(rhat_max, f64::max);
    }
    let mut models = BTreeMap::new();
    let mut per_model = BTreeMap::new();
    let mut laplace_models = BTreeMap::new();
    // A candidate's evidence sums over its modes.
    let log_evidence: Vec<f64> = (0..spaces.len())
        .map(|index| match facts.modes.get(index) {
            Some(modes) if !modes.is_empty() => {
                log_sum_exp(modes.iter().map(Laplace::log_evidence))
            }
            _ => f64::NEG_INFINITY,
        })
        .collect();
    let top = log_evidence
        .iter()
        .copied()
        .fold(f64::NEG_INFINITY, f64::max);
    let evidence_sum: f64 = log_evidence.iter().map(|l| (l - top).exp()).sum();
    let mut diffuse_share = 0.0;
    for (index, space) in spaces.iter().enumerate() {
        let own: Vec<Vec<&Draw>> = all
            .iter()
            .map(|c| c.iter().copied().filter(|d| d.model == index).collect())
            .collect();
        let count: usize = own.iter().map(Vec::len).sum();
        let probability = count as f64 / samples.max(1) as f64;
        *models.entry(space.model.name().to_string()).or_insert(0.0) += probability;
        // A MAP outside the priors' support has no Laplace evidence; then no model has one.
        if top.is_finite() {
            *laplace_models
                .entry(space.model.name().to_string())
                .or_insert(0.0) += (log_evidence[index] - top).exp() / evidence_sum;
        }
        if space.diffuse {
            diffuse_share += probability;
        }
        per_model.insert(
            candidate_label(spaces, index),
            ModelSummary {
                probability,
                samples: count,
                params: summarise_params(spaces, &own, false),
            },
        );
    }
    let mut within = Counts::default();
    let mut between = Counts::default();
    let mut between_modes = Counts::default();
    for s in states {
        within.add(s.within);
        between.add(s.between);
        between_modes.add(s.between_modes);
    }
    let modes = summarise_modes(spaces, &all.concat(), &facts.modes);
    Posterior {
        params,
        models,
        diffuse_probability: spaces
            .iter()
            .any(|s| s.diffuse != spaces[0].diffuse)
            .then_some(diffuse_share),
        rhat_max,
        ess_min,
        samples,
        laplace_models,
        per_model,
        modes,
        acceptance: Acceptance {
            within_model: within.rate(),
            between_models: between.rate(),
            between_modes: between_modes.rate(),
        },
        sampler: facts.sampler.to_string(),
        chains: states.len(),
        warmup: facts.warmup,
        kept: facts.kept,
        noise: facts.noise,
        model_error: facts.model_error,
        pixels: facts.pixels,
        map_seconds: facts.map_seconds,
        seconds: facts.seconds,
        ess_per_second: ess_min / facts.seconds.max(1e-9),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bsdf::Model;
    use crate::fit::bayes::log_posterior::Reading;
    use crate::fit::point::params::logit;

    #[test]
    fn diffuse_choice_is_pooled_by_model_name_and_reported_as_a_probability() {
        let space = |model, diffuse| ParamSpace {
            diffuse,
            ..ParamSpace::plain(model)
        };
        let spaces = [
            space(Model::Single, false),
            space(Model::Single, true),
            space(Model::KullaConty, false),
        ];
        let plain = |model, alpha: f64| Draw {
            model,
            x: vec![alpha.ln(), logit(0.5), logit(0.5), logit(0.5)],
        };
        let with_diffuse = Draw {
            model: 1,
            x: vec![
                0.2f64.ln(),
                logit(0.5),
                logit(0.5),
                logit(0.5),
                logit(0.4),
                logit(0.4),
                logit(0.4),
            ],
        };
        // Two chains of 16 draws: half single, a quarter single+diffuse, a quarter kulla-conty.
        let pattern = [plain(0, 0.1), plain(0, 0.3), with_diffuse, plain(2, 0.2)];
        let chain: Vec<Draw> = (0..4).flat_map(|_| pattern.clone()).collect();
        let chains = [chain.clone(), chain];
        let states: Vec<ChainState> = chains
            .into_iter()
            .map(|draws| ChainState {
                model: 0,
                x: draws[0].x.clone(),
                log_density: 0.0,
                gradient: None,
                step: vec![1.0; 3],
                adapted: vec![0; 3],
                within: Counts::default(),
                between: Counts::default(),
                between_modes: Counts::default(),
                iterations: 16,
                draws,
            })
            .collect();
        let noise = Noise {
            reading: Reading::Gaussian,
            sigma: 0.1,
            estimated: true,
        };
        let facts = RunFacts {
            sampler: "test",
            warmup: 0,
            kept: 16,
            noise,
            model_error: BTreeMap::new(),
            pixels: 1,
            // One mode per candidate with Laplace evidence 1, 1 and 2.
            modes: [0.0, 0.0, 2.0f64.ln()]
                .map(|log_evidence| {
                    vec![Laplace {
                        mean: vec![0.0],
                        precision: crate::fit::cholesky::Cholesky::new(&[1.0], 1).unwrap(),
                        log_density: log_evidence - 0.5 * (2.0 * std::f64::consts::PI).ln(),
                    }]
                })
                .to_vec(),
            map_seconds: 0.0,
            seconds: 1.0,
        };
        let p = summarise(&spaces, &states, facts);
        assert_eq!(p.models["single"], 0.75);
        assert_eq!(p.models["kulla-conty"], 0.25);
        assert_eq!(p.diffuse_probability, Some(0.25));
        assert_eq!(p.per_model["single+diffuse"].samples, 8);
        assert!((p.laplace_models["kulla-conty"] - 0.5).abs() < 1e-12);
        assert!(p.modes.is_empty());
        let ParamSummary::Scalar(alpha) = &p.params["alpha"] else {
            panic!()
        };
        assert!((alpha.mean - 0.2).abs() < 1e-12);
        let ParamSummary::Channels(diffuse) = &p.params["diffuse"] else {
            panic!()
        };
        assert!((diffuse.mean[0] - 0.1).abs() < 1e-9, "{:?}", diffuse.mean);
        assert_eq!(p.samples, 32);
        // The JSON round trip keeps scalars and channels apart.
        let json = serde_json::to_string(&p).unwrap();
        assert_eq!(serde_json::from_str::<Posterior>(&json).unwrap(), p);
    }

    #[test]
    fn type_7_quantiles_interpolate_between_order_statistics() {
        let v = [1.0, 2.0, 3.0, 4.0, 5.0];
        assert_eq!(quantile(&v, 0.0), 1.0);
        assert_eq!(quantile(&v, 0.5), 3.0);
        assert_eq!(quantile(&v, 0.975), 4.9);
        assert_eq!(quantile(&v, 1.0), 5.0);
    }
}

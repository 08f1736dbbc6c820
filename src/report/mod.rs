//! The comparison report of `bouncefit compare`: the data model that `report.json` serialises
//! and that the Markdown and HTML pages lay out.
//!
//! | file | content | module |
//! | --- | --- | --- |
//! | `report.json` | [`Report`] | here |
//! | `report.md` | table, verdicts, links to the images and plots | [`markdown`] |
//! | `report.html` | the same, self-contained (images as base64 data URIs, inline CSS) | [`html`] |
//! | `<model>/<stem>_target.png`, `_fit.png`, `_residual.png` | per model and photo | [`images`] |
//! | `loss_curves.png`, `posterior.png` | plots | [`plots`] |
//! | `relit/` | each model's fit under the bundled sky on a sphere and the sample, its glTF export beside it, its lobe | [`relit`] |
//!
//! `compare --maps` writes a [`maps::MapsReport`] instead, through the same pages ([`Page`]).
//!
//! Ranking is never by raw loss alone (Xie, Bieron, Peers & Hanrahan 2021 found multiple
//! scattering changes fits of measured rough materials only a little): the report gives the BIC
//! reading, the held-out error with its standard error, and with `--mcmc` the posterior model
//! probabilities, and says in words when the data cannot tell models apart.

pub mod html;
pub mod images;
pub mod maps;
pub mod markdown;
pub mod plots;
pub mod relit;

use crate::bsdf::Model;
use crate::fit::bayes::posterior::{ParamSummary, Posterior as FitPosterior};
use crate::fit::bayes::selection::{HeldOutRanking, Selection};
use crate::fit::{edge_tint, ModelFit, TracePoint};
use crate::loss::LossKind;
use crate::random::mean_and_standard_error;
use relit::Relit;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// Posterior probability at or above which the report names a model as preferred by MCMC.
const DECISIVE_POSTERIOR_PROBABILITY: f64 = 0.95;

/// One parameter's posterior summary, as in the fit file's `posterior.params.<name>`.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ParamPosterior {
    pub mean: f64,
    pub ci95: [f64; 2],
}

/// A model's MCMC posterior as the report shows it: its parameters' means and 95% intervals
/// within the model (RGB parameters one entry per channel, `f0 r`, `f0 g`, `f0 b`), every
/// model's posterior probability, and the run's convergence diagnostics.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Posterior {
    pub params: BTreeMap<String, ParamPosterior>,
    /// Posterior probability of each model (by name) among the candidates.
    pub models: BTreeMap<String, f64>,
    pub rhat_max: f64,
    pub ess_min: f64,
    pub samples: usize,
}

impl Posterior {
    /// The view of candidate `label` (a model name) in the posterior of a `--mcmc` run, or
    /// `None` when the chains never visited it.
    pub fn of_candidate(run: &FitPosterior, label: &str) -> Option<Posterior> {
        let within = run.per_model.get(label).filter(|m| m.samples > 0)?;
        let mut params = BTreeMap::new();
        for (name, summary) in &within.params {
            match summary {
                ParamSummary::Scalar(s) => {
                    params.insert(
                        name.clone(),
                        ParamPosterior {
                            mean: s.mean,
                            ci95: s.ci95,
                        },
                    );
                }
                ParamSummary::Channels(s) => {
                    for (c, channel) in ["r", "g", "b"].iter().enumerate() {
                        params.insert(
                            format!("{name} {channel}"),
                            ParamPosterior {
                                mean: s.mean[c],
                                ci95: s.ci95[c],
                            },
                        );
                    }
                }
            }
        }
        Some(Posterior {
            params,
            models: run.models.clone(),
            rhat_max: run.rhat_max,
            ess_min: run.ess_min,
            samples: within.samples,
        })
    }
}

/// Held-out error of one model over the folds of `--holdout K`.
#[derive(Clone, Debug, Serialize)]
pub struct HeldOut {
    pub fold_losses: Vec<f64>,
    pub mean: f64,
    pub standard_error: f64,
}

impl HeldOut {
    pub fn new(fold_losses: Vec<f64>) -> HeldOut {
        let (mean, standard_error) = mean_and_standard_error(&fold_losses);
        HeldOut {
            fold_losses,
            mean,
            standard_error,
        }
    }
}

/// A fitted parameter in the material's own units.
#[derive(Clone, Debug, Serialize)]
pub struct Parameter {
    pub name: String,
    pub value: f64,
    /// Central 95% interval where the fit computes one itself (the exposure's Laplace interval).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub interval: Option<[f64; 2]>,
}

/// One model's line of the report.
#[derive(Clone, Debug, Serialize)]
pub struct ModelRow {
    pub model: Model,
    pub loss: f64,
    pub parameters: Vec<Parameter>,
    pub bic: f64,
    pub delta_bic: f64,
    pub evidence: crate::fit::bayes::selection::Evidence,
    pub seconds: f64,
    pub evaluations: usize,
    pub held_out: Option<HeldOut>,
    /// With `compare --mcmc`: the model's posterior (`None` without it, or when no draw
    /// visited the model).
    pub posterior: Option<Posterior>,
    /// With `compare --mcmc`: the model's posterior probability among the candidates.
    pub probability: Option<f64>,
    /// The optimiser trace, for the loss-curve plot (also in `<model>/fit.json`).
    #[serde(skip)]
    pub trace: Vec<TracePoint>,
}

impl ModelRow {
    /// The row of `fit`, ranked in `selection`, with its held-out error and its share of the
    /// posterior `run` when computed.
    pub fn new(
        fit: &ModelFit,
        selection: &Selection,
        held_out: Option<HeldOut>,
        run: Option<&FitPosterior>,
    ) -> ModelRow {
        let name = fit.material.model.name();
        let candidate = selection
            .candidates
            .iter()
            .find(|c| c.model == fit.material.model)
            .expect("every fitted model is ranked");
        ModelRow {
            model: fit.material.model,
            loss: fit.loss,
            parameters: parameters_of(fit),
            bic: candidate.bic,
            delta_bic: candidate.delta_bic,
            evidence: candidate.evidence,
            seconds: fit.seconds,
            evaluations: fit.evaluations,
            held_out,
            posterior: run.and_then(|r| Posterior::of_candidate(r, name)),
            probability: run.map(|r| r.models.get(name).copied().unwrap_or(0.0)),
            trace: fit.trace.clone(),
        }
    }
}

/// The fitted material parameters a reader compares: roughness, F0, edge tint for conductors,
/// diffuse albedo when fitted.
fn parameters_of(fit: &ModelFit) -> Vec<Parameter> {
    let m = &fit.material;
    let mut out = Vec::new();
    let mut push = |name: &str, value: f64| {
        out.push(Parameter {
            name: name.into(),
            value,
            interval: None,
        })
    };
    if m.alpha[0] == m.alpha[1] {
        push("alpha", m.alpha[0]);
    } else {
        push("alpha_x", m.alpha[0]);
        push("alpha_y", m.alpha[1]);
    }
    let rgb = ["r", "g", "b"];
    for (c, v) in rgb.iter().zip(fit.f0) {
        push(&format!("f0_{c}"), v);
    }
    if let Some(tint) = edge_tint(m) {
        for (c, v) in rgb.iter().zip(tint) {
            push(&format!("edge_tint_{c}"), v);
        }
    }
    if m.diffuse != [0.0; 3] {
        for (c, v) in rgb.iter().zip(m.diffuse) {
            push(&format!("diffuse_{c}"), v);
        }
    }
    if let Some(exposure) = fit.exposure {
        out.push(Parameter {
            name: "exposure".into(),
            value: exposure.value,
            interval: exposure.interval,
        });
    }
    out
}

/// Everything the report says.
#[derive(Clone, Debug, Serialize)]
pub struct Report {
    pub capture: String,
    pub capture_name: String,
    /// Photo file stems, in capture order.
    pub photos: Vec<String>,
    pub pixels_used: usize,
    pub loss_kind: LossKind,
    /// K of `--holdout K`.
    pub holdout_folds: Option<usize>,
    pub models: Vec<ModelRow>,
    pub selection: Selection,
    pub held_out_ranking: Option<HeldOutRanking>,
    /// Linear radiance that maps to full colour in the residual images (the same for all).
    pub residual_scale: f64,
    /// One sentence per criterion.
    pub verdicts: Vec<String>,
    pub relit: Relit,
}

impl Report {
    /// The verdict sentences of the report: BIC, held-out error and posterior probability,
    /// each saying which model it prefers and which it cannot tell apart.
    pub fn verdicts(
        selection: &Selection,
        held_out: Option<&HeldOutRanking>,
        rows: &[ModelRow],
    ) -> Vec<String> {
        let lowest_loss = rows
            .iter()
            .min_by(|a, b| a.loss.total_cmp(&b.loss))
            .expect("at least one model");
        let mut out = vec![selection.verdict.clone()];
        out.push(match held_out {
            Some(ranking) => ranking.verdict.clone(),
            None => "Held-out error was not computed (run with --holdout K).".into(),
        });
        out.push(posterior_verdict(rows));
        if rows.len() > 1 {
            out.push(format!(
                "The lowest raw loss is {}'s; raw loss ignores noise and model size, so read the criteria above instead.",
                lowest_loss.model
            ));
        }
        out
    }

    /// Table header of the Markdown and HTML pages.
    pub fn table_header() -> [&'static str; 10] {
        [
            "model",
            "loss",
            "parameters",
            "95% intervals",
            "BIC",
            "Delta-BIC (evidence)",
            "P(model)",
            "held-out loss (mean +- se)",
            "time (s)",
            "evaluations",
        ]
    }

    /// Table cells of each model, as text, in the order of [`Report::table_header`].
    pub fn table_rows(&self) -> Vec<[String; 10]> {
        let not_available = || "n/a".to_string();
        self.models
            .iter()
            .map(|row| {
                let parameters: Vec<String> = row
                    .parameters
                    .iter()
                    .map(|p| match p.interval {
                        Some([lo, hi]) => format!("{} {:.4} [{lo:.4}, {hi:.4}]", p.name, p.value),
                        None => format!("{} {:.4}", p.name, p.value),
                    })
                    .collect();
                let intervals = row.posterior.as_ref().map_or_else(not_available, |post| {
                    post.params
                        .iter()
                        .map(|(name, s)| format!("{name} [{:.4}, {:.4}]", s.ci95[0], s.ci95[1]))
                        .collect::<Vec<_>>()
                        .join("; ")
                });
                [
                    row.model.to_string(),
                    format!("{:.4e}", row.loss),
                    parameters.join("; "),
                    intervals,
                    format!("{:.1}", row.bic),
                    format!("{:.1} ({})", row.delta_bic, row.evidence.describe()),
                    row.probability
                        .map_or_else(not_available, |p| format!("{p:.3}")),
                    row.held_out.as_ref().map_or_else(not_available, |h| {
                        format!("{:.4e} +- {:.1e}", h.mean, h.standard_error)
                    }),
                    format!("{:.2}", row.seconds),
                    row.evaluations.to_string(),
                ]
            })
            .collect()
    }
}

/// What the posterior probabilities say, or that they were not computed.
fn posterior_verdict(rows: &[ModelRow]) -> String {
    let probabilities: Vec<(Model, f64)> = rows
        .iter()
        .filter_map(|r| r.probability.map(|p| (r.model, p)))
        .collect();
    let Some(&(best, p)) = probabilities.iter().max_by(|a, b| a.1.total_cmp(&b.1)) else {
        return "Posterior model probabilities were not computed (run with --mcmc).".into();
    };
    let listed: Vec<String> = probabilities
        .iter()
        .map(|(m, p)| format!("{m} {p:.3}"))
        .collect();
    if p >= DECISIVE_POSTERIOR_PROBABILITY {
        format!(
            "The posterior prefers {best} (model probabilities: {}).",
            listed.join(", ")
        )
    } else {
        format!(
            "The posterior does not single out a model: no probability reaches {DECISIVE_POSTERIOR_PROBABILITY} ({}).",
            listed.join(", ")
        )
    }
}

/// Path, relative to the report folder, of a per-photo image: `kind` is `target`, `fit` or
/// `residual`.
pub fn photo_image(model: Model, stem: &str, kind: &str) -> String {
    format!("{model}/{stem}_{kind}.png")
}

/// The per-photo image grid of a comparison of `models` (see [`images`]): for each photo its
/// stem and `(caption, relative path)` cells, the photo first and then each model's fit and
/// residual.
pub fn photo_grid(photos: &[String], models: &[Model]) -> Vec<(String, Vec<(String, String)>)> {
    let Some(&first) = models.first() else {
        return Vec::new();
    };
    photos
        .iter()
        .map(|stem| {
            let mut cells = vec![("photo".to_string(), photo_image(first, stem, "target"))];
            for &model in models {
                cells.push((format!("{model} fit"), photo_image(model, stem, "fit")));
                cells.push((
                    format!("{model} residual"),
                    photo_image(model, stem, "residual"),
                ));
            }
            (stem.clone(), cells)
        })
        .collect()
}

/// The loss-curve plot, relative to the report folder.
pub const LOSS_CURVES: &str = "loss_curves.png";
/// The posterior plot (written only when some model has a posterior).
pub const POSTERIOR_PLOT: &str = "posterior.png";

impl Report {
    /// What was compared, as `(label, value)` pairs for the head of the pages.
    pub fn settings(&self) -> Vec<(&'static str, String)> {
        vec![
            (
                "photo set",
                format!("{} ({})", self.capture_name, self.capture),
            ),
            ("photos", self.photos.len().to_string()),
            ("pixels in the loss", self.pixels_used.to_string()),
            (
                "loss",
                serde_json::to_value(self.loss_kind)
                    .ok()
                    .and_then(|v| v.as_str().map(str::to_string))
                    .unwrap_or_default(),
            ),
            (
                "held-out folds",
                self.holdout_folds.map_or("none".to_string(), |k| {
                    if k == self.photos.len() {
                        format!("{k}: leave-one-photo-out (each photo predicted by a fit to the others)")
                    } else {
                        format!("{k} (photo i in fold i mod {k})")
                    }
                }),
            ),
            (
                "residual colour scale",
                format!(
                    "full red/blue at +-{:.3e} (fit - photo, mean over RGB)",
                    self.residual_scale
                ),
            ),
        ]
    }

    /// The per-photo image grid: for each photo its stem and `(caption, relative path)` cells,
    /// the photo first and then each model's fit and residual.
    pub fn image_grid(&self) -> Vec<(String, Vec<(String, String)>)> {
        let models: Vec<Model> = self.models.iter().map(|r| r.model).collect();
        photo_grid(&self.photos, &models)
    }

    /// The plots written with the report, as `(caption, relative path)`.
    pub fn plots(&self) -> Vec<(&'static str, &'static str)> {
        let mut plots = vec![("Loss during each fit", LOSS_CURVES)];
        if self.models.iter().any(|r| r.posterior.is_some()) {
            plots.push(("Posterior means and 95% intervals", POSTERIOR_PLOT));
        }
        plots
    }
}

/// A table of a report page: a heading, column names, rows of cells, and a note below it.
pub struct Table {
    pub heading: String,
    pub header: Vec<String>,
    pub rows: Vec<Vec<String>>,
    pub note: Option<String>,
}

/// What the Markdown and HTML pages lay out ([`markdown::render`], [`html::render`]): the
/// uniform comparison ([`Report`]) and the maps comparison ([`maps::MapsReport`]) both.
pub trait Page {
    fn title(&self) -> String;
    /// `(label, value)` pairs for the head of the page.
    fn settings(&self) -> Vec<(&'static str, String)>;
    fn verdict_lines(&self) -> &[String];
    fn tables(&self) -> Vec<Table>;
    /// Figures as `(caption, relative path)`.
    fn figures(&self) -> Vec<(String, String)>;
    /// Per photo: its stem and `(caption, relative path)` cells.
    fn image_grid(&self) -> Vec<(String, Vec<(String, String)>)>;
    /// The fits under new light.
    fn relit(&self) -> &Relit;
}

impl Page for Report {
    fn title(&self) -> String {
        format!("Model comparison: {}", self.capture_name)
    }

    fn settings(&self) -> Vec<(&'static str, String)> {
        Report::settings(self)
    }

    fn verdict_lines(&self) -> &[String] {
        &self.verdicts
    }

    fn tables(&self) -> Vec<Table> {
        vec![Table {
            heading: "Models".into(),
            header: Report::table_header().map(String::from).to_vec(),
            rows: self.table_rows().into_iter().map(Vec::from).collect(),
            note: Some(
                "BIC = N ln(RSS/N) + k ln N (Gaussian noise of unknown variance, N = pixels x 3). \
                 Delta-BIC on the Kass & Raftery scale: < 2 not distinguishable, 2-6 positive, \
                 6-10 strong, > 10 very strong."
                    .into(),
            ),
        }]
    }

    fn figures(&self) -> Vec<(String, String)> {
        self.plots()
            .into_iter()
            .map(|(caption, path)| (caption.to_string(), path.to_string()))
            .collect()
    }

    fn image_grid(&self) -> Vec<(String, Vec<(String, String)>)> {
        Report::image_grid(self)
    }

    fn relit(&self) -> &Relit {
        &self.relit
    }
}

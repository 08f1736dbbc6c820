//! The fit file of a uniform fit (docs/files.md): the chosen model's material and fit record,
//! the candidates beside it, and what produced it, as the JSON `fit` writes (and `compare`
//! writes per model).

use super::bayes::holdout::HeldOutPhoto;
use super::bayes::posterior::Posterior;
use super::bayes::selection::Selection;
use super::pipeline::{PipelineOptions, UniformRun};
use super::point::uniformity::{self, Uniformity};
use super::{edge_tint, ModelFit};
use crate::bsdf::Model;
use crate::capture::Capture;
use crate::error::{Error, Result};
use crate::shading::region::{AppliedRegion, SampleRegion};
use crate::shading::{ExclusionCounts, ShadingRecords};
use serde::Serialize;
use std::path::Path;

fn is_zero(value: &f64) -> bool {
    *value == 0.0
}

/// The `region` entry of a fit file: which part of the sample was fitted and how uniform it
/// looks under the fit ([`crate::fit::point::uniformity`]).
#[derive(Serialize)]
pub struct RegionReport {
    #[serde(skip_serializing_if = "Option::is_none")]
    rectangle: Option<[f64; 4]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    mask: Option<String>,
    /// Loss pixels left out because they see the sample outside the region.
    pixels_excluded: usize,
    uniformity: Option<Uniformity>,
}

impl RegionReport {
    /// The report of `applied` for a fit that predicts `predicted` for every pixel.
    pub fn new(
        applied: &AppliedRegion,
        records: &ShadingRecords,
        predicted: &[[f64; 3]],
    ) -> RegionReport {
        let (rectangle, mask) = match &applied.region {
            SampleRegion::Rectangle(r) => (Some(*r), None),
            SampleRegion::Mask { path, .. } => (None, Some(path.display().to_string())),
        };
        RegionReport {
            rectangle,
            mask,
            pixels_excluded: applied.excluded,
            uniformity: uniformity::measure(records, predicted, applied),
        }
    }

    /// One line for stderr.
    pub fn summary(&self) -> String {
        match &self.uniformity {
            Some(u) => format!(
                "region: block ratio photo/fit spread {:.3} over {} blocks (range {:.3}..{:.3}): {}",
                u.ratio_spread,
                u.blocks,
                u.ratio_range[0],
                u.ratio_range[1],
                if u.uniform { "looks uniform" } else { "not uniform" }
            ),
            None => "region: too few pixels per block to judge uniformity".into(),
        }
    }
}

/// One line of the candidates table of a multi-model fit.
#[derive(Serialize)]
struct Candidate {
    model: Model,
    loss: f64,
    alpha: [f64; 2],
    f0: [f64; 3],
    seconds: f64,
}

/// The fit file: the chosen model's material and fit record, and what produced it.
#[derive(Serialize)]
pub struct FitFile<'a> {
    #[serde(flatten)]
    fit: &'a ModelFit,
    #[serde(skip_serializing_if = "Option::is_none")]
    edge_tint: Option<[f64; 3]>,
    capture: String,
    capture_name: &'a str,
    /// `--depth` or the manifest's `[sample] depth`, when not 0.
    #[serde(skip_serializing_if = "is_zero")]
    depth: f64,
    pixel_samples: usize,
    pixels_used: usize,
    excluded: ExclusionCounts,
    seed: u64,
    version: &'static str,
    candidates: Vec<Candidate>,
    selection: &'a Selection,
    #[serde(skip_serializing_if = "Option::is_none")]
    posterior: Option<&'a Posterior>,
    #[serde(skip_serializing_if = "Option::is_none")]
    region: Option<RegionReport>,
    /// The photo left out of the fit and how well the fit predicts it (`--holdout-photo`).
    #[serde(skip_serializing_if = "Option::is_none")]
    holdout: Option<&'a HeldOutPhoto>,
}

impl<'a> FitFile<'a> {
    /// The fit file of `fits[chosen]`, the fits of `options.candidates` to `records` of
    /// `capture`.
    pub fn new(
        fits: &'a [ModelFit],
        chosen: usize,
        selection: &'a Selection,
        posterior: Option<&'a Posterior>,
        capture: (&Path, &'a Capture),
        records: &ShadingRecords,
        options: &PipelineOptions,
    ) -> FitFile<'a> {
        let fit = &fits[chosen];
        FitFile {
            fit,
            edge_tint: edge_tint(&fit.material),
            capture: capture.0.display().to_string(),
            capture_name: &capture.1.name,
            depth: capture.1.depth,
            pixel_samples: options.pixel_samples,
            pixels_used: records.weight.iter().filter(|w| **w > 0.0).count(),
            excluded: records.excluded,
            seed: options.candidates[chosen].seed,
            version: env!("CARGO_PKG_VERSION"),
            candidates: fits
                .iter()
                .map(|f| Candidate {
                    model: f.material.model,
                    loss: f.loss,
                    alpha: f.material.alpha,
                    f0: f.f0,
                    seconds: f.seconds,
                })
                .collect(),
            selection,
            posterior,
            region: None,
            holdout: None,
        }
    }

    /// The fit file `fit` writes for `run`, a run of `options` on `capture`: the most probable
    /// model's fit with a posterior, else BIC's choice, with the region report of that fit's
    /// prediction when the fit was restricted to a region.
    pub fn of_run(
        run: &'a UniformRun,
        capture: (&Path, &'a Capture),
        options: &PipelineOptions,
    ) -> FitFile<'a> {
        let chosen = run.chosen();
        let region = run
            .region
            .as_ref()
            .map(|applied| RegionReport::new(applied, &run.records, run.prediction()));
        FitFile {
            holdout: run.holdout.as_ref(),
            ..FitFile::new(
                &run.fits,
                chosen,
                &run.selection,
                run.posterior.as_ref().map(|r| &r.posterior),
                capture,
                &run.records,
                options,
            )
        }
        .with_region(region)
    }

    /// The `region` entry, if the fit was restricted to one.
    pub fn region(&self) -> Option<&RegionReport> {
        self.region.as_ref()
    }

    /// The file's JSON text, as [`FitFile::write`] writes it.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).expect("a fit file serialises")
    }

    /// The same file with a `region` entry.
    pub fn with_region(mut self, region: Option<RegionReport>) -> Self {
        self.region = region;
        self
    }

    /// Write the file as pretty JSON, atomically.
    pub fn write(&self, path: &Path) -> Result<()> {
        let text = self.to_json();
        crate::capture::atomic_file::write_atomically(path, |w| {
            std::io::Write::write_all(w, text.as_bytes()).map_err(|e| Error::io(path, e))
        })
    }
}

//! End-to-end jobs of `bouncefit bench` (issue #5 item 3): a render of a photo set and a fit of
//! each model to a photo set, timed in wall and CPU seconds.
//!
//! | job | what is timed | skip |
//! | --- | --- | --- |
//! | `render` | [`render_all`] of the records of a capture template (built once, 1 sample per pixel, no targets) with the template's material under each model; after one untimed render, the median of repeated renders until [`RenderTiming::min_seconds`] have passed | `false`: every pixel, exactly; `true`: only the pixels that enter a loss (weight > 0), through the [`RenderPlan`] a fit would use (the skips `--no-skip` leaves on); `rel_error_vs_exact` is the RMS difference from the exact render relative to its RMS |
//! | `maps-fit` | a maps fit ([`crate::maps::fit`]) of each model to a photo set at each texel grid, leaving the last photo out: wall and CPU seconds of the fit and the prediction of every photo, texels per second, peak resident memory, the held-out photo's relative error and the naive baseline (the mean of the other photos); `seconds_vs_single` against the `single` maps fit of the same set and grid | none (a maps fit evaluates each pixel at its centre, exactly) |
//! | `relight` | a relit preview ([`crate::relight::render`]) of the render job's material under each model on the sphere under the bundled sky, `size` pixels square at `samples` samples per pixel, once; `seconds_vs_single` against `single`'s in the same run | none |
//! | `fit` | [`fit_model`] of each model to a photo set (records built once, optionally halved in resolution `halvings` times); the final loss and `alpha_rel_error = (alpha - alpha_true) / alpha_true` against the set's `material.json` | `false`: `--no-skip all`; `true`: every skip of [`crate::render::plan`] that `--no-skip` leaves on (pixels of weight 0 are never rendered by a fit) |
//!
//! `skipped_pixels` says how many pixels of weight 0 were left out; `plan` what the render
//! plan skipped.

use super::cpu_time::process_seconds;
use crate::bsdf::Model;
use crate::capture::Capture;
use crate::error::Result;
use crate::fit::bayes::holdout::HeldOutPhoto;
use crate::fit::{fit_model, FitOptions};
use crate::maps::{MaterialMaps, TexelGrid};
use crate::material::Material;
use crate::relight::environment::Environment;
use crate::relight::geometry::Geometry;
use crate::relight::{render_under, Scene};
use crate::render::plan::{PlanSummary, RenderPlan, Skips};
use crate::render::{render_all, render_material};
use crate::shading::ShadingRecords;
use serde::Serialize;
use std::path::Path;
use std::time::Instant;

/// Which end-to-end job a row times.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum JobKind {
    Render,
    Fit,
    MapsFit,
    Relight,
}

impl JobKind {
    /// The job's name in the text table.
    pub fn name(self) -> &'static str {
        match self {
            JobKind::Render => "render",
            JobKind::Fit => "fit",
            JobKind::MapsFit => "maps-fit",
            JobKind::Relight => "relight",
        }
    }
}

/// One row of the job table (the `--json` contract of issue #5 plus context).
#[derive(Clone, Debug, Serialize)]
pub struct JobRow {
    pub job: JobKind,
    pub model: Model,
    pub skip: bool,
    /// Wall seconds of one job (renders: the median of `repeats`).
    pub seconds: f64,
    /// CPU seconds of the process per job, all threads.
    pub cpu_seconds: f64,
    pub repeats: usize,
    /// Final loss of a fit (its `loss_kind`); `None` for renders.
    pub loss: Option<f64>,
    /// Fitted roughness and its signed relative error against the set's true roughness
    /// (`None` without a `material.json` beside the set, and for renders).
    pub alpha: Option<f64>,
    pub alpha_rel_error: Option<f64>,
    /// Loss evaluations of a fit.
    pub evaluations: Option<usize>,
    /// Resolution of the first photo, photo count, pixels worked on and pixels skipped.
    pub resolution: [usize; 2],
    pub photos: usize,
    pub pixels: usize,
    pub skipped_pixels: usize,
    /// What the render plan skipped (rows with `skip`).
    pub plan: Option<PlanSummary>,
    /// Renders with `skip`: RMS difference from the exact render of the same pixels, relative
    /// to its RMS (for stochastic models this includes their noise: the streams differ).
    pub rel_error_vs_exact: Option<f64>,
    /// Fits: the photo set.
    pub set: Option<String>,
    /// Fits: `seconds` over the `single` fit of the same set with the same `skip` (maps fits:
    /// of the same set and texel grid).
    pub seconds_vs_single: Option<f64>,
    /// Maps fits: the texel grid, the number of bases chosen, and the held-out photo's
    /// relative error and its naive baseline (the mean of the other photos).
    pub texels: Option<[usize; 2]>,
    pub bases: Option<usize>,
    pub held_out_error: Option<f64>,
    pub held_out_baseline: Option<f64>,
    /// Maps fits: texels of the grid per wall second, and the process's peak resident memory
    /// during the job in MB (the photos' records, loaded before it, included;
    /// [`super::memory`]).
    pub texels_per_second: Option<f64>,
    pub peak_memory_mb: Option<f64>,
}

impl JobRow {
    fn new(
        job: JobKind,
        model: Model,
        skip: bool,
        records: &ShadingRecords,
        pixels: usize,
    ) -> Self {
        let resolution = records
            .photos
            .first()
            .map_or([0, 0], |p| [p.width, p.height]);
        let images = (resolution, records.photos.len());
        JobRow::of_images(
            job,
            model,
            skip,
            images,
            (pixels, records.pixel_count() - pixels),
        )
    }

    /// A row of `images` = `(resolution, count)`, `(pixels, skipped)` of them worked on and
    /// skipped, its measurements still to be filled in.
    fn of_images(
        job: JobKind,
        model: Model,
        skip: bool,
        (resolution, photos): ([usize; 2], usize),
        (pixels, skipped_pixels): (usize, usize),
    ) -> Self {
        JobRow {
            job,
            model,
            skip,
            seconds: 0.0,
            cpu_seconds: 0.0,
            repeats: 0,
            loss: None,
            alpha: None,
            alpha_rel_error: None,
            evaluations: None,
            resolution,
            photos,
            pixels,
            skipped_pixels,
            plan: None,
            rel_error_vs_exact: None,
            set: None,
            seconds_vs_single: None,
            texels: None,
            bases: None,
            held_out_error: None,
            held_out_baseline: None,
            texels_per_second: None,
            peak_memory_mb: None,
        }
    }

    /// The row of a maps fit of `model` to `records` on `grid` that took `seconds` wall and
    /// `cpu_seconds` CPU and `peak_bytes` of memory at most, with its held-out photo's
    /// prediction.
    pub fn maps_fit(
        model: Model,
        records: &ShadingRecords,
        (grid, bases): (TexelGrid, usize),
        (seconds, cpu_seconds, peak_bytes): (f64, f64, Option<u64>),
        held_out: Option<&HeldOutPhoto>,
    ) -> JobRow {
        let used = records.weight.iter().filter(|&&w| w > 0.0).count();
        JobRow {
            seconds,
            cpu_seconds,
            repeats: 1,
            texels: Some([grid.width, grid.height]),
            bases: Some(bases),
            held_out_error: held_out.map(|h| h.relative_error),
            held_out_baseline: held_out.and_then(|h| h.mean_photo_error),
            texels_per_second: Some(grid.len() as f64 / seconds),
            peak_memory_mb: peak_bytes.map(|b| b as f64 / (1u64 << 20) as f64),
            ..JobRow::new(JobKind::MapsFit, model, false, records, used)
        }
    }
}

/// Time a relit preview of `material` under `model`: the sphere under the bundled sky, `size`
/// pixels square, `samples` samples per pixel, one frame (the row's `pixels` are the image's).
pub fn relight_job(
    (material, model): (&Material, Model),
    size: usize,
    samples: usize,
    seed: u64,
) -> JobRow {
    let maps = MaterialMaps::uniform(&Material {
        model,
        ..material.clone()
    });
    let sky = Environment::sky();
    let scene = Scene {
        material: &maps,
        geometry: Geometry::Sphere,
        size,
        samples,
        seed,
    };
    let (started, cpu) = (Instant::now(), process_seconds());
    std::hint::black_box(render_under(&scene, &sky));
    JobRow {
        seconds: started.elapsed().as_secs_f64(),
        cpu_seconds: process_seconds() - cpu,
        repeats: 1,
        ..JobRow::of_images(
            JobKind::Relight,
            model,
            false,
            ([size, size], 1),
            (size * size, 0),
        )
    }
}

/// The records of the capture (template) at `path`, every photo resampled to `resolution`,
/// one sample per pixel, without targets: what a render job renders.
pub fn render_records(path: &Path, resolution: [usize; 2]) -> Result<ShadingRecords> {
    let mut capture = Capture::open(path)?;
    for photo in &mut capture.photos {
        photo.camera = photo.camera.resampled(resolution);
    }
    ShadingRecords::build(&capture, 1, false)
}

/// The photo set at `path` with targets, halved in resolution `halvings` times, and the true
/// material from the set's `material.json` when there is one.
pub fn fit_records(
    path: &Path,
    pixel_samples: usize,
    halvings: usize,
) -> Result<(ShadingRecords, Option<Material>)> {
    let capture = Capture::open(path)?;
    let mut records = ShadingRecords::build(&capture, pixel_samples, true)?;
    for _ in 0..halvings {
        match records.coarsened() {
            Some(coarser) => records = coarser,
            None => break,
        }
    }
    let truth = capture.root.join("material.json");
    let truth = if truth.is_file() {
        Some(Material::load(&truth)?)
    } else {
        None
    };
    Ok((records, truth))
}

/// How long to keep repeating a render.
#[derive(Clone, Copy, Debug)]
pub struct RenderTiming {
    /// Repeat until this much wall time has passed ...
    pub min_seconds: f64,
    /// ... or this many renders are done.
    pub max_repeats: usize,
}

/// Time renders of `material` under `model` over `records`: without skipping (every pixel)
/// and with it (pixels of weight > 0).
pub fn render_jobs(
    records: &ShadingRecords,
    (material, model): (&Material, Model),
    skips: Skips,
    timing: RenderTiming,
    seed: u64,
) -> [JobRow; 2] {
    let material = Material {
        model,
        ..material.clone()
    };
    let used: Vec<usize> = (0..records.pixel_count())
        .filter(|&p| records.weight[p] > 0.0)
        .collect();
    let plan = RenderPlan::for_material(skips, &material, records, &used);
    let planned = || render_material(&material, records, &used, &plan, seed);
    // One untimed render wakes the thread pool and touches the records.
    let exact = render_all(&material, records, seed);
    let error = relative_rms_difference(
        &planned(),
        &used.iter().map(|&p| exact[p]).collect::<Vec<_>>(),
    );
    [false, true].map(|skip| {
        let mut row = JobRow::new(
            JobKind::Render,
            model,
            skip,
            records,
            if skip {
                used.len()
            } else {
                records.pixel_count()
            },
        );
        let (started, cpu) = (Instant::now(), process_seconds());
        let mut seconds = Vec::new();
        while seconds.is_empty()
            || (started.elapsed().as_secs_f64() < timing.min_seconds
                && seconds.len() < timing.max_repeats)
        {
            let one = Instant::now();
            let image = if skip {
                planned()
            } else {
                render_all(&material, records, seed)
            };
            std::hint::black_box(image);
            seconds.push(one.elapsed().as_secs_f64());
        }
        seconds.sort_by(f64::total_cmp);
        row.repeats = seconds.len();
        row.seconds = seconds[seconds.len() / 2];
        row.cpu_seconds = (process_seconds() - cpu) / seconds.len() as f64;
        if skip {
            row.plan = Some(plan.summary(&material));
            row.rel_error_vs_exact = Some(error);
        }
        row
    })
}

/// `sqrt(sum |a - b|^2 / sum |b|^2)` over pixels and channels.
pub fn relative_rms_difference(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    let (mut diff, mut norm) = (0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        for c in 0..3 {
            diff += (x[c] - y[c]).powi(2);
            norm += y[c] * y[c];
        }
    }
    (diff / norm.max(f64::MIN_POSITIVE)).sqrt()
}

/// Set `seconds_vs_single` of the fit rows of one set: each row's time over the `single` row
/// of the same job with the same `skip` and texel grid (left `None` when `single` was not
/// fitted).
pub fn ratios_to_single(rows: &mut [JobRow]) {
    let single = |row: &JobRow, rows: &[JobRow]| {
        rows.iter()
            .find(|r| {
                r.job == row.job
                    && r.model == Model::Single
                    && r.skip == row.skip
                    && r.texels == row.texels
            })
            .map(|r| r.seconds)
    };
    for i in 0..rows.len() {
        if rows[i].job == JobKind::Render {
            continue;
        }
        if let Some(base) = single(&rows[i], rows) {
            rows[i].seconds_vs_single = Some(rows[i].seconds / base);
        }
    }
}

/// Fit the model of `options` to `records` and time it.
pub fn fit_job(
    records: &ShadingRecords,
    truth: Option<&Material>,
    options: &FitOptions,
) -> Result<JobRow> {
    let used = records.weight.iter().filter(|&&w| w > 0.0).count();
    let skip = options.skips.any();
    let mut row = JobRow::new(JobKind::Fit, options.space.model, skip, records, used);
    let cpu = process_seconds();
    let fit = fit_model(records, options)?;
    row.cpu_seconds = process_seconds() - cpu;
    row.seconds = fit.seconds;
    row.repeats = 1;
    row.loss = Some(fit.loss);
    row.evaluations = Some(fit.evaluations);
    row.plan = skip.then_some(fit.render_plan);
    let alpha = fit.material.alpha[0];
    row.alpha = Some(alpha);
    row.alpha_rel_error = truth.map(|t| (alpha - t.alpha[0]) / t.alpha[0]);
    Ok(row)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::point::params::ParamSpace;
    use crate::fit::Optimizer;
    use crate::loss::LossKind;

    fn repo(path: &str) -> std::path::PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join(path)
    }

    /// The render template resampled to 32x32 gives 9 photos of 32x32 all inside the sample;
    /// both render rows agree on the pixel counts, and the skipping row renders exactly the
    /// pixels that the other does not skip.
    #[test]
    fn render_jobs_count_pixels_and_time_every_repeat() {
        let records = render_records(
            &repo("datasets/sources/copper-flash.capture.toml"),
            [32, 32],
        )
        .unwrap();
        assert_eq!(records.photos.len(), 9);
        assert_eq!(records.pixel_count(), 9 * 32 * 32);
        let material = Material::load(&repo("datasets/sources/copper-a03.material.json")).unwrap();
        let timing = RenderTiming {
            min_seconds: 0.0,
            max_repeats: 3,
        };
        let [all, skipping] = render_jobs(
            &records,
            (&material, Model::Single),
            Skips::all(),
            timing,
            0,
        );
        assert!(!all.skip && skipping.skip);
        for row in [&all, &skipping] {
            assert_eq!(row.pixels + row.skipped_pixels, 9 * 32 * 32);
            assert_eq!(row.repeats, 1);
            assert!(row.seconds > 0.0 && row.loss.is_none());
        }
        assert_eq!(
            skipping.skipped_pixels, 0,
            "a rectified camera sees only the sample"
        );
    }

    /// A fit of `single` to the bundled copper set at 16x16 recovers the true roughness to a
    /// few percent, and the row reports it as the signed error against `material.json`.
    #[test]
    fn fit_job_reports_the_error_against_the_true_roughness() {
        let (records, truth) = fit_records(&repo("datasets/copper-flash"), 1, 3).unwrap();
        assert_eq!(records.photos[0].width, 16);
        let truth = truth.expect("the bundled set names its material");
        let options = FitOptions {
            space: ParamSpace::plain(Model::Single),
            optimizer: Optimizer::Auto,
            loss: LossKind::L2,
            gradient: Default::default(),
            max_iters: 100,
            seed: 0,
            progress: Default::default(),
            starts: 1,
            projection: true,
            pyramid: 1,
            skips: Default::default(),
            precision: None,
            stochastic_fit: Default::default(),
        };
        let row = fit_job(&records, Some(&truth), &options).unwrap();
        let alpha = row.alpha.unwrap();
        assert!(
            (row.alpha_rel_error.unwrap() - (alpha - 0.3) / 0.3).abs() < 1e-12,
            "{row:?}"
        );
        assert!(row.alpha_rel_error.unwrap().abs() < 0.05, "{row:?}");
        assert!(row.loss.unwrap() >= 0.0 && row.evaluations.unwrap() > 0);
    }
}

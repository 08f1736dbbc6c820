//! `bouncefit compare DIR --models single,bitterli,... -o REPORT_DIR`: fit each model to the
//! same photos, rank them by BIC, held-out error (`--holdout K`) and posterior probability
//! (`--mcmc`), and write a report folder ([`crate::report`]).
//!
//! | option | behaviour |
//! | --- | --- |
//! | `--models` | models to fit (required, distinct) |
//! | `--holdout K` | K-fold over photos (photo i in fold i mod K): each model is refitted K times without one fold and scored on it |
//! | `--holdout` (no K) or `--holdout loo` | leave-one-photo-out: K = the number of photos, each photo predicted by a fit to all the others |
//! | `--mcmc` and its options | one sampler run over all models with jumps between them (as `fit --mcmc`): each row gains its posterior probability and 95% intervals, and `posterior.png` is drawn; checkpoint `<REPORT_DIR>.mcmc-checkpoint.json` |
//! | fit options | as `fit` ([`FitOptionArgs`]) |
//! | `-o REPORT_DIR` | staged and renamed into place; an existing non-empty folder needs `--force` |
//! | `--maps` and its options (`--texels`, `--normals`, `--bases`, `--holdout-photo N`) | fit each model as material maps ([`crate::maps::pipeline`], as `fit --maps`) and write the maps report ([`crate::report::maps`]): the maps side by side, re-renders and residuals of every photo, the held-out photo's error, and each multi-bounce model minus `single` per texel and per basis material. `--holdout K` and `--mcmc` are refused (a maps fit holds out one photo) |

use super::fit::fit_photo_set;
use super::fit_args::{FitOptionArgs, MapsArgs, McmcArgs};
use super::inputs::print_warning;
use super::output::StagedFolder;
use crate::bsdf::Model;
use crate::capture::atomic_file::write_atomically;
use crate::capture::image_io::display_exposure;
use crate::capture::Capture;
use crate::error::{Error, Result};
use crate::export::gltf::{described, described_maps};
use crate::export::maps::MapsConversion;
use crate::export::Conversion;
use crate::fit::bayes::holdout::{check_fold_count, cross_validate};
use crate::fit::bayes::selection::{HeldOutErrors, HeldOutRanking};
use crate::fit::fit_file::{FitFile, RegionReport};
use crate::maps::compare::MapsDifference;
use crate::maps::fit::check_model;
use crate::maps::pipeline::{MapsRun, MapsSet};
use crate::maps::MaterialMaps;
use crate::progress::Reporting;
use crate::render::render_all;
use crate::report::images::{residual_scale, write_model_images};
use crate::report::maps::{
    write_difference_images, write_maps_image, write_uncertainty_image, DifferenceRow,
    MapsModelRow, MapsReport,
};
use crate::report::relit::{write_relit, RelitInput};
use crate::report::{html, markdown, plots, HeldOut, ModelRow, Page, Report};
use serde::Serialize;
use std::io::Write;
use std::path::{Path, PathBuf};

#[derive(clap::Args, Debug)]
pub struct CompareArgs {
    /// Photo set: a folder with capture.toml, a capture.toml, or a MaterialGAN-format folder.
    pub capture: PathBuf,
    /// Models to compare, comma-separated.
    #[arg(long, value_delimiter = ',', required = true)]
    pub models: Vec<Model>,
    /// Also fit K times leaving out one fold of photos (photo i in fold i mod K) and report
    /// the error on the held-out photos; without K (or `loo`), leave-one-photo-out.
    #[arg(long, value_name = "K", num_args = 0..=1, default_missing_value = "loo", value_parser = parse_holdout)]
    pub holdout: Option<Holdout>,
    #[command(flatten)]
    pub options: FitOptionArgs,
    /// Report folder to write.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Replace an existing report folder.
    #[arg(long)]
    pub force: bool,
    /// No progress display.
    #[arg(long)]
    pub quiet: bool,
    #[command(flatten)]
    pub mcmc: McmcArgs,
    #[command(flatten)]
    pub maps: MapsArgs,
}

/// `--holdout`: K folds, or one fold per photo.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Holdout {
    LeaveOneOut,
    Folds(usize),
}

fn parse_holdout(text: &str) -> std::result::Result<Holdout, String> {
    if text == "loo" {
        return Ok(Holdout::LeaveOneOut);
    }
    text.parse().map(Holdout::Folds).map_err(|_| {
        format!("`{text}` is neither a number of folds nor `loo` (leave-one-photo-out)")
    })
}

pub fn run_compare(args: &CompareArgs) -> Result<()> {
    compare_photo_set(args, None)
}

/// [`run_compare`] on the photo set `held` in memory (the Python package's sets from arrays)
/// when given, which `args.capture` then only names; else on the set at `args.capture`.
pub fn compare_photo_set(args: &CompareArgs, held: Option<Capture>) -> Result<()> {
    for (i, model) in args.models.iter().enumerate() {
        if args.models[..i].contains(model) {
            return Err(Error::argument(
                "--models",
                format!("{model} is listed twice"),
            ));
        }
    }
    if args.maps.maps {
        return run_maps_compare(args, held);
    }
    if args.maps.holdout_photo.is_some() {
        return Err(Error::argument(
            "--holdout-photo",
            "a uniform comparison holds photos out with --holdout K; --holdout-photo N is for --maps",
        ));
    }
    let capture = args.options.real.open_or(&args.capture, held)?;
    let holdout = args.holdout.map(|h| match h {
        Holdout::LeaveOneOut => capture.photos.len(),
        Holdout::Folds(k) => k,
    });
    if let Some(folds) = holdout {
        check_fold_count(folds, capture.photos.len())?;
    }
    let folder = StagedFolder::new(&args.output, args.force)?;
    let options = args.options.pipeline_options(
        &args.models,
        &args.mcmc,
        &args.output,
        Reporting::terminal_if(!args.quiet),
        args.force,
        None,
    );
    let Some(done) = fit_photo_set(&args.capture, &capture, &options, args.quiet)? else {
        return Ok(());
    };
    let (records, fits, selection) = (&done.records, &done.fits, &done.selection);
    let run = done.posterior.as_ref().map(|r| &r.posterior);

    let mut held_out = Vec::new();
    if let Some(folds) = holdout {
        for candidate in &options.candidates {
            let model = candidate.space.model;
            if !args.quiet {
                eprintln!("{model}: {folds} held-out fits");
            }
            held_out.push(HeldOutErrors {
                model,
                fold_losses: cross_validate(records, candidate, folds)?,
            });
        }
    }
    let held_out_ranking = (!held_out.is_empty()).then(|| HeldOutRanking::rank(&held_out));

    let rows: Vec<ModelRow> = fits
        .iter()
        .enumerate()
        .map(|(i, fit)| {
            let errors = held_out.get(i).map(|e| HeldOut::new(e.fold_losses.clone()));
            ModelRow::new(fit, selection, errors, run)
        })
        .collect();

    let root = folder.path("");
    let predictions: Vec<Vec<[f64; 3]>> = fits
        .iter()
        .map(|fit| render_all(&fit.material, &fit.exposed(records), args.options.seed))
        .collect();
    let exposure = display_exposure(&records.target);
    let scale = residual_scale(records, &predictions);
    let mut region_lines = Vec::new();
    for (chosen, (fit, predicted)) in fits.iter().zip(&predictions).enumerate() {
        let model = fit.material.model;
        let model_folder = root.join(model.name());
        std::fs::create_dir(&model_folder).map_err(|e| Error::io(&model_folder, e))?;
        write_model_images(&root, model, records, predicted, exposure, scale)?;
        let region = done
            .region
            .as_ref()
            .map(|applied| RegionReport::new(applied, records, predicted));
        region_lines.extend(region.as_ref().map(|r| format!("{model}: {}", r.summary())));
        FitFile::new(
            fits,
            chosen,
            selection,
            run,
            (&args.capture, &capture),
            records,
            &options,
        )
        .with_region(region)
        .write(&model_folder.join("fit.json"))?;
    }

    let mut verdicts = Report::verdicts(selection, held_out_ranking.as_ref(), &rows);
    verdicts.extend(region_lines);
    // What a fit may have got wrong (another basin as good, a bound) stands in the verdicts.
    verdicts.extend(fits.iter().flat_map(|fit| {
        let model = fit.material.model;
        fit.warnings
            .iter()
            .map(move |w| format!("{model}: warning: {w}"))
    }));
    let relit_inputs: Vec<RelitInput> = fits
        .iter()
        .map(|fit| RelitInput {
            model: fit.material.model,
            fitted: MaterialMaps::uniform(&fit.material),
            gltf: MaterialMaps::uniform(&described(&Conversion::new(&fit.material))),
            lobe: Some(fit.material.clone()),
        })
        .collect();
    let report = Report {
        relit: write_relit(&root, &relit_inputs)?,
        capture: args.capture.display().to_string(),
        capture_name: capture.name.clone(),
        photos: records.photos.iter().map(|p| p.stem.clone()).collect(),
        pixels_used: records.weight.iter().filter(|w| **w > 0.0).count(),
        loss_kind: args.options.loss,
        holdout_folds: holdout,
        models: rows,
        selection: selection.clone(),
        held_out_ranking,
        residual_scale: scale,
        verdicts,
    };
    write_report(&report, &root)?;
    folder.commit()?;
    done.remove_checkpoint()?;
    done_message(args, &report.verdicts);
    Ok(())
}

/// Plots, `report.json`, `report.md` and `report.html` under `root` (the images are there).
fn write_report(report: &Report, root: &Path) -> Result<()> {
    plots::loss_curves(&root.join(crate::report::LOSS_CURVES), &report.models)?;
    let posteriors: Vec<_> = report
        .models
        .iter()
        .filter_map(|r| r.posterior.as_ref().map(|p| (r.model, p)))
        .collect();
    if !posteriors.is_empty() {
        plots::posterior_intervals(&root.join(crate::report::POSTERIOR_PLOT), &posteriors)?;
    }
    write_pages(report, root)
}

/// `report.json`, `report.md` and `report.html` of `page` under `root` (its images are there).
fn write_pages<P: Page + Serialize>(page: &P, root: &Path) -> Result<()> {
    let write_text = |name: &str, text: &str| {
        let path = root.join(name);
        write_atomically(&path, |w| {
            w.write_all(text.as_bytes())
                .map_err(|e| Error::io(&path, e))
        })
    };
    let json =
        serde_json::to_string_pretty(page).map_err(|e| Error::io(root.join("report.json"), e))?;
    write_text("report.json", &json)?;
    write_text("report.md", &markdown::render(page))?;
    write_text("report.html", &html::render(page, root)?)
}

/// `compare --maps`: every model's maps fit of the same photos, and the maps report.
fn run_maps_compare(args: &CompareArgs, held: Option<Capture>) -> Result<()> {
    if args.holdout.is_some() {
        return Err(Error::argument(
            "--holdout",
            "a maps comparison holds out one photo: use --holdout-photo N",
        ));
    }
    if args.mcmc.mcmc {
        return Err(Error::argument(
            "--mcmc",
            "a maps comparison has no posterior sampler; leave out --mcmc",
        ));
    }
    for &model in &args.models {
        check_model(model)?;
    }
    let capture = args.options.real.open_or(&args.capture, held)?;
    let folder = StagedFolder::new(&args.output, args.force)?;
    // Each maps fit takes the options of the first model with its own model.
    let options = args.options.maps_options(
        args.models[0],
        &args.maps,
        Reporting::terminal_if(!args.quiet),
    );
    let set = MapsSet::new(&args.capture, capture, options, &print_warning)?;
    let mut runs: Vec<MapsRun> = Vec::new();
    for &model in &args.models {
        if !args.quiet {
            eprintln!("{model}: maps fit");
        }
        runs.push(set.fit(model)?);
    }

    let root = folder.path("");
    let predictions: Vec<Vec<[f64; 3]>> = runs.iter().map(|r| r.predicted.clone()).collect();
    let display = display_exposure(&set.records.target);
    let scale = residual_scale(&set.records, &predictions);
    let mut rows = Vec::new();
    for run in &runs {
        let model = run.model;
        let model_folder = root.join(model.name());
        std::fs::create_dir(&model_folder).map_err(|e| Error::io(&model_folder, e))?;
        write_model_images(&root, model, &run.records, &run.predicted, display, scale)?;
        let fit_file = model_folder.join("fit.json");
        let maps_folder = MaterialMaps::folder_beside(&fit_file);
        std::fs::create_dir(&maps_folder).map_err(|e| Error::io(&maps_folder, e))?;
        let (maps, fields) = set.write_fit_images(run, &fit_file, &maps_folder)?;
        run.fit.maps.save_json(&fit_file, maps, fields)?;
        rows.push(MapsModelRow {
            model,
            seconds: run.fit.seconds,
            train_error: run.fit.train_error,
            holdout: run.holdout.clone(),
            exposure: run.exposure,
            fit_file: format!("{model}/fit.json"),
            maps_fit: run.fit.clone(),
        });
    }
    let fits: Vec<_> = runs.iter().map(|r| (r.model, &r.fit.maps)).collect();
    let maps_image = write_maps_image(&root, &fits)?;
    let sds: Vec<_> = runs.iter().map(|r| (r.model, &r.fit.uncertainty)).collect();
    let uncertainty_image = write_uncertainty_image(&root, &sds)?;
    let mut differences = Vec::new();
    if let Some(single) = runs.iter().find(|r| r.model == Model::Single) {
        for run in runs.iter().filter(|r| r.model != Model::Single) {
            let (difference, deltas) = MapsDifference::new(
                (run.model, &run.fit.maps),
                &single.fit.maps,
                &run.fit.labels,
                &run.fit.bases,
            );
            let images = write_difference_images(&root, &difference, &deltas, set.grid)?;
            differences.push(DifferenceRow { difference, images });
        }
    }
    let relit_inputs: Vec<RelitInput> = runs
        .iter()
        .map(|run| RelitInput {
            model: run.model,
            fitted: run.fit.maps.clone(),
            gltf: described_maps(&MapsConversion::new(&run.fit.maps)),
            lobe: None,
        })
        .collect();
    let report = MapsReport {
        relit: write_relit(&root, &relit_inputs)?,
        kind: "maps",
        capture: args.capture.display().to_string(),
        capture_name: set.capture.name.clone(),
        photos: set.records.photos.iter().map(|p| p.stem.clone()).collect(),
        pixels_used: set.records.weight.iter().filter(|w| **w > 0.0).count(),
        texels: [set.grid.width, set.grid.height],
        holdout_photo: args.maps.holdout_photo,
        verdicts: MapsReport::verdicts(&rows, &differences),
        models: rows,
        maps_image,
        uncertainty_image,
        differences,
        residual_scale: scale,
    };
    write_pages(&report, &root)?;
    folder.commit()?;
    done_message(args, &report.verdicts);
    Ok(())
}

/// The verdicts on stderr (unless `--quiet`) and the report folder on stdout.
fn done_message(args: &CompareArgs, verdicts: &[String]) {
    if !args.quiet {
        for verdict in verdicts {
            eprintln!("{verdict}");
        }
    }
    println!("{}", args.output.display());
}

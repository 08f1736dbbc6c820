//! `bouncefit fit DIR`: fit one or more models to a photo set ([`crate::fit::pipeline`]) and
//! write the fit file ([`crate::fit::fit_file`]) plus a residual image per photo; with `--maps`,
//! material maps ([`super::fit_maps`]). The arguments are in [`super::fit_args`]; `compare`
//! shares [`fit_photo_set`] too.

use super::fit_args::FitArgs;
use super::images::write_photo_images;
use super::inputs::print_warning;
use super::output::StagedFolder;
use crate::capture::image_io::display_exposure;
use crate::capture::Capture;
use crate::error::Result;
use crate::fit::fit_file::FitFile;
use crate::fit::pipeline::{self, PipelineOptions, UniformRun};
use crate::progress::Reporting;
use std::path::Path;

/// The uniform fit of the photo set at `capture_path` ([`pipeline::run`]), printing the
/// warnings about its photos, a line per finished fit (unless `quiet`) and, when the sampler
/// stopped early, where it left its state.
pub fn fit_photo_set(
    capture_path: &Path,
    capture: &Capture,
    options: &PipelineOptions,
    quiet: bool,
) -> Result<Option<UniformRun>> {
    let done = pipeline::run(capture_path, capture, options, &print_warning, &|fit| {
        if !quiet {
            eprintln!("{}", fit.summary());
        }
    })?;
    if done.is_none() {
        let checkpoint = options.mcmc.as_ref().and_then(|m| m.checkpoint.as_ref());
        if let Some(checkpoint) = checkpoint {
            eprintln!(
                "stopped; the sampler state is in {} (continue with --resume)",
                checkpoint.display()
            );
        }
    }
    Ok(done)
}

pub fn run_fit(args: &FitArgs) -> Result<()> {
    if args.map_options.maps {
        return super::fit_maps::run_maps_fit(args);
    }
    let capture = args.options.real.open(&args.capture)?;
    let output = args.output_path(&capture)?;
    let residual_folder = StagedFolder::new(&output.with_extension("residuals"), args.force)?;
    let options = args.options.pipeline_options(
        &args.models,
        &args.mcmc,
        &output,
        Reporting::terminal_if(!args.quiet),
        args.force,
        args.map_options.holdout_photo,
    );
    let Some(done) = fit_photo_set(&args.capture, &capture, &options, args.quiet)? else {
        return Ok(());
    };
    let (records, fits, selection) = (&done.records, &done.fits, &done.selection);
    // Whatever a fit may have got wrong is said even with --quiet.
    for fit in fits {
        for warning in &fit.warnings {
            eprintln!("warning: {}: {warning}", fit.material.model);
        }
    }
    if !args.quiet && fits.len() > 1 {
        eprintln!("{}", selection.verdict);
    }
    let file = FitFile::of_run(&done, (&args.capture, &capture), &options);
    if let (Some(region), false) = (file.region(), args.quiet) {
        eprintln!("{}", region.summary());
    }
    if let (Some(holdout), false) = (&done.holdout, args.quiet) {
        eprintln!("{}", holdout.summary());
    }
    // Residual images (prediction - photo, linear EXR; |residual| PNG at the photos' exposure),
    // from the render the fit's loss measured.
    let predicted = done.prediction();
    let residual = records.residuals(predicted.to_vec());
    let exposure = display_exposure(&records.target);
    write_photo_images(&residual_folder.path(""), records, &residual, exposure, "")?;
    file.write(&output)?;
    residual_folder.commit()?;
    done.remove_checkpoint()?;
    println!("{}", output.display());
    Ok(())
}

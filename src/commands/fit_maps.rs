//! `bouncefit fit DIR --maps`: fit material maps ([`crate::maps::pipeline`]) and write a maps fit
//! file (`FIT.json` naming `FIT.maps/diffuse.png`, `specular.png`, `roughness.exr`,
//! `normal.png`, and under `uncertainty` the per-texel standard deviations
//! `roughness_sd.exr`, `specular_sd.exr`, `diffuse_sd.exr`) plus residual images, every output
//! staged and committed at the end. Pixels are evaluated at their centre (one sub-sample), so
//! each sees exactly one texel.

use super::fit_args::FitArgs;
use super::images::write_photo_images;
use super::inputs::print_warning;
use super::output::StagedFolder;
use crate::bsdf::Model;
use crate::capture::image_io::display_exposure;
use crate::error::{Error, Result};
use crate::fit::bayes::holdout::HeldOutPhoto;
use crate::maps::fit::MapsFit;
use crate::maps::pipeline::MapsSet;
use crate::maps::MaterialMaps;
use crate::progress::Reporting;

/// The one model a maps fit with `args` fits, refusing several models and `--mcmc`.
pub fn maps_model(args: &FitArgs) -> Result<Model> {
    let [model] = args.models.as_slice() else {
        return Err(Error::argument(
            "--models",
            "a maps fit takes one model (compare maps of several with `compare --maps`)",
        ));
    };
    if args.mcmc.mcmc {
        return Err(Error::argument(
            "--mcmc",
            "a maps fit reports maximum a posteriori maps; the posterior sampler is for uniform \
             fits (drop --maps, or --mcmc)",
        ));
    }
    Ok(*model)
}

pub fn run_maps_fit(args: &FitArgs) -> Result<()> {
    let model = maps_model(args)?;
    let capture = args.options.real.open(&args.capture)?;
    let output = args.output_path(&capture)?;
    let maps_folder = StagedFolder::new(&MaterialMaps::folder_beside(&output), args.force)?;
    let residual_folder = StagedFolder::new(&output.with_extension("residuals"), args.force)?;
    let options = args.options.maps_options(
        model,
        &args.map_options,
        Reporting::terminal_if(!args.quiet),
    );
    let set = MapsSet::new(&args.capture, capture, options, &print_warning)?;
    let mut run = set.fit(model)?;
    if !args.quiet {
        summarise(&run.fit, run.holdout.as_ref());
    }
    let residual = run.records.residuals(std::mem::take(&mut run.predicted));
    let display = display_exposure(&run.records.target);
    write_photo_images(
        &residual_folder.path(""),
        &run.records,
        &residual,
        display,
        "",
    )?;
    let (maps_entry, fields) = set.write_fit_images(&run, &output, &maps_folder.path(""))?;
    maps_folder.commit()?;
    residual_folder.commit()?;
    run.fit.maps.save_json(&output, maps_entry, fields)?;
    println!("{}", output.display());
    Ok(())
}

/// One line per stage for stderr.
fn summarise(fit: &MapsFit, holdout: Option<&HeldOutPhoto>) {
    for trial in &fit.basis_trials {
        eprintln!(
            "{} bases: validation photo relative error {:.4} (roughness floor {}; {:.4} without)",
            trial.bases,
            trial.validation_error,
            trial
                .roughness_floor
                .map_or("none".into(), |f| format!("{f}")),
            trial.unfloored_validation_error
        );
    }
    let bases: Vec<String> = fit
        .bases
        .iter()
        .map(|b| format!("alpha {:.3} ({:.0}%)", b.alpha, 100.0 * b.share))
        .collect();
    eprintln!(
        "maps {}: {} bases [{}], training relative error {:.4}, {:.1} s",
        fit.texels_seen,
        fit.bases.len(),
        bases.join(", "),
        fit.train_error,
        fit.seconds
    );
    if let Some(h) = holdout {
        eprintln!("{}", h.summary());
    }
}

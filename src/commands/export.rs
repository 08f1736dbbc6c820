//! `bouncefit export FIT.json --format json|mitsuba|gltf|materialx -o FILE`: write a fitted (or
//! any) material for a renderer (formats and approximations: [`crate::export`]).
//!
//! The input is a fit file or a material file (both read by [`Material::load`]). For `mitsuba`
//! the scene's camera and light come from the capture a fit file names in its `capture` field
//! (resolved against the working directory, then against the fit file's folder), else from the
//! default flash setup; the scene's comment says which and why. The output is written
//! atomically and replaces an existing file only with `--force`.
//!
//! `--format mitsuba --scene CAPTURE -o FOLDER` writes the whole capture instead: one complete
//! scene `<photo stem>.xml` per photo (each photo has its own camera and light, and a Mitsuba
//! scene lights every sensor with every emitter), so `mitsuba FOLDER/00.xml` re-renders photo
//! `00` with the fitted material.

use super::inputs::{load_material, open_capture};
use super::output::{check_output_file, StagedFolder};
use crate::capture::atomic_file::write_atomically;
use crate::capture::Capture;
use crate::error::{Error, Result};
use crate::export::mitsuba::Scene;
use crate::export::{gltf, json, materialx, mitsuba, Conversion, ExportFormat};
use std::io::Write;
use std::path::{Path, PathBuf};

#[derive(clap::Args, Debug)]
pub struct ExportArgs {
    /// Fit file (from `bouncefit fit`) or material file.
    pub input: PathBuf,
    /// json | mitsuba | gltf | materialx
    #[arg(long)]
    pub format: String,
    /// File to write (with --scene: a folder).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Photo set whose every photo becomes a Mitsuba scene `<stem>.xml` in the output folder
    /// (--format mitsuba only).
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// Replace an existing output file.
    #[arg(long)]
    pub force: bool,
}

pub fn run_export(args: &ExportArgs) -> Result<()> {
    let format: ExportFormat = args.format.parse().map_err(|msg: String| {
        Error::argument(
            "--format",
            format!("{msg}, exporting {}", args.input.display()),
        )
    })?;
    if let Some(capture) = &args.scene {
        if format != ExportFormat::Mitsuba {
            return Err(Error::argument(
                "--scene",
                format!("needs --format mitsuba, got --format {}", args.format),
            ));
        }
        return export_scenes(args, capture);
    }
    check_output_file(&args.output, args.force)?;
    let material = load_material(&args.input)?;
    let conversion = Conversion::new(&material);
    let text = match format {
        ExportFormat::Json => json::document(&conversion),
        ExportFormat::Gltf => gltf::document(&conversion),
        ExportFormat::Materialx => materialx::document(&conversion),
        ExportFormat::Mitsuba => mitsuba::document(&conversion, &scene_of(&args.input)),
    };
    write_atomically(&args.output, |w| {
        w.write_all(text.as_bytes())
            .map_err(|e| Error::io(&args.output, e))
    })?;
    if format != ExportFormat::Json {
        if let Some(energy) = conversion.energy() {
            eprintln!("note: {}", energy.note(material.model));
        }
    }
    println!("wrote {}", args.output.display());
    Ok(())
}

/// `--scene`: one Mitsuba scene per photo of `capture_path` in the output folder.
fn export_scenes(args: &ExportArgs, capture_path: &Path) -> Result<()> {
    let material = load_material(&args.input)?;
    let capture = open_capture(capture_path)?;
    if capture.photos.is_empty() {
        return Err(Error::invalid(
            capture_path,
            "photo",
            "the capture has no photos",
        ));
    }
    let conversion = Conversion::new(&material);
    let folder = StagedFolder::new(&args.output, args.force)?;
    let named = capture_path.display().to_string();
    for (index, photo) in capture.photos.iter().enumerate() {
        let scene = Scene::of_photo(&capture, &named, index)
            .expect("every photo index of the capture has a scene");
        let path = folder.path(&format!("{}.xml", photo.stem()));
        let text = mitsuba::document(&conversion, &scene);
        write_atomically(&path, |w| {
            w.write_all(text.as_bytes())
                .map_err(|e| Error::io(&path, e))
        })?;
    }
    folder.commit()?;
    if let Some(energy) = conversion.energy() {
        eprintln!("note: {}", energy.note(material.model));
    }
    println!(
        "wrote {} Mitsuba scenes to {}",
        capture.photos.len(),
        args.output.display()
    );
    Ok(())
}

/// The scene of the capture named by the fit file's `capture` field, else the default flash.
fn scene_of(fit: &Path) -> Scene {
    let file = std::fs::read_to_string(fit)
        .ok()
        .and_then(|text| serde_json::from_str::<serde_json::Value>(&text).ok());
    let named = file
        .as_ref()
        .and_then(|value| value.get("capture")?.as_str().map(str::to_owned));
    // A fit made with --depth records it; the scene puts the camera and light that much higher.
    let depth = file.as_ref().and_then(|value| value.get("depth")?.as_f64());
    let Some(named) = named else {
        return Scene::default_flash("the input names no capture");
    };
    let beside_fit = fit.parent().unwrap_or(Path::new(".")).join(&named);
    let opened = Capture::open(Path::new(&named))
        .or_else(|first| Capture::open(&beside_fit).map_err(|_| first));
    match opened {
        Ok(mut capture) => {
            capture.depth = depth.unwrap_or(capture.depth);
            Scene::from_capture(&capture.in_material_frame(), &named).unwrap_or_else(|| {
                Scene::default_flash(&format!("capture '{named}' has no photos"))
            })
        }
        Err(err) => Scene::default_flash(&format!("capture '{named}' not readable: {err}")),
    }
}

//! `bouncefit export FIT.json --format json|mitsuba|gltf|materialx -o FILE`: write a fitted (or
//! any) material for a renderer (formats and approximations: [`crate::export`]).
//!
//! The input is a fit file or a material file (both read by [`Material::load`]). For `mitsuba`
//! the scene's camera and light come from the capture a fit file names in its `capture` field
//! (resolved against the working directory, then against the fit file's folder), else from the
//! default flash setup; the scene's comment says which and why. The output is written
//! atomically and replaces an existing file only with `--force`.
//!
//! A maps material ([`crate::maps`]) exports to `gltf`, `materialx` and `mitsuba` with its
//! textures ([`crate::export::maps`]) in the folder `<output without extension>.textures/`
//! beside the output file, which the file names by relative paths (with `--scene`:
//! `FOLDER/textures/`, shared by the scenes); `json` refuses it (the maps material file is
//! already that form).
//!
//! `--format mitsuba --scene CAPTURE -o FOLDER` writes the whole capture instead: one complete
//! scene `<photo stem>.xml` per photo (each photo has its own camera and light, and a Mitsuba
//! scene lights every sensor with every emitter), so `mitsuba FOLDER/00.xml` re-renders photo
//! `00` with the fitted material.

use super::inputs::{load_any_material, open_capture};
use super::output::{check_output_file, StagedFolder};
use crate::capture::atomic_file::write_atomically;
use crate::capture::Capture;
use crate::error::{Error, Result};
use crate::export::maps::{MapsConversion, PbrFormat};
use crate::export::mitsuba::Scene;
use crate::export::{gltf, json, materialx, mitsuba, Conversion, ExportFormat};
use crate::maps::{AnyMaterial, MaterialMaps};
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
    let material = match load_any_material(&args.input)? {
        AnyMaterial::Uniform(material) => material,
        AnyMaterial::Maps(maps) => return export_maps(args, format, &maps),
    };
    let conversion = Conversion::new(&material);
    let text = match format {
        ExportFormat::Json => json::document(&conversion),
        ExportFormat::Gltf => gltf::document(&conversion),
        ExportFormat::Materialx => materialx::document(&conversion),
        ExportFormat::Mitsuba => mitsuba::document(&conversion, &scene_of(&args.input)),
    };
    write_text(&args.output, &text)?;
    if format != ExportFormat::Json {
        print_energy_note(&conversion);
    }
    println!("wrote {}", args.output.display());
    Ok(())
}

fn write_text(path: &Path, text: &str) -> Result<()> {
    write_atomically(path, |w| {
        w.write_all(text.as_bytes()).map_err(|e| Error::io(path, e))
    })
}

/// A maps material to `format`: the textures into `<output stem>.textures/`, then the file.
fn export_maps(args: &ExportArgs, format: ExportFormat, maps: &MaterialMaps) -> Result<()> {
    if format == ExportFormat::Json {
        return Err(Error::invalid(
            &args.input,
            "maps",
            "--format json exports uniform materials; a maps material file is already its own \
             JSON form (use gltf, materialx or mitsuba)",
        ));
    }
    let conversion = MapsConversion::new(maps);
    let scene = scene_of(&args.input);
    let textures = args.output.with_extension("textures");
    let prefix = textures
        .file_name()
        .unwrap_or_default()
        .to_string_lossy()
        .into_owned();
    let folder = StagedFolder::new(&textures, args.force)?;
    let text = match format {
        ExportFormat::Gltf => {
            let written = conversion.write_pbr_textures(folder.staging(), PbrFormat::Gltf)?;
            gltf::maps_document(&conversion, &written, &prefix, scene.sample)
        }
        ExportFormat::Materialx => {
            let written = conversion.write_pbr_textures(folder.staging(), PbrFormat::Materialx)?;
            materialx::maps_document(&conversion, &written, &prefix)
        }
        ExportFormat::Mitsuba => {
            let written = conversion.write_mitsuba_textures(folder.staging())?;
            mitsuba::maps_document(&conversion, &written, &prefix, &scene)
        }
        ExportFormat::Json => unreachable!("refused above"),
    };
    folder.commit()?;
    write_text(&args.output, &text)?;
    print_energy_note(&conversion.roughest);
    println!("wrote {} and {}", args.output.display(), textures.display());
    Ok(())
}

fn print_energy_note(conversion: &Conversion) {
    if let Some(energy) = conversion.energy() {
        eprintln!("note: {}", energy.note(conversion.material.model));
    }
}

/// The Mitsuba scene of the exported material under a photo's scene.
type SceneDocument = Box<dyn Fn(&Scene) -> String>;

/// `--scene`: one Mitsuba scene per photo of `capture_path` in the output folder.
fn export_scenes(args: &ExportArgs, capture_path: &Path) -> Result<()> {
    let material = load_any_material(&args.input)?;
    let capture = open_capture(capture_path)?;
    if capture.photos.is_empty() {
        return Err(Error::invalid(
            capture_path,
            "photo",
            "the capture has no photos",
        ));
    }
    let folder = StagedFolder::new(&args.output, args.force)?;
    let (document, roughest): (SceneDocument, Conversion) = match &material {
        AnyMaterial::Uniform(material) => {
            let conversion = Conversion::new(material);
            let copy = conversion.clone();
            (
                Box::new(move |scene| mitsuba::document(&copy, scene)),
                conversion,
            )
        }
        AnyMaterial::Maps(maps) => {
            maps.check_sample(&args.input, &capture.sample)?;
            let conversion = MapsConversion::new(maps);
            let textures = folder.path("textures");
            std::fs::create_dir(&textures).map_err(|e| Error::io(&textures, e))?;
            let written = conversion.write_mitsuba_textures(&textures)?;
            let roughest = conversion.roughest.clone();
            (
                Box::new(move |scene| {
                    mitsuba::maps_document(&conversion, &written, "textures", scene)
                }),
                roughest,
            )
        }
    };
    let named = capture_path.display().to_string();
    for (index, photo) in capture.photos.iter().enumerate() {
        let scene = Scene::of_photo(&capture, &named, index)
            .expect("every photo index of the capture has a scene");
        write_text(
            &folder.path(&format!("{}.xml", photo.stem())),
            &document(&scene),
        )?;
    }
    folder.commit()?;
    print_energy_note(&roughest);
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

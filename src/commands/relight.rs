//! `bouncefit relight`: previews of a fit or material under new light (docs/relight.md).

use super::inputs::{load_any_material, open_capture};
use super::output::StagedFolder;
use crate::capture::image_io::display_exposure;
use crate::error::{Error, Result};
use crate::maps::{AnyMaterial, MaterialMaps};
use crate::relight::environment::Environment;
use crate::relight::geometry::Geometry;
use crate::relight::lights::{fit_capture, Lights};
use crate::relight::output::{write_frames, ENVIRONMENT, PREVIEW};
use crate::relight::shade::Sampling;
use crate::relight::{render, Scene};
use std::path::PathBuf;

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum LightKind {
    /// An environment map (`--env`).
    Env,
    /// A point light circling the sample (`--frames`, `--elevation`, `--distance`).
    Turntable,
    /// The lights of the photo set the fit was made from (or `--capture`).
    Capture,
}

#[derive(clap::Args, Debug)]
pub struct RelightArgs {
    /// Fit file (`fit`, `fit --maps`) or material file.
    pub material: PathBuf,
    /// Output folder: `<frame>.exr` (linear), `<frame>.png` (sRGB) and preview.gif.
    #[arg(short, long)]
    pub output: PathBuf,
    #[arg(long, value_enum, default_value = "sphere")]
    pub geometry: Geometry,
    /// Image width in pixels (the sphere's images are square, the flat sample's keep the
    /// maps' proportions).
    #[arg(long, default_value_t = 256)]
    pub size: usize,
    #[arg(long, value_enum, default_value = "env")]
    pub light: LightKind,
    /// `sky` (bundled), `white` (radiance 1 everywhere) or a latitude-longitude EXR file.
    #[arg(long, default_value = "sky")]
    pub env: String,
    /// Environment sampling: `mis` (environment and material) or `light` (environment only).
    #[arg(long, value_enum, default_value = "mis")]
    pub sampling: Sampling,
    /// Samples per pixel.
    #[arg(long, default_value_t = 64)]
    pub spp: usize,
    /// Frames: the turntable's light positions, or the environment's turns about the zenith
    /// (default 24 for the turntable, 1 for an environment).
    #[arg(long)]
    pub frames: Option<usize>,
    /// Turntable light's elevation above the horizon, degrees.
    #[arg(long, default_value_t = 30.0, allow_negative_numbers = true)]
    pub elevation: f64,
    /// Turntable light's distance from the centre, in sphere radii (sample half-widths).
    #[arg(long, default_value_t = 4.0, allow_negative_numbers = true)]
    pub distance: f64,
    /// Photo set whose lights `--light capture` uses (default: the one the fit file names).
    #[arg(long)]
    pub capture: Option<PathBuf>,
    /// Multiplier of radiance in the PNGs and the preview (default: the 99.5th percentile of
    /// all frames maps to 1).
    #[arg(long)]
    pub exposure: Option<f64>,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Replace a non-empty output folder.
    #[arg(long)]
    pub force: bool,
}

fn positive(flag: &str, value: usize) -> Result<usize> {
    if value == 0 {
        return Err(Error::argument(flag, "must be at least 1"));
    }
    Ok(value)
}

pub fn run_relight(args: &RelightArgs) -> Result<()> {
    positive("--size", args.size)?;
    positive("--spp", args.spp)?;
    if let Some(exposure) = args.exposure {
        if !(exposure.is_finite() && exposure > 0.0) {
            return Err(Error::argument("--exposure", "must be a finite number > 0"));
        }
    }
    let material = match load_any_material(&args.material)? {
        AnyMaterial::Uniform(material) => MaterialMaps::uniform(&material),
        AnyMaterial::Maps(maps) => maps,
    };
    let lights = match args.light {
        LightKind::Env => Lights::Environment {
            env: Environment::named_or_file(&args.env)?,
            frames: positive("--frames", args.frames.unwrap_or(1))?,
            sampling: args.sampling,
        },
        LightKind::Turntable => Lights::turntable(
            positive("--frames", args.frames.unwrap_or(24))?,
            args.elevation,
            args.distance,
        )?,
        LightKind::Capture => {
            let path = match &args.capture {
                Some(path) => path.clone(),
                None => fit_capture(&args.material)?,
            };
            Lights::Capture(open_capture(&path)?)
        }
    };
    let folder = StagedFolder::new(&args.output, args.force)?;
    let scene = Scene {
        material: &material,
        geometry: args.geometry,
        size: args.size,
        samples: args.spp,
        seed: args.seed,
    };
    let frames = render(&scene, &lights.frames());
    let exposure = args.exposure.unwrap_or_else(|| {
        let all: Vec<[f64; 3]> = frames.iter().flat_map(|f| f.rgb.iter().copied()).collect();
        display_exposure(&all)
    });
    write_frames(folder.staging(), &frames, exposure)?;
    if let Lights::Environment { env, .. } = &lights {
        env.write(&folder.staging().join(ENVIRONMENT))?;
    }
    folder.commit()?;
    eprintln!(
        "relit {} frame(s) of {}x{} to {} ({PREVIEW})",
        frames.len(),
        frames[0].resolution[0],
        frames[0].resolution[1],
        args.output.display()
    );
    Ok(())
}

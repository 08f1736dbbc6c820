//! `bouncefit synth` (make a photo set from a material and a capture) and `bouncefit render`
//! (re-render a photo set with a material or fit, a fit's `exposure` applied).

use super::images::write_photo_images;
use super::inputs::{load_any_material, open_capture};
use super::output::StagedFolder;
use crate::board::geometry::Intrinsics;
use crate::board::phone::Vignetting;
use crate::capture::camera::Camera;
use crate::capture::image_io::display_exposure;
use crate::capture::image_io::ColorEncoding;
use crate::error::{Error, Result};
use crate::maps::render::{check_fits_capture, render_any, render_records};
use crate::maps::AnyMaterial;
use crate::random::rng_stream;
use crate::shading::ShadingRecords;
use rand_distr::{Distribution, StandardNormal};
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct SynthArgs {
    /// Material file (JSON) of the sample.
    #[arg(long)]
    pub material: PathBuf,
    /// Capture manifest (capture.toml) giving cameras, lights and image names; images need not exist.
    #[arg(long)]
    pub capture: PathBuf,
    /// Output folder: one EXR (linear) and PNG (tone-mapped) per photo, capture.toml, material.json.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Relative Gaussian noise: each channel becomes v (1 + SIGMA n), n ~ N(0, 1).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub noise: f64,
    /// Stratified sub-pixel samples per pixel (a perfect square).
    #[arg(long, default_value_t = 4)]
    pub pixel_samples: usize,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Replace a non-empty output folder.
    #[arg(long)]
    pub force: bool,
    /// Output format: `exr` (linear EXR + capture.toml), `materialgan` (8-bit gamma-2.2 PNGs
    /// clipped at 1, with camera_pos.txt, light_pos.txt, light_power.txt, image_size.txt), or
    /// `phone` (8-bit sRGB JPEGs as a phone writes them, the gain that maps the brightest
    /// 0.5% to 0.9 recorded as each photo's `exposure` in capture.toml).
    #[arg(long, value_enum, default_value = "exr")]
    pub format: SynthFormat,
    /// A printed tag board (board.toml) around the sample: its paper and tags are rendered
    /// where the cameras see the board plane outside the sample (for `bouncefit capture`).
    #[arg(long)]
    pub board: Option<PathBuf>,
    /// Radial distortion K1,K2 of the phone's lens (`--format phone`, pinhole cameras with
    /// square pixels): each photo is rendered through a pinhole and then distorted as
    /// `capture --lens calibrated` models it (K1 < 0: barrel).
    #[arg(long, value_parser = super::capture::parse_pair)]
    pub distortion: Option<[f64; 2]>,
    /// Vignetting A,B of the phone's lens (`--format phone`, pinhole cameras): each photo's
    /// radiance times `1 + A r^2 + B r^4` of the normalised image radius (A < 0: darker
    /// corners), as `capture --vignetting calibrated` models it.
    #[arg(long, value_parser = super::capture::parse_pair)]
    pub vignetting: Option<[f64; 2]>,
    /// JPEG quality of `--format phone`.
    #[arg(long, default_value_t = 92)]
    pub jpeg_quality: u8,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum SynthFormat {
    Exr,
    Materialgan,
    Phone,
}

#[derive(clap::Args, Debug)]
pub struct RenderArgs {
    /// Photo set (folder with capture.toml, a capture.toml, or a MaterialGAN-format folder).
    #[arg(long)]
    pub capture: PathBuf,
    /// Material or fit file.
    #[arg(long)]
    pub material: PathBuf,
    /// Output folder: `<photo image stem>.exr` and `.png` per photo.
    #[arg(short, long)]
    pub output: PathBuf,
    #[arg(long, default_value_t = 4)]
    pub pixel_samples: usize,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// The sample's surface lies this far below the plane the cameras and lights were
    /// calibrated on (as `fit --depth`).
    #[arg(long, value_parser = super::fit_args::parse_depth)]
    pub depth: Option<f64>,
    #[arg(long)]
    pub force: bool,
}

pub fn run_synth(args: &SynthArgs) -> Result<()> {
    if !(args.noise.is_finite() && args.noise >= 0.0) {
        return Err(Error::argument(
            "--noise",
            format!("must be a finite number >= 0, got {}", args.noise),
        ));
    }
    let material = load_any_material(&args.material)?;
    let capture = open_capture(&args.capture)?;
    check_fits_capture(&material, &args.material, &capture)?;
    let records = ShadingRecords::build(&capture, args.pixel_samples, false)?;
    let folder = StagedFolder::new(&args.output, args.force)?;
    let mut pixels = render_any(&material, &records, args.seed)?;
    if let Some(board) = &args.board {
        let board = crate::board::Board::load(board)?;
        let paper = crate::board::paper::paper_radiance(&board, &capture, args.pixel_samples);
        for (p, q) in pixels.iter_mut().zip(paper) {
            *p = std::array::from_fn(|i| p[i] + q[i]);
        }
    }
    for (flag, given) in [
        ("--distortion", args.distortion),
        ("--vignetting", args.vignetting),
    ] {
        if given.is_none() {
            continue;
        }
        if args.format != SynthFormat::Phone {
            return Err(Error::argument(
                flag,
                "is a phone lens's: give --format phone",
            ));
        }
        for photo in &capture.photos {
            match &photo.camera {
                Camera::Pinhole(p) if p.fx == p.fy => {}
                _ => {
                    return Err(Error::argument(
                        flag,
                        "is a lens's of pinhole cameras with square pixels (fx = fy) only",
                    ))
                }
            }
        }
    }
    for (photo, span) in capture.photos.iter().zip(&records.photos) {
        let Camera::Pinhole(pinhole) = &photo.camera else {
            continue;
        };
        let lens = Intrinsics {
            focal: pinhole.fx,
            cx: pinhole.cx,
            cy: pinhole.cy,
            distortion: args.distortion.unwrap_or([0.0; 2]),
        };
        if args.distortion.is_some() {
            let image = crate::board::phone::distorted(
                &pixels[span.pixels()],
                [span.width, span.height],
                pinhole.fx,
                [pinhole.cx, pinhole.cy],
                lens.distortion,
            );
            pixels[span.pixels()].copy_from_slice(&image);
        }
        if let Some(v) = args.vignetting {
            let vignetting = Vignetting(v);
            for (i, p) in pixels[span.pixels()].iter_mut().enumerate() {
                let factor = vignetting.at_pixel(&lens, i, span.width);
                *p = p.map(|value| value * factor);
            }
        }
    }
    if args.noise > 0.0 {
        for (p, v) in pixels.iter_mut().enumerate() {
            let mut rng = rng_stream(args.seed ^ 0x6E6F_6973_6500_0000, p as u64);
            for c in v.iter_mut() {
                let n: f64 = StandardNormal.sample(&mut rng);
                *c = (*c * (1.0 + args.noise * n)).max(0.0);
            }
        }
    }
    let staging_root = folder.path("");
    if args.format == SynthFormat::Materialgan {
        crate::capture::materialgan_writer::write(&staging_root, &capture, &pixels)?;
        folder.commit()?;
        eprintln!(
            "wrote {} MaterialGAN-format photos to {}",
            records.photos.len(),
            args.output.display()
        );
        return Ok(());
    }
    let mut synthetic = capture.clone();
    synthetic.root = staging_root.clone();
    if args.format == SynthFormat::Phone {
        let gain = 0.9 * display_exposure(&pixels);
        write_phone_jpegs(&staging_root, &records, &pixels, gain, args.jpeg_quality)?;
        for photo in &mut synthetic.photos {
            photo.image = PathBuf::from(format!("{}.jpg", photo.stem()));
            photo.color = ColorEncoding::Srgb;
            photo.exposure *= gain;
        }
    } else {
        write_photo_images(
            &staging_root,
            &records,
            &pixels,
            display_exposure(&pixels),
            "",
        )?;
        for photo in &mut synthetic.photos {
            photo.image = PathBuf::from(format!("{}.exr", photo.stem()));
            photo.color = ColorEncoding::Linear;
        }
    }
    for photo in &mut synthetic.photos {
        photo.mask = None;
        photo.saturated_mask = None;
    }
    synthetic.save_manifest(&folder.path("capture.toml"))?;
    match &material {
        AnyMaterial::Uniform(material) => {
            crate::capture::atomic_file::write_atomically(&folder.path("material.json"), |w| {
                serde_json::to_writer_pretty(&mut *w, material)
                    .map_err(|e| Error::io(args.output.join("material.json"), e))
            })?
        }
        AnyMaterial::Maps(maps) => maps.save(&folder.path("material.json"), Default::default())?,
    }
    folder.commit()?;
    eprintln!(
        "wrote {} photos of {}x{} to {}",
        records.photos.len(),
        records.photos[0].width,
        records.photos[0].height,
        args.output.display()
    );
    Ok(())
}

/// `<stem>.jpg` per photo: linear radiance times `gain`, clipped at 1, sRGB-encoded to 8 bits.
fn write_phone_jpegs(
    folder: &std::path::Path,
    records: &ShadingRecords,
    pixels: &[[f64; 3]],
    gain: f64,
    quality: u8,
) -> Result<()> {
    use crate::capture::image_io::linear_to_srgb;
    for photo in &records.photos {
        let bytes: Vec<u8> = pixels[photo.pixels()]
            .iter()
            .flat_map(|v| {
                v.map(|c| (linear_to_srgb((c * gain).clamp(0.0, 1.0)) * 255.0).round() as u8)
            })
            .collect();
        let path = folder.join(format!("{}.jpg", photo.stem));
        crate::capture::atomic_file::write_atomically(&path, |w| {
            image::codecs::jpeg::JpegEncoder::new_with_quality(w, quality)
                .encode(
                    &bytes,
                    photo.width as u32,
                    photo.height as u32,
                    image::ExtendedColorType::Rgb8,
                )
                .map_err(|e| Error::io(&path, e))
        })?;
    }
    Ok(())
}

pub fn run_render(args: &RenderArgs) -> Result<()> {
    let material = load_any_material(&args.material)?;
    let mut capture = open_capture(&args.capture)?;
    if let Some(depth) = args.depth {
        capture.depth = depth;
    }
    let records = render_records(&material, &args.material, &capture, args.pixel_samples)?;
    let folder = StagedFolder::new(&args.output, args.force)?;
    let pixels = render_any(&material, &records, args.seed)?;
    write_photo_images(
        &folder.path(""),
        &records,
        &pixels,
        display_exposure(&pixels),
        "",
    )?;
    folder.commit()?;
    eprintln!(
        "rendered {} photos to {}",
        records.photos.len(),
        args.output.display()
    );
    Ok(())
}

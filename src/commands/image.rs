//! `bouncefit image OP ...`: the image operations of the fitter, one at a time, on image files,
//! so that independent implementations (OpenCV, Kornia in `tests/crosscheck/`) can check them.
//!
//! | op | input | output (EXR, linear f32) | the fitter's code |
//! | --- | --- | --- | --- |
//! | `decode --color C` | PNG/JPEG (8 or 16 bit) or EXR | linear values | [`load_image`]: how every photo is read |
//! | `encode --color C` | EXR | encoded values, unquantised | [`ColorEncoding::encode`]: what PNG outputs store before rounding |
//! | `downsample` | EXR | half size, 2 x 2 block means, odd last row/column dropped | [`ShadingRecords::coarsened`]: the targets of `--pyramid` levels |
//! | `blur` | EXR | Gaussian window (sigma 1.5, radius 5), zero outside the image | [`ssim::gaussian_blur`]: SSIM's local means |
//! | `ssim PRED TARGET` | two EXR | SSIM per pixel and channel, `L` = brightest target value | [`ssim::similarity`]: the `--loss ssim` map |
//!
//! `C` is `srgb`, `linear` or `gamma:G`. Each op prints one JSON object (`op`, `input`,
//! `output`, `width`, `height`, and for `ssim` the `mean` SSIM) and writes its output atomically,
//! replacing an existing file only with `--force`.

use super::output::check_output_file;
use crate::capture::image_io::{load_image, write_exr, ColorEncoding, LinearImage};
use crate::error::{Error, Result};
use crate::loss::{ssim, ImageLayout};
use crate::shading::{PhotoSpan, ShadingRecords};
use serde_json::json;
use std::path::{Path, PathBuf};

#[derive(clap::Args, Debug)]
pub struct ImageArgs {
    #[command(subcommand)]
    pub op: ImageOp,
    /// Output EXR file.
    #[arg(short, long, global = true)]
    pub output: Option<PathBuf>,
    /// Replace an existing output file.
    #[arg(long, global = true)]
    pub force: bool,
}

#[derive(clap::Subcommand, Debug)]
pub enum ImageOp {
    /// Read an image as the fitter reads a photo: stored values -> linear.
    Decode {
        input: PathBuf,
        /// srgb | linear | gamma:G (default: by file type, EXR linear, PNG/JPEG sRGB).
        #[arg(long)]
        color: Option<ColorEncoding>,
    },
    /// Linear values of an EXR -> encoded values (unquantised).
    Encode {
        input: PathBuf,
        /// srgb | linear | gamma:G
        #[arg(long)]
        color: ColorEncoding,
    },
    /// One level of the fitter's pyramid: 2 x 2 block means.
    Downsample { input: PathBuf },
    /// SSIM's Gaussian window blur (sigma 1.5 px, radius 5), zero outside the image.
    Blur { input: PathBuf },
    /// SSIM map of a prediction against a target, per pixel and channel.
    Ssim {
        prediction: PathBuf,
        target: PathBuf,
    },
}

/// An image of `f64` values, row-major from the top row.
struct Values {
    width: usize,
    height: usize,
    rgb: Vec<[f64; 3]>,
}

impl Values {
    fn of(image: &LinearImage) -> Values {
        Values {
            width: image.width,
            height: image.height,
            rgb: image.rgb.iter().map(|p| p.map(f64::from)).collect(),
        }
    }
}

pub fn run_image(args: &ImageArgs) -> Result<()> {
    let output = args
        .output
        .as_deref()
        .ok_or_else(|| Error::argument("--output", "give the EXR file to write with -o"))?;
    check_output_file(output, args.force)?;
    let linear = |path: &Path| load_image(path, ColorEncoding::Linear);
    let (name, input, result, mut summary) = match &args.op {
        ImageOp::Decode { input, color } => {
            let color = color.unwrap_or_else(|| ColorEncoding::default_for(input));
            let values = Values::of(&load_image(input, color)?);
            ("decode", input, values, json!({"color": color}))
        }
        ImageOp::Encode { input, color } => {
            let mut values = Values::of(&linear(input)?);
            for p in &mut values.rgb {
                *p = p.map(|v| color.encode(v));
            }
            ("encode", input, values, json!({"color": color}))
        }
        ImageOp::Downsample { input } => {
            let values = downsampled(input, &linear(input)?)?;
            ("downsample", input, values, json!({}))
        }
        ImageOp::Blur { input } => {
            let mut values = Values::of(&linear(input)?);
            let size = [values.width, values.height];
            let channels = [0, 1, 2].map(|c| {
                let plane: Vec<f64> = values.rgb.iter().map(|p| p[c]).collect();
                ssim::gaussian_blur(&plane, size)
            });
            for (i, p) in values.rgb.iter_mut().enumerate() {
                *p = [0, 1, 2].map(|c| channels[c][i]);
            }
            ("blur", input, values, json!({}))
        }
        ImageOp::Ssim { prediction, target } => {
            let values = similarity(&linear(prediction)?, target, &linear(target)?)?;
            let mean = values.rgb.iter().flatten().sum::<f64>() / (3 * values.rgb.len()) as f64;
            let summary = json!({"target": target.display().to_string(), "mean": mean});
            ("ssim", prediction, values, summary)
        }
    };
    let rgb: Vec<[f32; 3]> = result.rgb.iter().map(|p| p.map(|v| v as f32)).collect();
    write_exr(output, &rgb, result.width, result.height)?;
    summary["op"] = json!(name);
    summary["input"] = json!(input.display().to_string());
    summary["output"] = json!(output.display().to_string());
    summary["width"] = json!(result.width);
    summary["height"] = json!(result.height);
    println!("{summary}");
    Ok(())
}

/// Shading records of one image with one sample per pixel and every pixel in the loss: the
/// form in which the fitter's pyramid and SSIM read targets.
fn records_of(image: &LinearImage) -> ShadingRecords {
    let n = image.width * image.height;
    ShadingRecords {
        photos: vec![PhotoSpan {
            stem: String::new(),
            width: image.width,
            height: image.height,
            first_pixel: 0,
        }],
        samples_per_pixel: 1,
        wi: vec![[0.0, 0.0, 1.0]; n],
        wo: vec![[0.0, 0.0, 1.0]; n],
        irradiance: vec![[0.0; 3]; n],
        target: Values::of(image).rgb,
        weight: vec![1.0; n],
        ..ShadingRecords::default()
    }
}

fn downsampled(input: &Path, image: &LinearImage) -> Result<Values> {
    let coarse = records_of(image).coarsened().ok_or_else(|| {
        Error::invalid(
            input,
            "resolution",
            "an image smaller than 2 x 2 has no coarser level",
        )
    })?;
    let span = &coarse.photos[0];
    Ok(Values {
        width: span.width,
        height: span.height,
        rgb: coarse.target,
    })
}

/// The SSIM map of `prediction` against the target image (read from `target_path`).
fn similarity(
    prediction: &LinearImage,
    target_path: &Path,
    target: &LinearImage,
) -> Result<Values> {
    if (prediction.width, prediction.height) != (target.width, target.height) {
        return Err(Error::invalid(
            target_path,
            "resolution",
            format!(
                "the target is {}x{} but the prediction is {}x{}",
                target.width, target.height, prediction.width, prediction.height
            ),
        ));
    }
    let records = records_of(target);
    let all: Vec<usize> = (0..records.pixel_count()).collect();
    let layout = ImageLayout::new(&records, &all);
    let predicted = Values::of(prediction).rgb;
    Ok(Values {
        width: target.width,
        height: target.height,
        rgb: ssim::similarity(&layout, &predicted, &records.target, &records.weight),
    })
}

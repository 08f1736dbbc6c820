//! `bouncefit lobe`: a picture of a model's lobe `f(wi, wo) wo.z` over the projected hemisphere of
//! `wo` (PNG, disk of radius 1 = horizon, +x to the right, +y up), and its directional albedo
//! split by bounce count for a list of roughness values.

use super::MaterialArgs;
use crate::albedo::albedo_by_bounce;
use crate::error::{Error, Result};
use crate::lobe::{incidence, lobe_picture};
use crate::material::Material;
use crate::scalar::Vec3;
use serde_json::json;
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct LobeArgs {
    #[command(flatten)]
    pub material: MaterialArgs,
    /// Incidence angle of `wi` from the normal, degrees, in the xz-plane (light toward +x).
    #[arg(long, default_value_t = 45.0, allow_negative_numbers = true)]
    pub theta_i: f64,
    /// PNG of the lobe to write (atomically; an existing file only with --force).
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Replace an existing output file.
    #[arg(long)]
    pub force: bool,
    /// Image side in pixels.
    #[arg(long, default_value_t = 256)]
    pub size: usize,
    /// Evaluations per pixel for stochastic models.
    #[arg(long, default_value_t = 16)]
    pub pixel_samples: usize,
    /// Roughness values of the per-bounce energy table.
    #[arg(long, value_delimiter = ',', default_value = "0.1,0.3,0.6,1.0,1.5")]
    pub table_alphas: Vec<f64>,
    /// Samples per entry of the energy table.
    #[arg(long, default_value_t = 65_536)]
    pub samples: usize,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    #[arg(long)]
    pub json: bool,
}

pub fn run_lobe(args: &LobeArgs) -> Result<()> {
    let material = args.material.material()?;
    if !(0.0..90.0).contains(&args.theta_i) {
        return Err(Error::argument(
            "--theta-i",
            format!("{} is outside [0, 90) degrees", args.theta_i),
        ));
    }
    if args.size == 0 || args.size > 4096 {
        return Err(Error::argument("--size", "must be between 1 and 4096"));
    }
    if let Some(&alpha) = args
        .table_alphas
        .iter()
        .find(|a| !(a.is_finite() && **a > 0.0))
    {
        return Err(Error::argument(
            "--table-alphas",
            format!("{alpha} is not a roughness > 0"),
        ));
    }
    if let Some(path) = &args.output {
        super::output::check_output_file(path, args.force)?;
    }
    let wi = incidence(args.theta_i);
    if let Some(path) = &args.output {
        write_lobe_png(&material, wi, args, path)?;
    }
    let mut rows = Vec::new();
    for &alpha in &args.table_alphas {
        let m = Material {
            alpha: [alpha, alpha * material.alpha[1] / material.alpha[0]],
            ..material.clone()
        };
        let split = albedo_by_bounce(m.brdf().as_ref(), wi, args.samples, args.seed);
        rows.push((alpha, split));
    }
    if args.json {
        let table: Vec<_> = rows.iter().map(|(a, s)| json!({"alpha": a, "by_bounce": s.by_bounce, "resolved": s.resolved, "samples": s.samples})).collect();
        println!(
            "{}",
            json!({"model": material.model.name(), "ndf": material.ndf.name(), "theta_i_deg": args.theta_i, "energy": table})
        );
    } else {
        println!(
            "albedo by bounce, {} {} at theta_i = {} deg (channel means):",
            material.model,
            material.ndf.name(),
            args.theta_i
        );
        println!(
            "{:>8} {:>9} {:>9} {:>9} {:>9} {:>9}",
            "alpha", "1", "2", "3", "4+", "total"
        );
        for (alpha, s) in &rows {
            let mean = |k: usize| s.by_bounce[k].iter().sum::<f64>() / 3.0;
            let total: f64 = (0..4).map(mean).sum();
            if s.resolved {
                println!(
                    "{alpha:>8.3} {:>9.5} {:>9.5} {:>9.5} {:>9.5} {total:>9.5}",
                    mean(0),
                    mean(1),
                    mean(2),
                    mean(3)
                );
            } else {
                println!("{alpha:>8.3} {:>9.5} {:>9} {:>9} {:>9} {total:>9.5}   (2+: {:.5}, not split by bounce)", mean(0), "-", "-", "-", mean(1));
            }
        }
    }
    Ok(())
}

fn write_lobe_png(
    material: &Material,
    wi: Vec3<f64>,
    args: &LobeArgs,
    path: &std::path::Path,
) -> Result<()> {
    let n = args.size;
    let values = lobe_picture(material, wi, n, args.pixel_samples, args.seed);
    let exposure = crate::capture::image_io::display_exposure(&values);
    let rgb: Vec<[f32; 3]> = values.iter().map(|v| v.map(|c| c as f32)).collect();
    crate::capture::image_io::write_png_tonemapped(path, &rgb, n, n, exposure)
}

//! `bouncefit brdf` and `bouncefit albedo`: evaluate one model at one configuration.

use super::{parse_direction, unit_direction, MaterialArgs};
use crate::albedo::directional_albedo;

use crate::bsdf::Brdf;
use crate::random::{rng_stream, Moments};

use crate::error::{Error, Result};
use crate::random::Rng;
use crate::scalar::Vec3;
use serde_json::json;
use std::path::{Path, PathBuf};
use std::time::Instant;

#[derive(clap::Args, Debug)]
pub struct BrdfArgs {
    #[command(flatten)]
    pub material: MaterialArgs,
    /// Direction toward the light, X,Y,Z (normalised by the tool).
    #[arg(long, allow_hyphen_values = true, required_unless_present = "pairs")]
    pub wi: Option<String>,
    /// Direction toward the camera, X,Y,Z.
    #[arg(long, allow_hyphen_values = true, required_unless_present = "pairs")]
    pub wo: Option<String>,
    /// Evaluate many direction pairs in one run: a JSON file `[[wi, wo], ...]` with each
    /// direction `[x, y, z]`; prints JSON with `f` (and `f_single`, `f_multi`, `stderr`) as
    /// lists in the file's order.
    #[arg(long, conflicts_with_all = ["wi", "wo"])]
    pub pairs: Option<PathBuf>,
    /// Monte Carlo samples for stochastic models (analytic models evaluate once).
    #[arg(long, default_value_t = 4096)]
    pub samples: usize,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
}

#[derive(clap::Args, Debug)]
pub struct AlbedoArgs {
    #[command(flatten)]
    pub material: MaterialArgs,
    /// Incidence angle from the normal, degrees, in [0, 90).
    #[arg(long, allow_negative_numbers = true)]
    pub theta_i: f64,
    /// Evaluations (analytic models: a product quadrature of about this many nodes).
    #[arg(long, default_value_t = 65_536)]
    pub samples: usize,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    #[arg(long)]
    pub json: bool,
}

/// `f(wi, wo)` split into the single bounce and the mean of the multi-bounce estimates, with
/// the latter's standard error.
struct Estimate {
    f: [f64; 3],
    single: [f64; 3],
    multi: [f64; 3],
    stderr: [f64; 3],
}

/// Evaluate `f(wi, wo)`; stochastic models average `n` independent estimates.
fn estimate(brdf: &dyn Brdf, wi: Vec3<f64>, wo: Vec3<f64>, n: usize, rng: &mut Rng) -> Estimate {
    let (mut moments, mut single) = (Moments::default(), [0.0; 3]);
    for _ in 0..n {
        let v = brdf.eval(wi, wo, rng);
        single = v.single;
        moments.push(v.multi);
    }
    let multi = moments.mean();
    // An analytic value is exact; one draw of a stochastic one has no error bar (JSON null).
    let stderr = if brdf.is_stochastic() {
        moments.standard_error()
    } else {
        [0.0; 3]
    };
    Estimate {
        f: [0, 1, 2].map(|c| single[c] + multi[c]),
        single,
        multi,
        stderr,
    }
}

/// The direction pairs of a `--pairs` file, each direction normalised and above the surface.
fn read_pairs(path: &Path) -> Result<Vec<(Vec3<f64>, Vec3<f64>)>> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    let pairs: Vec<[[f64; 3]; 2]> = serde_json::from_str(&text).map_err(|e| {
        Error::invalid(
            path,
            "pairs",
            format!("{e}; expected [[[wi_x, wi_y, wi_z], [wo_x, wo_y, wo_z]], ...]"),
        )
    })?;
    pairs
        .iter()
        .enumerate()
        .map(|(k, [wi, wo])| {
            let direction = |name: &str, w: &[f64; 3]| {
                unit_direction(w).map_err(|msg| Error::invalid(path, format!("[{k}].{name}"), msg))
            };
            Ok((direction("wi", wi)?, direction("wo", wo)?))
        })
        .collect()
}

/// Evaluate `f(wi, wo)` at one pair (`--wi`, `--wo`) or at every pair of a `--pairs` file.
pub fn run_brdf(args: &BrdfArgs) -> Result<()> {
    let material = args.material.material()?;
    let pairs = match (&args.pairs, &args.wi, &args.wo) {
        (Some(path), _, _) => read_pairs(path)?,
        (None, Some(wi), Some(wo)) => {
            vec![(parse_direction("--wi", wi)?, parse_direction("--wo", wo)?)]
        }
        _ => {
            return Err(Error::argument(
                "--wi",
                "give --wi and --wo, or --pairs FILE",
            ))
        }
    };
    if args.samples == 0 {
        return Err(Error::argument("--samples", "must be at least 1"));
    }
    let brdf = material.brdf();
    let start = Instant::now();
    let n = if brdf.is_stochastic() {
        args.samples
    } else {
        1
    };
    let mut rng = rng_stream(args.seed, 0);
    let estimates: Vec<Estimate> = pairs
        .iter()
        .map(|&(wi, wo)| estimate(brdf.as_ref(), wi, wo, n, &mut rng))
        .collect();
    let seconds = start.elapsed().as_secs_f64();
    let mut out = json!({
        "model": material.model.name(), "ndf": material.ndf.name(), "height": material.height.name(),
        "alpha": material.alpha, "samples": n, "seconds": seconds,
    });
    let column = |field: fn(&Estimate) -> [f64; 3]| estimates.iter().map(field).collect::<Vec<_>>();
    if args.pairs.is_some() {
        out["pairs"] = json!(pairs.len());
        out["f"] = json!(column(|e| e.f));
        out["f_single"] = json!(column(|e| e.single));
        out["f_multi"] = json!(column(|e| e.multi));
        out["stderr"] = json!(column(|e| e.stderr));
    } else {
        let ((wi, wo), e) = (pairs[0], &estimates[0]);
        out["wi"] = json!(wi.re());
        out["wo"] = json!(wo.re());
        out["f"] = json!(e.f);
        out["f_cos"] = json!(e.f.map(|v| v * wo.z));
        out["f_single"] = json!(e.single);
        out["f_multi"] = json!(e.multi);
        out["stderr"] = json!(e.stderr);
    }
    add_fallback_rate(&mut out, brdf.as_ref());
    print_result(args.json || args.pairs.is_some(), &out, || {
        let Estimate {
            f,
            single,
            multi,
            stderr,
        } = &estimates[0];
        format!("f = {:.6e} {:.6e} {:.6e} 1/sr (single {:.6e} {:.6e} {:.6e}, multi {:.6e} {:.6e} {:.6e} +- {:.1e})", f[0], f[1], f[2], single[0], single[1], single[2], multi[0], multi[1], multi[2], stderr.iter().cloned().fold(0.0, f64::max))
    });
    Ok(())
}

/// Directional albedo at incidence `theta_i`.
pub fn run_albedo(args: &AlbedoArgs) -> Result<()> {
    let material = args.material.material()?;
    if !(0.0..90.0).contains(&args.theta_i) {
        return Err(Error::argument(
            "--theta-i",
            format!("{} is outside [0, 90) degrees", args.theta_i),
        ));
    }
    let t = args.theta_i.to_radians();
    let wi = Vec3::new(t.sin(), 0.0, t.cos());
    let brdf = material.brdf();
    let est = directional_albedo(brdf.as_ref(), wi, args.samples, args.seed);
    let mut out = json!({
        "model": material.model.name(), "ndf": material.ndf.name(), "alpha": material.alpha,
        "theta_i_deg": args.theta_i, "albedo": est.value, "stderr": est.stderr, "samples": est.samples,
    });
    add_fallback_rate(&mut out, brdf.as_ref());
    print_result(args.json, &out, || {
        format!(
            "albedo = {:.6} {:.6} {:.6} (+- {:.1e}, {} samples)",
            est.value[0],
            est.value[1],
            est.value[2],
            est.stderr.iter().cloned().fold(0.0, f64::max),
            est.samples
        )
    });
    Ok(())
}

/// Report the share of paths that took a numerical fallback, for models that count them.
fn add_fallback_rate(out: &mut serde_json::Value, brdf: &dyn crate::bsdf::Brdf) {
    if let Some((fallbacks, paths)) = brdf.fallback_stats() {
        out["fallback_paths"] = json!(fallbacks);
        out["fallback_rate"] = json!(if paths > 0 {
            fallbacks as f64 / paths as f64
        } else {
            0.0
        });
    }
}

fn print_result(as_json: bool, value: &serde_json::Value, human: impl FnOnce() -> String) {
    if as_json {
        println!("{value}");
    } else {
        println!("{}", human());
    }
}

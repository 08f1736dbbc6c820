//! The command-line commands (DESIGN.md "Command-line contract"). `src/main.rs` only parses
//! arguments and maps errors to exit codes; each command lives in its own file here.

pub mod bench;
pub mod brdf;
pub mod capture;
pub mod compare;
pub mod export;
pub mod fit;
pub mod fit_args;
pub mod fit_maps;
pub mod image;
pub mod images;
pub mod inputs;
pub mod lobe;
pub mod output;
pub mod records;
pub mod relight;
pub mod stress;
pub mod synth;

use crate::bsdf::Model;
use crate::error::{Error, Result};
use crate::material::{FresnelSpec, Material};
use crate::microfacet::{Height, NdfKind};
use crate::scalar::Vec3;

/// Material options shared by `brdf` and `albedo`.
#[derive(clap::Args, Debug, Clone)]
pub struct MaterialArgs {
    /// Model name (single, ...).
    #[arg(long)]
    pub model: Model,
    /// Distribution of normals.
    #[arg(long, default_value = "ggx")]
    pub ndf: NdfKind,
    /// Isotropic roughness alpha (not perceptual roughness).
    #[arg(long, allow_hyphen_values = true, conflicts_with_all = ["alpha_x", "alpha_y"], required_unless_present_all = ["alpha_x", "alpha_y"])]
    pub alpha: Option<f64>,
    /// Roughness along x (with --alpha-y).
    #[arg(long, allow_hyphen_values = true, requires = "alpha_y")]
    pub alpha_x: Option<f64>,
    /// Roughness along y (with --alpha-x).
    #[arg(long, allow_hyphen_values = true, requires = "alpha_x")]
    pub alpha_y: Option<f64>,
    /// white | conductor:ETA_R,ETA_G,ETA_B:K_R,K_G,K_B | schlick:R,G,B | dielectric:ETA
    #[arg(long, default_value = "white")]
    pub fresnel: String,
    /// Height correlation of masking and shadowing.
    #[arg(long, default_value = "correlated")]
    pub height: Height,
}

impl MaterialArgs {
    /// The material these options describe, validated.
    pub fn material(&self) -> Result<Material> {
        let alpha = match (self.alpha, self.alpha_x, self.alpha_y) {
            (Some(a), _, _) => [a, a],
            (None, Some(x), Some(y)) => [x, y],
            _ => {
                return Err(Error::argument(
                    "--alpha",
                    "give --alpha or both --alpha-x and --alpha-y",
                ))
            }
        };
        let material = Material {
            model: self.model,
            ndf: self.ndf,
            height: self.height,
            alpha,
            fresnel: FresnelSpec::parse(&self.fresnel)?,
            diffuse: [0.0; 3],
        };
        material
            .validate()
            .map_err(|(field, msg)| Error::argument(format!("--{field}"), msg))?;
        Ok(material)
    }
}

/// Parse `X,Y,Z` into a unit direction above the surface (reflection-only models).
pub fn parse_direction(flag: &str, text: &str) -> Result<Vec3<f64>> {
    let v: Vec<f64> = text
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| Error::argument(flag, format!("'{text}' is not X,Y,Z")))?;
    let [x, y, z] = v[..] else {
        return Err(Error::argument(flag, format!("'{text}' is not X,Y,Z")));
    };
    unit_direction(&[x, y, z]).map_err(|msg| Error::argument(flag, format!("'{text}' {msg}")))
}

/// `[x, y, z]` normalised, if it is a direction above the surface; else what is wrong with it.
pub fn unit_direction(xyz: &[f64; 3]) -> std::result::Result<Vec3<f64>, String> {
    let w = Vec3::new(xyz[0], xyz[1], xyz[2]);
    let len = w.length();
    if !len.is_finite() || len == 0.0 {
        return Err("is not a direction (zero or non-finite length)".to_string());
    }
    let w = w * (1.0 / len);
    if w.z <= 0.0 {
        return Err(
            "points below or along the surface (z <= 0); reflection models need z > 0".to_string(),
        );
    }
    Ok(w)
}

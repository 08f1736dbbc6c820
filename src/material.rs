//! The material file (DESIGN.md "Material / fit file"): model, distribution, roughness,
//! Fresnel and an optional Lambertian diffuse albedo; and the `--fresnel` syntax of the CLI.
//!
//! A fit file is a material file with more fields (loss, trace, timings), so reading ignores
//! fields it does not know.

use crate::bsdf::single::SingleBounce;
use crate::bsdf::{registry, BounceCap, Brdf, Model};
use crate::error::{Error, Result};
use crate::microfacet::{Fresnel, Height, Microfacet, NdfKind};
use crate::scalar::{Real, Rgb};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Fresnel parameters as stored in material files.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase", deny_unknown_fields)]
pub enum FresnelSpec {
    White,
    Schlick { f0: [f64; 3] },
    Conductor { eta: [f64; 3], k: [f64; 3] },
    Dielectric { eta: f64 },
}

impl FresnelSpec {
    /// Parse the command-line syntax `white`, `schlick:R,G,B`,
    /// `conductor:ETA_R,ETA_G,ETA_B:K_R,K_G,K_B` or `dielectric:ETA`.
    pub fn parse(text: &str) -> Result<Self> {
        let bad = |msg: &str| Error::argument("--fresnel", format!("'{text}': {msg}"));
        let triple = |s: &str| -> Result<[f64; 3]> {
            let v: Vec<f64> = s
                .split(',')
                .map(|x| x.trim().parse::<f64>())
                .collect::<Result<_, _>>()
                .map_err(|_| bad("expected numbers"))?;
            match v.as_slice() {
                [x] => Ok([*x; 3]),
                [r, g, b] => Ok([*r, *g, *b]),
                _ => Err(bad("expected one or three comma-separated numbers")),
            }
        };
        let parts: Vec<&str> = text.split(':').collect();
        let spec = match parts.as_slice() {
            ["white"] => FresnelSpec::White,
            ["schlick", f0] => FresnelSpec::Schlick { f0: triple(f0)? },
            ["conductor", eta, k] => FresnelSpec::Conductor { eta: triple(eta)?, k: triple(k)? },
            ["dielectric", eta] => FresnelSpec::Dielectric { eta: eta.trim().parse().map_err(|_| bad("expected a number"))? },
            _ => return Err(bad("expected white, schlick:R,G,B, conductor:ETA_R,ETA_G,ETA_B:K_R,K_G,K_B or dielectric:ETA")),
        };
        spec.validate().map_err(|msg| bad(&msg))?;
        Ok(spec)
    }

    /// Physical ranges: Schlick F0 in [0, 1], eta > 0, k >= 0, all finite.
    pub fn validate(&self) -> std::result::Result<(), String> {
        let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
        match self {
            FresnelSpec::White => Ok(()),
            FresnelSpec::Schlick { f0 }
                if finite(f0) && f0.iter().all(|&x| (0.0..=1.0).contains(&x)) =>
            {
                Ok(())
            }
            FresnelSpec::Schlick { .. } => Err("Schlick f0 must lie in [0, 1]".into()),
            FresnelSpec::Conductor { eta, k }
                if finite(eta)
                    && finite(k)
                    && eta.iter().all(|&x| x > 0.0)
                    && k.iter().all(|&x| x >= 0.0) =>
            {
                Ok(())
            }
            FresnelSpec::Conductor { .. } => Err("conductor eta must be > 0 and k >= 0".into()),
            FresnelSpec::Dielectric { eta } if eta.is_finite() && *eta > 0.0 => Ok(()),
            FresnelSpec::Dielectric { .. } => Err("dielectric eta must be > 0".into()),
        }
    }

    /// The kernel's Fresnel at scalar type `T` (constants: no derivative part).
    pub fn to_fresnel<T: Real>(&self) -> Fresnel<T> {
        match *self {
            FresnelSpec::White => Fresnel::White,
            FresnelSpec::Schlick { f0 } => Fresnel::Schlick {
                f0: Rgb::from_f64(f0),
            },
            FresnelSpec::Conductor { eta, k } => Fresnel::Conductor {
                eta: Rgb::from_f64(eta),
                k: Rgb::from_f64(k),
            },
            FresnelSpec::Dielectric { eta } => Fresnel::Dielectric { eta: T::c(eta) },
        }
    }

    /// Reflectance at normal incidence, per channel.
    pub fn f0(&self) -> [f64; 3] {
        self.to_fresnel::<f64>().f0().0
    }
}

/// Roughness as stored: one number (isotropic) or `[alpha_x, alpha_y]`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
enum AlphaField {
    Isotropic(f64),
    Anisotropic([f64; 2]),
}

fn deserialize_alpha<'de, D: serde::Deserializer<'de>>(
    d: D,
) -> std::result::Result<[f64; 2], D::Error> {
    AlphaField::deserialize(d).map(<[f64; 2]>::from)
}

impl From<AlphaField> for [f64; 2] {
    fn from(alpha: AlphaField) -> [f64; 2] {
        match alpha {
            AlphaField::Isotropic(a) => [a, a],
            AlphaField::Anisotropic(a) => a,
        }
    }
}

/// The keys of a material file.
const MATERIAL_FIELDS: [&str; 6] = ["model", "ndf", "height", "alpha", "fresnel", "diffuse"];

/// The key every fit file has and no material file: its extra keys are not warned about.
const FIT_FILE_MARKER: &str = "version";

/// serde_json's message without its trailing "at line L column C" (the caller names the place).
fn json_message(error: &serde_json::Error) -> String {
    let message = error.to_string();
    match message.rfind(" at line ") {
        Some(end) => message[..end].to_string(),
        None => message,
    }
}

/// Removes `key` from a material file's `fields` and deserialises it; a wrong value is an
/// error naming the key and what was `expected`.
fn optional<T: serde::de::DeserializeOwned>(
    path: &Path,
    fields: &mut serde_json::Map<String, serde_json::Value>,
    key: &str,
    expected: &str,
) -> Result<Option<T>> {
    fields
        .remove(key)
        .map(|value| {
            serde_json::from_value(value).map_err(|e| {
                Error::invalid(
                    path,
                    key,
                    format!("{}; expected {expected}", json_message(&e)),
                )
            })
        })
        .transpose()
}

/// Like [`optional`], but a missing key is an error.
fn required<T: serde::de::DeserializeOwned>(
    path: &Path,
    fields: &mut serde_json::Map<String, serde_json::Value>,
    key: &str,
    expected: &str,
) -> Result<T> {
    optional(path, fields, key, expected)?
        .ok_or_else(|| Error::invalid(path, key, format!("missing; expected {expected}")))
}

/// The top-level JSON object of the material or fit file `path`; syntax errors name the line
/// and column.
pub fn read_json_object(path: &Path) -> Result<serde_json::Map<String, serde_json::Value>> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    let value: serde_json::Value = serde_json::from_str(&text).map_err(|e| {
        Error::invalid(
            path,
            format!("line {} column {}", e.line(), e.column()),
            format!("{}; expected a JSON material file", json_message(&e)),
        )
    })?;
    match value {
        serde_json::Value::Object(fields) => Ok(fields),
        _ => Err(Error::invalid(
            path,
            "top level",
            "expected a JSON object {\"model\": ..., \"alpha\": ..., \"fresnel\": ...}",
        )),
    }
}

/// A homogeneous material: a specular microfacet model plus an optional Lambertian layer,
/// `f = f_model + diffuse / pi`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Material {
    pub model: Model,
    #[serde(default)]
    pub ndf: NdfKind,
    #[serde(default)]
    pub height: Height,
    /// Microfacet roughness `[alpha_x, alpha_y]` (not perceptual roughness).
    #[serde(deserialize_with = "deserialize_alpha")]
    pub alpha: [f64; 2],
    pub fresnel: FresnelSpec,
    /// Lambertian albedo per channel in [0, 1].
    #[serde(default)]
    pub diffuse: [f64; 3],
}

impl Material {
    /// Read and validate a material or fit file; errors name the file and the field.
    pub fn load(path: &Path) -> Result<Self> {
        Material::load_with_warnings(path).map(|(material, _)| material)
    }

    /// [`Material::load`], also returning a warning for every key of a material file that is
    /// not a material field (a misspelt `difuse` would otherwise be silently ignored). Fit
    /// files, recognised by their `version` field, carry many more fields and get no warnings.
    ///
    /// Each field is read on its own so that a wrong type names its key; JSON syntax errors
    /// name the line and column.
    pub fn load_with_warnings(path: &Path) -> Result<(Self, Vec<String>)> {
        Material::from_fields(path, read_json_object(path)?)
    }

    /// [`Material::load_with_warnings`] from the already parsed top-level object of `path`.
    pub fn from_fields(
        path: &Path,
        mut fields: serde_json::Map<String, serde_json::Value>,
    ) -> Result<(Self, Vec<String>)> {
        let warnings = if fields.contains_key(FIT_FILE_MARKER) {
            Vec::new()
        } else {
            fields
                .keys()
                .filter(|key| !MATERIAL_FIELDS.contains(&key.as_str()))
                .map(|key| format!("{}: {key}: unknown key, ignored", path.display()))
                .collect()
        };
        let material = Material {
            model: required(
                path,
                &mut fields,
                "model",
                "a model name such as \"single\"",
            )?,
            ndf: optional(path, &mut fields, "ndf", "\"ggx\" or \"beckmann\"")?.unwrap_or_default(),
            height: optional(
                path,
                &mut fields,
                "height",
                "\"correlated\" or \"uncorrelated\"",
            )?
            .unwrap_or_default(),
            alpha: required::<AlphaField>(
                path,
                &mut fields,
                "alpha",
                "a number or [alpha_x, alpha_y]",
            )?
            .into(),
            fresnel: required(
                path,
                &mut fields,
                "fresnel",
                "an object such as {\"kind\": \"conductor\", \"eta\": [r, g, b], \"k\": [r, g, b]}",
            )?,
            diffuse: optional(path, &mut fields, "diffuse", "[r, g, b] in [0, 1]")?
                .unwrap_or_default(),
        };
        material
            .validate()
            .map_err(|(field, msg)| Error::invalid(path, field, msg))?;
        Ok((material, warnings))
    }

    /// Check physical ranges; returns the offending field and the reason.
    pub fn validate(&self) -> std::result::Result<(), (String, String)> {
        if !self.alpha.iter().all(|a| a.is_finite() && *a > 0.0) {
            return Err((
                "alpha".into(),
                format!("roughness must be finite and > 0, got {:?}", self.alpha),
            ));
        }
        self.fresnel
            .validate()
            .map_err(|m| ("fresnel".to_string(), m))?;
        if !self
            .diffuse
            .iter()
            .all(|d| d.is_finite() && (0.0..=1.0).contains(d))
        {
            return Err((
                "diffuse".into(),
                format!("albedo must lie in [0, 1], got {:?}", self.diffuse),
            ));
        }
        Ok(())
    }

    /// The single-bounce model of this material at scalar type `T`.
    pub fn single<T: Real>(&self) -> SingleBounce<T> {
        SingleBounce {
            microfacet: Microfacet::new(self.ndf, T::c(self.alpha[0]), T::c(self.alpha[1])),
            fresnel: self.fresnel.to_fresnel(),
            height: self.height,
        }
    }

    /// The specular model as a BRDF object (the diffuse layer is added by the renderer).
    pub fn brdf(&self) -> Box<dyn Brdf> {
        self.capped_brdf(BounceCap::NONE)
    }

    /// [`Material::brdf`] with the stochastic estimators limited to paths of `cap` reflections
    /// (the analytic models ignore it).
    pub fn capped_brdf(&self, cap: BounceCap) -> Box<dyn Brdf> {
        registry::brdf(self.model, self.single(), cap)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn design_example_parses_and_round_trips() {
        let text = r#"{"model": "single", "ndf": "ggx", "height": "correlated",
            "alpha": [0.3, 0.3],
            "fresnel": {"kind": "conductor", "eta": [0.2, 0.92, 1.1], "k": [3.9, 2.45, 2.14]},
            "diffuse": [0.0, 0.0, 0.0], "loss": 0.5}"#;
        let m: Material = serde_json::from_str(text).unwrap();
        assert_eq!(m.alpha, [0.3, 0.3]);
        let back: Material = serde_json::from_str(&serde_json::to_string(&m).unwrap()).unwrap();
        assert_eq!(m, back);
        let iso: Material =
            serde_json::from_str(r#"{"model":"single","alpha":0.2,"fresnel":{"kind":"white"}}"#)
                .unwrap();
        assert_eq!(iso.alpha, [0.2, 0.2]);
        assert_eq!(iso.ndf, NdfKind::Ggx);
    }

    #[test]
    fn cli_fresnel_syntax() {
        assert_eq!(FresnelSpec::parse("white").unwrap(), FresnelSpec::White);
        assert_eq!(
            FresnelSpec::parse("schlick:0.9,0.6,0.3").unwrap(),
            FresnelSpec::Schlick {
                f0: [0.9, 0.6, 0.3]
            }
        );
        assert_eq!(
            FresnelSpec::parse("conductor:0.2,0.9,1.1:3.9,2.4,2.1").unwrap(),
            FresnelSpec::Conductor {
                eta: [0.2, 0.9, 1.1],
                k: [3.9, 2.4, 2.1]
            }
        );
        assert_eq!(
            FresnelSpec::parse("dielectric:1.5").unwrap(),
            FresnelSpec::Dielectric { eta: 1.5 }
        );
        for bad in [
            "gold",
            "schlick:1.2,0,0",
            "conductor:1,1,1",
            "dielectric:-1",
            "schlick:a,b,c",
            "conductor:0,1,1:1,1,1",
        ] {
            assert!(FresnelSpec::parse(bad).is_err(), "{bad}");
        }
    }
}

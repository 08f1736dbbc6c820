//! Maps material files: a material file (DESIGN.md "Material / fit file") whose `maps` object
//! names one image per mapped parameter, relative to the JSON file's folder:
//!
//! ```json
//! {"model": "kulla-conty", "ndf": "ggx", "height": "correlated",
//!  "maps": {"diffuse": "tile.maps/diffuse.png", "specular": "tile.maps/specular.png",
//!           "roughness": "tile.maps/roughness.exr", "normal": "tile.maps/normal.png"}}
//! ```
//!
//! | map | encoding read | written by bouncefit |
//! | --- | --- | --- |
//! | `diffuse`, `specular` | EXR and 16-bit PNG: linear values; 8-bit PNG/JPEG: sRGB-encoded (the texture convention of glTF and of paint programs) | 16-bit PNG, linear |
//! | `roughness` | `alpha` itself (not perceptual roughness): R along the sample's x, G along its y (a grey image is isotropic; B is not read); EXR any value > 0; PNG `code / max` in (0, 1] | EXR (`alpha_x` in R, `alpha_y` in G, `sqrt(alpha_x alpha_y)` in B: grey where isotropic) |
//! | `normal` | `n = 2 code / max - 1` per channel (OpenGL/glTF convention: +y up), normalised; `n.z > 0` | 16-bit PNG |
//!
//! Every map must have the same resolution, which is the texel grid's. Parameters without a map
//! take the file's uniform `alpha`, `fresnel`, `diffuse` (then optional where a map replaces
//! them). Errors name the file and the map or texel: a missing image, images of different
//! sizes, non-finite or out-of-range texels, a normal below the surface.

use super::fit::Uncertainty;
use super::{AnyMaterial, MaterialMaps, TexelGrid};
use crate::capture::atomic_file::write_atomically;
use crate::capture::image_io::{load_image, srgb_to_linear, write_exr, ColorEncoding};
use crate::capture::Sample;
use crate::error::{Error, Result};
use crate::material::{read_json_object, Material};
use serde_json::{json, Value};
use std::path::{Path, PathBuf};

/// The map names a `maps` object may hold, in the order they are read and written.
pub const MAP_NAMES: [&str; 4] = ["diffuse", "specular", "roughness", "normal"];

/// File names bouncefit writes the maps under (inside a `<name>.maps/` folder).
const WRITTEN: [(&str, &str); 4] = [
    ("diffuse", "diffuse.png"),
    ("specular", "specular.png"),
    ("roughness", "roughness.exr"),
    ("normal", "normal.png"),
];

impl AnyMaterial {
    /// Read a material or fit file, uniform or with maps; also returns the warnings of unknown
    /// keys ([`Material::load_with_warnings`]).
    pub fn load_with_warnings(path: &Path) -> Result<(AnyMaterial, Vec<String>)> {
        let mut fields = read_json_object(path)?;
        let Some(maps) = fields.remove("maps") else {
            return Material::from_fields(path, fields).map(|(m, w)| (AnyMaterial::Uniform(m), w));
        };
        let maps = map_paths(path, &maps)?;
        let has = |name: &str| maps.iter().any(|(n, _)| *n == name);
        // Uniform values a map replaces need not be given: placeholders, overwritten per texel.
        if has("roughness") && !fields.contains_key("alpha") {
            fields.insert("alpha".into(), json!(1.0));
        }
        if has("specular") && !fields.contains_key("fresnel") {
            fields.insert(
                "fresnel".into(),
                json!({"kind": "schlick", "f0": [0.04, 0.04, 0.04]}),
            );
        }
        let (base, warnings) = Material::from_fields(path, fields)?;
        let mut loaded = MaterialMaps::uniform(&base);
        let mut grid: Option<(TexelGrid, &PathBuf)> = None;
        for (name, image) in &maps {
            let (texels, size) = read_map(name, image)?;
            match grid {
                Some((first, first_path)) if first != size => {
                    return Err(Error::invalid(
                        image,
                        "resolution",
                        format!(
                            "map `{name}` is {}x{} but {} is {}x{}; expected every map of {} \
                             at one resolution",
                            size.width,
                            size.height,
                            first_path.display(),
                            first.width,
                            first.height,
                            path.display()
                        ),
                    ))
                }
                _ => grid = Some((size, image)),
            }
            match *name {
                "diffuse" => loaded.diffuse = Some(texels.iter().map(|t| t.rgb).collect()),
                "specular" => loaded.specular = Some(texels.iter().map(|t| t.rgb).collect()),
                "roughness" => {
                    loaded.roughness = Some(texels.iter().map(|t| [t.rgb[0], t.rgb[1]]).collect())
                }
                _ => loaded.normal = Some(texels.iter().map(|t| t.rgb).collect()),
            }
        }
        loaded.grid = grid.expect("map_paths refuses an empty maps object").0;
        Ok((AnyMaterial::Maps(loaded), warnings))
    }
}

/// The `(name, image path)` pairs of a `maps` object, paths resolved against the material
/// file's folder.
fn map_paths(path: &Path, maps: &Value) -> Result<Vec<(&'static str, PathBuf)>> {
    let expected =
        "an object {\"diffuse\" | \"specular\" | \"roughness\" | \"normal\": \"image file\"}";
    let Value::Object(entries) = maps else {
        return Err(Error::invalid(path, "maps", format!("expected {expected}")));
    };
    let folder = path.parent().unwrap_or(Path::new("."));
    for key in entries.keys() {
        if !MAP_NAMES.contains(&key.as_str()) {
            return Err(Error::invalid(
                path,
                format!("maps.{key}"),
                "unknown map; expected diffuse, specular, roughness or normal",
            ));
        }
    }
    let mut out = Vec::new();
    for name in MAP_NAMES {
        match entries.get(name) {
            None => {}
            Some(Value::String(file)) => out.push((name, folder.join(file))),
            Some(_) => {
                return Err(Error::invalid(
                    path,
                    format!("maps.{name}"),
                    "expected the image file's path as a string",
                ))
            }
        }
    }
    if out.is_empty() {
        return Err(Error::invalid(
            path,
            "maps",
            format!("no map given; expected {expected}"),
        ));
    }
    Ok(out)
}

/// One texel of a map image, decoded.
struct Texel {
    rgb: [f64; 3],
}

/// Whether an integer image stores 8 bits per channel (then colour maps are sRGB-encoded).
fn is_eight_bit(image: &Path) -> Result<bool> {
    use image::ImageDecoder;
    let extension = image
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    if extension.as_deref() == Some("exr") {
        return Ok(false);
    }
    let decoder = image::ImageReader::open(image)
        .and_then(|r| r.with_guessed_format())
        .map_err(|e| Error::io(image, e))?
        .into_decoder()
        .map_err(|e| {
            Error::invalid(
                image,
                "image data",
                format!("{e}; expected a PNG, JPEG or EXR map"),
            )
        })?;
    Ok(decoder.color_type().bytes_per_pixel() / decoder.color_type().channel_count() == 1)
}

/// Reads the map `name` from `image` and checks every texel's range (see the module table).
fn read_map(name: &str, image: &Path) -> Result<(Vec<Texel>, TexelGrid)> {
    let colour = matches!(name, "diffuse" | "specular");
    let srgb = colour && is_eight_bit(image)?;
    let decoded = load_image(image, ColorEncoding::Linear)?;
    let grid = TexelGrid {
        width: decoded.width,
        height: decoded.height,
    };
    if grid.is_empty() {
        return Err(Error::invalid(image, "resolution", "the map has no texels"));
    }
    let integer = !image
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("exr"));
    let mut texels = Vec::with_capacity(grid.len());
    for (index, value) in decoded.rgb.iter().enumerate() {
        let at = || {
            format!(
                "texel ({}, {}) of map `{name}`",
                index % grid.width,
                index / grid.width
            )
        };
        let mut rgb = value.map(f64::from);
        if rgb.iter().any(|v| !v.is_finite()) {
            return Err(Error::invalid(
                image,
                at(),
                format!("{rgb:?} is not finite"),
            ));
        }
        if srgb {
            rgb = rgb.map(srgb_to_linear);
        }
        match name {
            "diffuse" | "specular" if rgb.iter().any(|v| !(0.0..=1.0).contains(v)) => {
                return Err(Error::invalid(
                    image,
                    at(),
                    format!("{rgb:?}: expected values in [0, 1]"),
                ))
            }
            "roughness" if rgb[0] <= 0.0 || rgb[1] <= 0.0 => {
                return Err(Error::invalid(
                    image,
                    at(),
                    format!(
                        "alpha_x {}, alpha_y {} (red, green) must be > 0 (roughness maps store \
                         alpha itself)",
                        rgb[0], rgb[1]
                    ),
                ))
            }
            "normal" => {
                let n = if integer {
                    rgb.map(|v| 2.0 * v - 1.0)
                } else {
                    rgb
                };
                let length = n.iter().map(|v| v * v).sum::<f64>().sqrt();
                if !(length > 1e-6 && n[2] / length > 1e-3) {
                    return Err(Error::invalid(
                        image,
                        at(),
                        format!("normal {n:?} is not above the surface (n.z must be > 0)"),
                    ));
                }
                rgb = n.map(|v| v / length);
            }
            _ => {}
        }
        texels.push(Texel { rgb });
    }
    Ok((texels, grid))
}

impl MaterialMaps {
    /// Refuses a texel grid whose texels are not square on `sample` (within 1%): the maps were
    /// made for a sample of another shape (`path` names the material file).
    pub fn check_sample(&self, path: &Path, sample: &Sample) -> Result<()> {
        if self.grid.len() == 1 {
            return Ok(());
        }
        let texel_aspect =
            (sample.width / self.grid.width as f64) / (sample.height / self.grid.height as f64);
        if (texel_aspect - 1.0).abs() > 0.01 {
            return Err(Error::invalid(
                path,
                "maps resolution",
                format!(
                    "a {}x{} texel grid on a {} x {} sample has texels of aspect {texel_aspect:.3}; \
                     expected square texels (a grid of the sample's proportions)",
                    self.grid.width, self.grid.height, sample.width, sample.height
                ),
            ));
        }
        Ok(())
    }

    /// The folder of the maps of the material file `path`: `<path without extension>.maps/`.
    pub fn folder_beside(path: &Path) -> PathBuf {
        path.with_extension("maps")
    }

    /// Writes the material file `path` (the base material's fields, `extra` fields such as a
    /// fit's report, and `maps`) and its maps into [`MaterialMaps::folder_beside`] it, each file
    /// atomically.
    pub fn save(&self, path: &Path, extra: serde_json::Map<String, Value>) -> Result<()> {
        let folder = MaterialMaps::folder_beside(path);
        std::fs::create_dir_all(&folder).map_err(|e| Error::io(&folder, e))?;
        let name = folder.file_name().unwrap_or_default().to_string_lossy();
        let maps = self.write_images(&folder, &name)?;
        self.save_json(path, maps, extra)
    }

    /// Writes the material file `path` naming the already written `maps` object, with `extra`
    /// fields, atomically.
    pub fn save_json(
        &self,
        path: &Path,
        maps: Value,
        extra: serde_json::Map<String, Value>,
    ) -> Result<()> {
        let document = self.document(maps, extra);
        write_atomically(path, |w| {
            serde_json::to_writer_pretty(&mut *w, &document).map_err(|e| Error::io(path, e))
        })
    }

    /// The material file [`MaterialMaps::save_json`] writes: the base material, `extra`, and
    /// `maps` (the object [`MaterialMaps::write_images`] returns).
    pub fn document(&self, maps: Value, extra: serde_json::Map<String, Value>) -> Value {
        let Value::Object(mut fields) =
            serde_json::to_value(&self.base).expect("a material serialises")
        else {
            unreachable!("a material serialises to an object")
        };
        fields.extend(extra);
        fields.insert("maps".into(), maps);
        Value::Object(fields)
    }

    /// Writes the maps this material has into `folder` (which must exist) and returns the
    /// `maps` object naming them as `<prefix>/<file>` (`prefix`: the folder as the material
    /// file will see it).
    pub fn write_images(&self, folder: &Path, prefix: &str) -> Result<Value> {
        let TexelGrid { width, height } = self.grid;
        let mut entries = serde_json::Map::new();
        for (name, file) in WRITTEN {
            let path = folder.join(file);
            match name {
                "diffuse" | "specular" | "normal" => {
                    let texels = match name {
                        "diffuse" => self.diffuse.as_ref(),
                        "specular" => self.specular.as_ref(),
                        _ => self.normal.as_ref(),
                    };
                    let Some(texels) = texels else { continue };
                    let encode = |v: f64| if name == "normal" { 0.5 * v + 0.5 } else { v };
                    write_png16(&path, texels, width, height, encode)?;
                }
                _ => {
                    let Some(alpha) = &self.roughness else {
                        continue;
                    };
                    let rgb: Vec<[f32; 3]> = alpha
                        .iter()
                        .map(|&[ax, ay]| [ax, ay, (ax * ay).sqrt()].map(|a| a as f32))
                        .collect();
                    write_exr(&path, &rgb, width, height)?;
                }
            }
            entries.insert(name.into(), Value::String(format!("{prefix}/{file}")));
        }
        Ok(Value::Object(entries))
    }
}

impl Uncertainty {
    /// Writes the standard-deviation maps into `folder` (which must exist) as EXR, each file
    /// atomically, and returns the fit file's `uncertainty` object: each map as `<prefix>/<file>`
    /// (`prefix`: the folder as the fit file sees it) with the coordinate its sd is of.
    pub fn write_images(&self, folder: &Path, prefix: &str) -> Result<Value> {
        let TexelGrid { width, height } = self.grid;
        let mut entries = serde_json::Map::new();
        entries.insert("method".into(), json!("laplace"));
        for (name, texels, sd_of) in [
            ("roughness_sd", Some(&self.roughness), "ln_alpha"),
            ("specular_sd", self.specular.as_ref(), "f0"),
            ("diffuse_sd", Some(&self.diffuse), "albedo"),
        ] {
            let Some(texels) = texels else { continue };
            let file = format!("{name}.exr");
            write_exr(&folder.join(&file), texels, width, height)?;
            entries.insert(
                name.into(),
                json!({"file": format!("{prefix}/{file}"), "sd_of": sd_of}),
            );
        }
        Ok(Value::Object(entries))
    }
}

/// Writes per-texel values as a 16-bit RGB PNG, `encode`d and clamped to [0, 1], atomically.
pub(crate) fn write_png16(
    path: &Path,
    texels: &[[f64; 3]],
    width: usize,
    height: usize,
    encode: impl Fn(f64) -> f64,
) -> Result<()> {
    use image::ImageEncoder;
    let bytes: Vec<u8> = texels
        .iter()
        .flatten()
        .flat_map(|&v| {
            let code = (encode(v).clamp(0.0, 1.0) * 65535.0).round() as u16;
            code.to_ne_bytes()
        })
        .collect();
    let too_large = || Error::invalid(path, "texels", "too many texels for a PNG");
    let (w, h) = (
        u32::try_from(width).map_err(|_| too_large())?,
        u32::try_from(height).map_err(|_| too_large())?,
    );
    write_atomically(path, |file| {
        image::codecs::png::PngEncoder::new(file)
            .write_image(&bytes, w, h, image::ExtendedColorType::Rgb16)
            .map_err(|e| Error::io(path, e))
    })
}

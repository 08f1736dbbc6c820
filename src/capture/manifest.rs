//! Reading and writing `capture.toml` (DESIGN.md "Photo-set manifest").
//!
//! Reading walks the TOML tree key by key so that every error names the manifest and the full
//! field path (`photo[3].light.intensity`), with serde's message for wrong types, and so that
//! unknown keys become warnings instead of errors. Writing serialises the resolved capture.

use std::io::Write;
use std::path::{Path, PathBuf};

use glam::DVec3;
use serde::de::DeserializeOwned;

use super::atomic_file::write_atomically;
use super::{absolute_folder, checks, folder_of};
use super::{Camera, Capture, ColorEncoding, Light, Photo, Pinhole, Rectified, Sample};
use crate::error::{Error, Result};

/// One TOML table being read: its remaining entries and its field path in the manifest.
struct Table<'a> {
    manifest: &'a Path,
    /// Field path of this table (`""` for the top level, `photo[2].light`, ...).
    path: String,
    entries: toml::Table,
}

impl<'a> Table<'a> {
    fn field(&self, key: &str) -> String {
        if self.path.is_empty() {
            key.to_string()
        } else {
            format!("{}.{key}", self.path)
        }
    }

    fn error(&self, key: &str, message: impl Into<String>) -> Error {
        Error::invalid(self.manifest, self.field(key), message)
    }

    /// Removes `key`, deserialises it as `T` and passes it through `check`.
    fn optional<T: DeserializeOwned, U>(
        &mut self,
        key: &str,
        check: impl FnOnce(T) -> Result<U, String>,
    ) -> Result<Option<U>> {
        let Some(value) = self.entries.remove(key) else {
            return Ok(None);
        };
        let typed: T = value
            .try_into()
            .map_err(|e: toml::de::Error| self.error(key, e.message()))?;
        check(typed)
            .map(Some)
            .map_err(|message| self.error(key, message))
    }

    /// Like [`Table::optional`], but a missing key is an error.
    fn required<T: DeserializeOwned, U>(
        &mut self,
        key: &str,
        check: impl FnOnce(T) -> Result<U, String>,
    ) -> Result<U> {
        self.optional(key, check)?.ok_or_else(|| {
            let table = if self.path.is_empty() {
                "the top level".to_string()
            } else {
                self.path.clone()
            };
            self.error(key, format!("missing; add `{key} = ...` to {table}"))
        })
    }

    /// Like [`Table::optional`], remembering where the value came from.
    fn sourced<T: DeserializeOwned, U>(
        &mut self,
        key: &str,
        check: impl FnOnce(T) -> Result<U, String>,
    ) -> Result<Option<Sourced<U>>> {
        let field = self.field(key);
        Ok(self
            .optional(key, check)?
            .map(|value| Sourced { value, field }))
    }

    fn sub_table(&mut self, key: &str) -> Result<Option<Table<'a>>> {
        let path = self.field(key);
        let entries = self.optional::<toml::Table, _>(key, Ok)?;
        Ok(entries.map(|entries| Table {
            manifest: self.manifest,
            path,
            entries,
        }))
    }

    fn required_sub_table(&mut self, key: &str) -> Result<Table<'a>> {
        let field = self.field(key);
        self.sub_table(key)?
            .ok_or_else(|| self.error(key, format!("missing; add a [{field}] table")))
    }

    /// An array of tables (`[[photo]]`), each with the path `key[i]`.
    fn tables(&mut self, key: &str) -> Result<Vec<Table<'a>>> {
        let path = self.field(key);
        let list = self
            .optional::<Vec<toml::Table>, _>(key, Ok)?
            .ok_or_else(|| {
                self.error(key, format!("missing; add at least one [[{path}]] table"))
            })?;
        Ok(list
            .into_iter()
            .enumerate()
            .map(|(i, entries)| Table {
                manifest: self.manifest,
                path: format!("{path}[{i}]"),
                entries,
            })
            .collect())
    }

    /// Reports every key nobody asked for as a warning.
    fn finish(self, warnings: &mut Vec<String>) {
        for key in self.entries.keys() {
            warnings.push(format!(
                "{}: {}: unknown key, ignored",
                self.manifest.display(),
                self.field(key)
            ));
        }
    }
}

/// A value and the field path it was read from, so that errors found after merging a photo's
/// camera with the `[camera]` defaults still name the right key.
#[derive(Clone, Debug)]
struct Sourced<T> {
    value: T,
    field: String,
}

impl<T> Sourced<T> {
    /// Path of the table the value was read from.
    fn table(&self) -> &str {
        self.field.rsplit_once('.').map_or("", |(table, _)| table)
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum CameraModel {
    Pinhole,
    Rectified,
}

/// The keys of one camera table, each optional until the defaults and overrides are merged.
#[derive(Clone, Debug, Default)]
struct CameraFields {
    model: Option<Sourced<CameraModel>>,
    position: Option<Sourced<DVec3>>,
    look_at: Option<Sourced<DVec3>>,
    up: Option<Sourced<DVec3>>,
    fov_y_deg: Option<Sourced<f64>>,
    fx: Option<Sourced<f64>>,
    fy: Option<Sourced<f64>>,
    cx: Option<Sourced<f64>>,
    cy: Option<Sourced<f64>>,
    resolution: Option<Sourced<[usize; 2]>>,
}

fn finite_number(x: f64) -> Result<f64, String> {
    if x.is_finite() {
        Ok(x)
    } else {
        Err(format!("must be finite, got {x}"))
    }
}

impl CameraFields {
    fn read(mut t: Table, warnings: &mut Vec<String>) -> Result<CameraFields> {
        let fields = CameraFields {
            model: t.sourced("model", |name: String| match name.as_str() {
                "pinhole" => Ok(CameraModel::Pinhole),
                "rectified" => Ok(CameraModel::Rectified),
                _ => Err(format!(
                    "unknown camera model `{name}`; expected \"pinhole\" or \"rectified\""
                )),
            })?,
            position: t.sourced("position", checks::above_sample_plane)?,
            look_at: t.sourced("look_at", checks::finite)?,
            up: t.sourced("up", checks::finite)?,
            fov_y_deg: t.sourced("fov_y_deg", |deg: f64| {
                if deg > 0.0 && deg < 180.0 {
                    Ok(deg)
                } else {
                    Err(format!(
                        "must be between 0 and 180 degrees (exclusive), got {deg}"
                    ))
                }
            })?,
            fx: t.sourced("fx", checks::positive)?,
            fy: t.sourced("fy", checks::positive)?,
            cx: t.sourced("cx", finite_number)?,
            cy: t.sourced("cy", finite_number)?,
            resolution: t.sourced("resolution", checks::resolution)?,
        };
        if fields.fov_y_deg.is_some() && (fields.fx.is_some() || fields.fy.is_some()) {
            return Err(t.error("fov_y_deg", "give either fov_y_deg or fx and fy, not both"));
        }
        t.finish(warnings);
        Ok(fields)
    }

    /// `over` (a photo's camera table) on top of `self` (the `[camera]` defaults), key by key,
    /// except that the two ways of giving the focal length replace each other.
    fn overlay(&self, over: &CameraFields) -> CameraFields {
        fn pick<T: Clone>(over: &Option<T>, base: &Option<T>) -> Option<T> {
            over.clone().or_else(|| base.clone())
        }
        let focal_given = over.fx.is_some() || over.fy.is_some();
        let fov_given = over.fov_y_deg.is_some();
        CameraFields {
            model: pick(&over.model, &self.model),
            position: pick(&over.position, &self.position),
            look_at: pick(&over.look_at, &self.look_at),
            up: pick(&over.up, &self.up),
            fov_y_deg: if focal_given {
                over.fov_y_deg.clone()
            } else {
                pick(&over.fov_y_deg, &self.fov_y_deg)
            },
            fx: if fov_given {
                over.fx.clone()
            } else {
                pick(&over.fx, &self.fx)
            },
            fy: if fov_given {
                over.fy.clone()
            } else {
                pick(&over.fy, &self.fy)
            },
            cx: pick(&over.cx, &self.cx),
            cy: pick(&over.cy, &self.cy),
            resolution: pick(&over.resolution, &self.resolution),
        }
    }

    /// The camera of photo `photo` from the merged keys.
    fn resolve(&self, manifest: &Path, photo: usize, warnings: &mut Vec<String>) -> Result<Camera> {
        fn value<'s, T>(
            manifest: &Path,
            photo: usize,
            key: &str,
            field: &'s Option<Sourced<T>>,
        ) -> Result<&'s Sourced<T>> {
            field.as_ref().ok_or_else(|| {
                Error::invalid(
                    manifest,
                    format!("photo[{photo}].camera.{key}"),
                    "missing: give it in [camera] or in this photo's camera table",
                )
            })
        }
        let model = value(manifest, photo, "model", &self.model)?;
        let position = value(manifest, photo, "position", &self.position)?.value;
        let resolution = value(manifest, photo, "resolution", &self.resolution)?.value;
        if model.value == CameraModel::Rectified {
            self.warn_pinhole_keys_beside(model, manifest, warnings);
            return Ok(Camera::Rectified(Rectified {
                position,
                resolution,
            }));
        }
        let look_at = value(manifest, photo, "look_at", &self.look_at)?;
        let up = value(manifest, photo, "up", &self.up)?;
        let mut pinhole = match &self.fov_y_deg {
            Some(fov) => {
                Pinhole::with_fov(position, look_at.value, up.value, fov.value, resolution)
            }
            None => {
                let focal = |key, field| value(manifest, photo, key, field).map(|s| s.value);
                let (fx, fy) = (
                    focal("fx (or fov_y_deg)", &self.fx)?,
                    focal("fy (or fov_y_deg)", &self.fy)?,
                );
                let [cx, cy] = resolution.map(|n| n as f64 / 2.0);
                Pinhole {
                    position,
                    look_at: look_at.value,
                    up: up.value,
                    fx,
                    fy,
                    cx,
                    cy,
                    resolution,
                }
            }
        };
        if let Some(cx) = &self.cx {
            pinhole.cx = cx.value;
        }
        if let Some(cy) = &self.cy {
            pinhole.cy = cy.value;
        }
        if let Some((key, message)) = pinhole.degeneracy() {
            let field = if key == "up" {
                &up.field
            } else {
                &look_at.field
            };
            return Err(Error::invalid(manifest, field, message));
        }
        Ok(Camera::Pinhole(pinhole))
    }

    /// Warns once per key about pinhole-only keys written in the table that declares
    /// `model = "rectified"` (inherited ones are legitimately unused).
    fn warn_pinhole_keys_beside(
        &self,
        model: &Sourced<CameraModel>,
        manifest: &Path,
        warnings: &mut Vec<String>,
    ) {
        let vectors = [&self.look_at, &self.up]
            .into_iter()
            .flatten()
            .map(|s| s.field.as_str());
        let numbers = [&self.fov_y_deg, &self.fx, &self.fy, &self.cx, &self.cy]
            .into_iter()
            .flatten();
        let same_table =
            |field: &str| field.rsplit_once('.').map_or("", |(t, _)| t) == model.table();
        for field in vectors
            .chain(numbers.map(|s| s.field.as_str()))
            .filter(|f| same_table(f))
        {
            let warning = format!(
                "{}: {field}: not used by the rectified camera model, ignored",
                manifest.display()
            );
            if !warnings.contains(&warning) {
                warnings.push(warning);
            }
        }
    }
}

fn read_light(mut t: Table, warnings: &mut Vec<String>) -> Result<Light> {
    let kind: String = t.required("kind", Ok)?;
    let light = match kind.as_str() {
        "point" => Light::Point {
            position: t.required("position", checks::above_sample_plane)?,
            intensity: t.required("intensity", checks::light_power)?,
        },
        "directional" => Light::Directional {
            direction: t.required("direction", checks::above_sample_plane)?,
            irradiance: t.required("irradiance", checks::light_power)?,
        },
        "flash" => Light::Flash {
            intensity: t.required("intensity", checks::light_power)?,
        },
        _ => {
            return Err(t.error(
                "kind",
                format!(
                    "unknown light kind `{kind}`; expected \"point\", \"directional\" or \"flash\""
                ),
            ))
        }
    };
    t.finish(warnings);
    Ok(light)
}

fn non_empty_path(text: String) -> Result<PathBuf, String> {
    if text.is_empty() {
        Err("must not be empty".to_string())
    } else {
        Ok(PathBuf::from(text))
    }
}

fn read_photo(
    mut t: Table,
    index: usize,
    default_camera: &CameraFields,
    default_color: Option<ColorEncoding>,
    warnings: &mut Vec<String>,
) -> Result<Photo> {
    let manifest = t.manifest;
    let image = t.required("image", non_empty_path)?;
    let light = read_light(t.required_sub_table("light")?, warnings)?;
    let exposure = t.optional("exposure", checks::positive)?.unwrap_or(1.0);
    let weight = t.optional("weight", checks::positive)?.unwrap_or(1.0);
    let mask = t.optional("mask", non_empty_path)?;
    let saturated_mask = t.optional("saturated_mask", non_empty_path)?;
    let color = t
        .optional::<ColorEncoding, _>("color", Ok)?
        .or(default_color)
        .unwrap_or_else(|| ColorEncoding::default_for(&image));
    let own_camera = match t.sub_table("camera")? {
        Some(table) => CameraFields::read(table, warnings)?,
        None => CameraFields::default(),
    };
    t.finish(warnings);
    let camera = default_camera
        .overlay(&own_camera)
        .resolve(manifest, index, warnings)?;
    Ok(Photo {
        image,
        camera,
        light,
        exposure,
        weight,
        mask,
        saturated_mask,
        color,
        pixels: None,
    })
}

/// The line number of a byte offset, for syntax errors.
fn line_of(text: &str, offset: usize) -> usize {
    text.as_bytes()[..offset.min(text.len())]
        .iter()
        .filter(|&&b| b == b'\n')
        .count()
        + 1
}

/// Reads and validates the manifest at `manifest`.
pub(super) fn read(manifest: &Path) -> Result<Capture> {
    let text = std::fs::read_to_string(manifest).map_err(|e| Error::io(manifest, e))?;
    let entries: toml::Table = toml::from_str(&text).map_err(|e| {
        let line = e.span().map_or_else(
            || "TOML syntax".to_string(),
            |s| format!("line {}", line_of(&text, s.start)),
        );
        Error::invalid(manifest, line, e.message())
    })?;
    from_table(manifest, absolute_folder(folder_of(manifest))?, entries)
}

/// Validates a manifest's tables `entries` (errors and warnings name `manifest` and the
/// field); relative image and mask paths are against `root`.
pub(super) fn from_table(manifest: &Path, root: PathBuf, entries: toml::Table) -> Result<Capture> {
    let mut warnings = Vec::new();
    let mut top = Table {
        manifest,
        path: String::new(),
        entries,
    };
    let name = top.required::<String, _>("name", Ok)?;
    let units = top.required::<String, _>("units", Ok)?;
    let mut sample_table = top.required_sub_table("sample")?;
    let sample = Sample {
        width: sample_table.required("width", checks::positive)?,
        height: sample_table.required("height", checks::positive)?,
    };
    let depth = sample_table
        .optional("depth", checks::non_negative)?
        .unwrap_or(0.0);
    sample_table.finish(&mut warnings);
    let color = top.optional::<ColorEncoding, _>("color", Ok)?;
    let default_camera = match top.sub_table("camera")? {
        Some(table) => CameraFields::read(table, &mut warnings)?,
        None => CameraFields::default(),
    };
    let photo_tables = top.tables("photo")?;
    if photo_tables.is_empty() {
        return Err(top.error("photo", "at least one [[photo]] is required"));
    }
    top.finish(&mut warnings);
    let photos = photo_tables
        .into_iter()
        .enumerate()
        .map(|(i, table)| read_photo(table, i, &default_camera, color, &mut warnings))
        .collect::<Result<Vec<Photo>>>()?;
    for (i, photo) in photos.iter().enumerate() {
        if let Some(first) = photos[..i].iter().position(|p| p.stem() == photo.stem()) {
            return Err(Error::invalid(
                manifest,
                format!("photo[{i}].image"),
                format!("has the same file stem `{}` as photo[{first}]; rendered outputs are named by stem", photo.stem()),
            ));
        }
    }
    Ok(Capture {
        name,
        units,
        root,
        sample,
        depth,
        color,
        photos,
        warnings,
    })
}

/// The manifest as written: values before tables, defaults left out.
#[derive(serde::Serialize)]
struct ManifestOut<'a> {
    name: &'a str,
    units: &'a str,
    #[serde(skip_serializing_if = "Option::is_none")]
    color: Option<ColorEncoding>,
    sample: SampleOut,
    camera: &'a Camera,
    photo: Vec<PhotoOut<'a>>,
}

#[derive(serde::Serialize)]
struct SampleOut {
    width: f64,
    height: f64,
    #[serde(skip_serializing_if = "is_zero")]
    depth: f64,
}

#[derive(serde::Serialize)]
struct PhotoOut<'a> {
    image: String,
    exposure: f64,
    #[serde(skip_serializing_if = "is_one")]
    weight: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    mask: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    saturated_mask: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    color: Option<ColorEncoding>,
    light: &'a Light,
    #[serde(skip_serializing_if = "Option::is_none")]
    camera: Option<&'a Camera>,
}

fn is_one(value: &f64) -> bool {
    *value == 1.0
}

fn is_zero(value: &f64) -> bool {
    *value == 0.0
}

/// Writes `capture` as a manifest at `path` (see [`Capture::save_manifest`]).
pub(super) fn write(capture: &Capture, path: &Path) -> Result<()> {
    let first = capture
        .photos
        .first()
        .ok_or_else(|| Error::invalid(path, "photo", "a capture without photos cannot be saved"))?;
    let keep_relative = absolute_folder(folder_of(path))? == absolute_folder(&capture.root)?;
    let path_text = |file: &Path, field: String| -> Result<String> {
        let written = if keep_relative {
            file.to_path_buf()
        } else {
            absolute_folder(&capture.root)?.join(file)
        };
        written.to_str().map(str::to_owned).ok_or_else(|| {
            Error::invalid(
                path,
                field,
                format!("{} is not valid UTF-8", written.display()),
            )
        })
    };
    let photo = capture
        .photos
        .iter()
        .enumerate()
        .map(|(i, p)| {
            if let Some(pixels) = &p.pixels {
                return Err(Error::invalid(
                    path,
                    format!("photo[{i}].image"),
                    format!(
                        "{} is held in memory; write it to an image file first",
                        pixels.name
                    ),
                ));
            }
            let optional_path = |file: &Option<PathBuf>, key: &str| {
                file.as_deref()
                    .map(|f| path_text(f, format!("photo[{i}].{key}")))
                    .transpose()
            };
            let default_color = capture
                .color
                .unwrap_or_else(|| ColorEncoding::default_for(&p.image));
            Ok(PhotoOut {
                image: path_text(&p.image, format!("photo[{i}].image"))?,
                exposure: p.exposure,
                weight: p.weight,
                mask: optional_path(&p.mask, "mask")?,
                saturated_mask: optional_path(&p.saturated_mask, "saturated_mask")?,
                color: (p.color != default_color).then_some(p.color),
                light: &p.light,
                camera: (p.camera != first.camera).then_some(&p.camera),
            })
        })
        .collect::<Result<Vec<_>>>()?;
    let out = ManifestOut {
        name: &capture.name,
        units: &capture.units,
        color: capture.color,
        sample: SampleOut {
            width: capture.sample.width,
            height: capture.sample.height,
            depth: capture.depth,
        },
        camera: &first.camera,
        photo,
    };
    let text =
        toml::to_string(&out).map_err(|e| Error::invalid(path, "manifest", e.to_string()))?;
    write_atomically(path, |file| {
        file.write_all(text.as_bytes())
            .map_err(|e| Error::io(path, e))
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::capture::MANIFEST_NAME;

    /// DESIGN.md's example manifest, verbatim.
    const DESIGN_EXAMPLE: &str = r#"
name = "copper-a03"
units = "cm"                  # unit of every length below
[sample]                      # flat sample centred at the origin, normal +z
width = 10.0
height = 10.0
[camera]                      # default for all photos; a photo may override any field
model = "pinhole"             # or "rectified": the image covers exactly the sample rectangle
position = [0.0, 0.0, 30.0]
look_at = [0.0, 0.0, 0.0]
up = [0.0, 1.0, 0.0]
fov_y_deg = 30.0              # or fx, fy, cx, cy in pixels
resolution = [128, 128]
[[photo]]
image = "000.exr"             # EXR linear; PNG/JPEG sRGB unless color = "linear"
light = { kind = "point", position = [0.0, 0.0, 30.0], intensity = [1000.0, 1000.0, 1000.0] }
exposure = 1.0
# mask = "000_mask.png"       # optional: zero = ignore
"#;

    fn write_manifest(text: &str) -> (tempfile::TempDir, PathBuf) {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(MANIFEST_NAME);
        std::fs::write(&path, text).unwrap();
        (dir, path)
    }

    fn open_text(text: &str) -> Result<Capture> {
        let (_dir, path) = write_manifest(text);
        Capture::open(&path)
    }

    /// The error message of opening `text`, which must name the manifest file.
    fn error_of(text: &str) -> String {
        let (_dir, path) = write_manifest(text);
        let message = Capture::open(&path).unwrap_err().to_string();
        assert!(message.contains(&path.display().to_string()), "{message}");
        message
    }

    /// DESIGN_EXAMPLE with `from` replaced by `to` (which must occur).
    fn example_with(from: &str, to: &str) -> String {
        assert!(DESIGN_EXAMPLE.contains(from), "{from}");
        DESIGN_EXAMPLE.replacen(from, to, 1)
    }

    /// What `Capture::from_tables` makes of `text`'s tables, each photo's pixels in memory.
    fn from_tables(text: &str) -> Result<Capture> {
        let table: toml::Table = toml::from_str(text).unwrap();
        let photos = table["photo"].as_array().unwrap().len();
        let pixels = (0..photos)
            .map(|i| crate::capture::InMemoryPhoto {
                name: format!("images[{i}]"),
                image: crate::capture::LinearImage {
                    width: 1,
                    height: 1,
                    rgb: vec![[0.5; 3]],
                    saturated: vec![false],
                },
                keep: None,
            })
            .collect();
        Capture::from_tables(Path::new("arrays"), table, pixels)
    }

    #[test]
    fn tables_in_memory_are_read_and_checked_as_the_manifest() {
        let text = rich_capture_text();
        let (from_file, in_memory) = (open_text(&text).unwrap(), from_tables(&text).unwrap());
        assert_eq!(in_memory.root, std::path::absolute(".").unwrap());
        assert_eq!(in_memory.photos.len(), from_file.photos.len());
        for (a, b) in in_memory.photos.iter().zip(&from_file.photos) {
            assert!(a.pixels.is_some());
            assert_eq!(
                Photo {
                    pixels: None,
                    ..a.clone()
                },
                *b
            );
        }
        // The same checks and messages, naming the source given in place of the manifest.
        for (from, to) in [
            ("[0.0, 0.0, 30.0], intensity", "[0.0, 0.0, -1.0], intensity"),
            ("up = [0.0, 1.0, 0.0]", "up = [0.0, 0.0, -2.0]"),
            ("kind = \"point\"", "kind = \"spot\""),
        ] {
            let text = example_with(from, to);
            let (_dir, path) = write_manifest(&text);
            let expected = Capture::open(&path).unwrap_err().to_string();
            let expected = expected.replacen(&path.display().to_string(), "arrays", 1);
            assert_eq!(from_tables(&text).unwrap_err().to_string(), expected);
        }
        // Pixels held in memory are not written as a manifest's images.
        let m = in_memory_save_error(&text);
        assert!(
            m.contains("photo[0].image: images[0] is held in memory"),
            "{m}"
        );
    }

    fn in_memory_save_error(text: &str) -> String {
        let dir = tempfile::tempdir().unwrap();
        let capture = from_tables(text).unwrap();
        capture
            .save_manifest(&dir.path().join(MANIFEST_NAME))
            .unwrap_err()
            .to_string()
    }

    #[test]
    fn depth_is_read_checked_saved_and_lifts_positions_in_the_material_frame() {
        let text = example_with("height = 10.0\n", "height = 10.0\ndepth = 0.25\n");
        let (dir, path) = write_manifest(&text);
        let c = Capture::open(&path).unwrap();
        assert_eq!(c.depth, 0.25);
        // Positions stay as calibrated; the material frame raises cameras and point lights.
        assert_eq!(c.photos[0].camera.position().z, 30.0);
        let lifted = c.in_material_frame();
        assert_eq!(lifted.depth, 0.0);
        assert_eq!(lifted.photos[0].camera.position().z, 30.25);
        match (&lifted.photos[0].camera, &lifted.photos[0].light) {
            (Camera::Pinhole(p), Light::Point { position, .. }) => {
                assert_eq!(p.look_at.z, 0.25);
                assert_eq!(position.z, 30.25);
            }
            other => panic!("{other:?}"),
        }
        let copy = dir.path().join("copy.toml");
        c.save_manifest(&copy).unwrap();
        let back = Capture::open(&copy).unwrap();
        assert_eq!(back.depth, 0.25);
        assert_eq!(back.photos, c.photos);
        let m = error_of(&example_with(
            "height = 10.0\n",
            "height = 10.0\ndepth = -1\n",
        ));
        assert!(
            m.contains("sample.depth: must be finite and zero or positive"),
            "{m}"
        );
    }

    #[test]
    fn reads_the_design_example() {
        let (dir, path) = write_manifest(DESIGN_EXAMPLE);
        let c = Capture::open(&path).unwrap();
        assert_eq!((c.name.as_str(), c.units.as_str()), ("copper-a03", "cm"));
        assert_eq!(c.root, std::path::absolute(dir.path()).unwrap());
        assert_eq!(
            c.sample,
            Sample {
                width: 10.0,
                height: 10.0
            }
        );
        assert!(c.warnings.is_empty(), "{:?}", c.warnings);
        assert_eq!(c.photos.len(), 1);
        let p = &c.photos[0];
        assert_eq!(p.image, PathBuf::from("000.exr"));
        assert_eq!(p.color, ColorEncoding::Linear);
        assert_eq!(p.exposure, 1.0);
        assert_eq!(
            p.light,
            Light::Point {
                position: DVec3::new(0.0, 0.0, 30.0),
                intensity: [1000.0; 3]
            }
        );
        let Camera::Pinhole(cam) = &p.camera else {
            panic!("{:?}", p.camera)
        };
        assert!((cam.fy - 64.0 / 15f64.to_radians().tan()).abs() < 1e-12);
        assert_eq!(
            (cam.fx, cam.cx, cam.cy, cam.resolution),
            (cam.fy, 64.0, 64.0, [128, 128])
        );
        // Opening the folder finds the same manifest.
        assert_eq!(Capture::open(dir.path()).unwrap(), c);
    }

    #[test]
    fn photo_camera_overrides_single_fields_and_focal_style() {
        let text = format!(
            "{DESIGN_EXAMPLE}{}",
            r#"
[[photo]]
image = "001.png"
light = { kind = "flash", intensity = [1.0, 2.0, 3.0] }
camera = { position = [1.0, 2.0, 20.0] }
[[photo]]
image = "002.png"
color = "gamma:2.2"
light = { kind = "directional", direction = [0.0, 0.6, 0.8], irradiance = [4.0, 4.0, 4.0] }
camera = { fx = 100.0, fy = 90.0, cy = 60.0 }
[[photo]]
image = "003.png"
light = { kind = "flash", intensity = [1.0, 1.0, 1.0] }
camera = { model = "rectified", resolution = [32, 16] }
"#
        );
        let c = open_text(&text).unwrap();
        assert!(c.warnings.is_empty(), "{:?}", c.warnings);
        let Camera::Pinhole(base) = c.photos[0].camera.clone() else {
            panic!()
        };
        assert_eq!(
            c.photos[1].camera,
            Camera::Pinhole(Pinhole {
                position: DVec3::new(1.0, 2.0, 20.0),
                ..base.clone()
            })
        );
        assert_eq!(c.photos[1].color, ColorEncoding::Srgb);
        assert_eq!(
            c.photos[2].camera,
            Camera::Pinhole(Pinhole {
                fx: 100.0,
                fy: 90.0,
                cx: 64.0,
                cy: 60.0,
                ..base.clone()
            })
        );
        assert_eq!(c.photos[2].color, ColorEncoding::Gamma(2.2));
        assert_eq!(
            c.photos[3].camera,
            Camera::Rectified(Rectified {
                position: DVec3::new(0.0, 0.0, 30.0),
                resolution: [32, 16]
            })
        );
    }

    #[test]
    fn top_level_color_is_the_default_of_every_photo() {
        let c = open_text(&example_with(
            "units = \"cm\"",
            "units = \"cm\"\ncolor = \"srgb\"",
        ))
        .unwrap();
        assert_eq!(c.color, Some(ColorEncoding::Srgb));
        assert_eq!(c.photos[0].color, ColorEncoding::Srgb);
    }

    #[test]
    fn missing_fields_name_their_path() {
        let m = error_of(&example_with(", intensity = [1000.0, 1000.0, 1000.0]", ""));
        assert!(m.contains("photo[0].light.intensity: missing"), "{m}");
        let m = error_of(&example_with("units = \"cm\"", ""));
        assert!(m.contains("units: missing"), "{m}");
        let m = error_of(&example_with("width = 10.0", ""));
        assert!(m.contains("sample.width: missing"), "{m}");
        let m = error_of(&example_with("look_at = [0.0, 0.0, 0.0]", ""));
        assert!(m.contains("photo[0].camera.look_at: missing"), "{m}");
        let m = error_of(&example_with("fov_y_deg = 30.0", ""));
        assert!(
            m.contains("photo[0].camera.fx (or fov_y_deg): missing"),
            "{m}"
        );
        let m = error_of(&example_with("[[photo]]", "[[nophoto]]"));
        assert!(m.contains(": photo: missing"), "{m}");
    }

    #[test]
    fn wrong_types_give_serde_message_and_path() {
        let m = error_of(&example_with("exposure = 1.0", "exposure = \"bright\""));
        assert!(
            m.contains("photo[0].exposure: invalid type: string \"bright\", expected f64"),
            "{m}"
        );
        let m = error_of(&example_with(
            "resolution = [128, 128]",
            "resolution = [128]",
        ));
        assert!(m.contains("camera.resolution: invalid length 1"), "{m}");
        let m = error_of(&example_with(
            "[0.0, 0.0, 30.0], intensity",
            "[0.0, 30.0], intensity",
        ));
        assert!(
            m.contains("photo[0].light.position: invalid length 2"),
            "{m}"
        );
        let m = error_of(&example_with(
            "units = \"cm\"",
            "units = \"cm\"\ncolor = \"rgb\"",
        ));
        assert!(m.contains(": color: `rgb` is not a colour encoding"), "{m}");
        let m = error_of(&example_with(
            "image = \"000.exr\"",
            "image = \"000.exr\"\ncolor = \"gamma:0\"",
        ));
        assert!(
            m.contains("photo[0].color: gamma must be finite and positive"),
            "{m}"
        );
        let m = error_of(&example_with(
            "name = \"copper-a03\"",
            "name = \"copper-a03\"\nname2 = [1, ",
        ));
        // The example starts with a blank line; the unclosed array runs into line 4.
        assert!(
            m.contains("capture.toml: line 4: unexpected `=` in array"),
            "{m}"
        );
    }

    #[test]
    fn geometry_below_the_sample_and_degenerate_cameras_are_errors() {
        let m = error_of(&example_with(
            "position = [0.0, 0.0, 30.0]",
            "position = [0.0, 0.0, 0.0]",
        ));
        assert!(
            m.contains("camera.position: must be above the sample plane"),
            "{m}"
        );
        let m = error_of(&example_with(
            "[0.0, 0.0, 30.0], intensity",
            "[0.0, 0.0, -1.0], intensity",
        ));
        assert!(
            m.contains("photo[0].light.position: must be above the sample plane"),
            "{m}"
        );
        let m = error_of(&example_with(
            "look_at = [0.0, 0.0, 0.0]",
            "look_at = [0.0, 0.0, 30.0]",
        ));
        assert!(
            m.contains("camera.look_at: equals the camera position"),
            "{m}"
        );
        let m = error_of(&example_with(
            "up = [0.0, 1.0, 0.0]",
            "up = [0.0, 0.0, -2.0]",
        ));
        assert!(m.contains("camera.up: is zero or parallel"), "{m}");
        // A photo's override that makes the camera degenerate is blamed on the override.
        let text = example_with(
            "exposure = 1.0",
            "exposure = 1.0\ncamera = { up = [0.0, 0.0, 1.0] }",
        );
        let m = error_of(&text);
        assert!(m.contains("photo[0].camera.up: is zero or parallel"), "{m}");
    }

    #[test]
    fn non_positive_sizes_and_bad_intensities_are_errors() {
        for (from, to, expected) in [
            (
                "resolution = [128, 128]",
                "resolution = [0, 128]",
                "camera.resolution: must be positive",
            ),
            (
                "resolution = [128, 128]",
                "resolution = [-1, 128]",
                "camera.resolution: invalid value",
            ),
            (
                "fov_y_deg = 30.0",
                "fov_y_deg = 0.0",
                "camera.fov_y_deg: must be between 0 and 180",
            ),
            (
                "fov_y_deg = 30.0",
                "fov_y_deg = 180.0",
                "camera.fov_y_deg: must be between 0 and 180",
            ),
            (
                "fov_y_deg = 30.0",
                "fx = -5.0\nfy = 5.0",
                "camera.fx: must be finite and positive",
            ),
            (
                "fov_y_deg = 30.0",
                "fov_y_deg = 30.0\nfx = 5.0",
                "camera.fov_y_deg: give either",
            ),
            (
                "width = 10.0",
                "width = 0.0",
                "sample.width: must be finite and positive",
            ),
            (
                "height = 10.0",
                "height = -3.0",
                "sample.height: must be finite and positive",
            ),
            (
                "exposure = 1.0",
                "exposure = 0.0",
                "photo[0].exposure: must be finite and positive",
            ),
            (
                "exposure = 1.0",
                "exposure = 1.0\nweight = -0.5",
                "photo[0].weight: must be finite and positive",
            ),
            (
                "[1000.0, 1000.0, 1000.0]",
                "[1000.0, -1.0, 1000.0]",
                "photo[0].light.intensity: must be finite and non-negative",
            ),
            (
                "[1000.0, 1000.0, 1000.0]",
                "[0.0, 0.0, 0.0]",
                "photo[0].light.intensity: is zero in every channel",
            ),
            (
                "kind = \"point\"",
                "kind = \"spot\"",
                "photo[0].light.kind: unknown light kind `spot`",
            ),
            (
                "model = \"pinhole\"",
                "model = \"fisheye\"",
                "camera.model: unknown camera model `fisheye`",
            ),
            (
                "image = \"000.exr\"",
                "image = \"\"",
                "photo[0].image: must not be empty",
            ),
        ] {
            let m = error_of(&example_with(from, to));
            assert!(m.contains(expected), "{to}: {m}");
        }
    }

    #[test]
    fn duplicate_image_stems_are_errors() {
        let text = format!("{DESIGN_EXAMPLE}[[photo]]\nimage = \"other/000.png\"\nlight = {{ kind = \"flash\", intensity = [1.0, 1.0, 1.0] }}\n");
        let m = error_of(&text);
        assert!(
            m.contains("photo[1].image: has the same file stem `000` as photo[0]"),
            "{m}"
        );
    }

    #[test]
    fn unknown_keys_are_warnings() {
        let text = example_with(
            "exposure = 1.0",
            "exposure = 1.0\nshutter = 3\ncamera = { lens = \"50mm\" }",
        )
        .replace("[sample]", "author = \"me\"\n[sample]")
        .replace("kind = \"point\"", "kind = \"point\", colour = 2");
        let c = open_text(&text).unwrap();
        let joined = c.warnings.join("\n");
        for key in [
            "author",
            "photo[0].shutter",
            "photo[0].camera.lens",
            "photo[0].light.colour",
        ] {
            assert!(
                joined.contains(&format!(": {key}: unknown key, ignored")),
                "{key}: {joined}"
            );
        }
        assert_eq!(c.warnings.len(), 4, "{joined}");
        // Pinhole keys written beside model = "rectified" are reported once, inherited ones not.
        let text = example_with("model = \"pinhole\"", "model = \"rectified\"");
        let text = format!("{text}[[photo]]\nimage = \"b.png\"\nlight = {{ kind = \"flash\", intensity = [1.0, 1.0, 1.0] }}\n");
        let c = open_text(&text).unwrap();
        let expected: Vec<&str> = vec!["camera.look_at", "camera.up", "camera.fov_y_deg"];
        assert_eq!(c.warnings.len(), expected.len(), "{:?}", c.warnings);
        for (warning, key) in c.warnings.iter().zip(expected) {
            assert!(
                warning.ends_with(&format!(
                    "{key}: not used by the rectified camera model, ignored"
                )),
                "{warning}"
            );
        }
    }

    fn rich_capture_text() -> String {
        format!(
            "{}{}",
            example_with("units = \"cm\"", "units = \"cm\"\ncolor = \"gamma:2.2\""),
            r#"
[[photo]]
image = "sub/001.png"
exposure = 0.3333333333333333
weight = 0.25
mask = "sub/001_mask.png"
saturated_mask = "sub/001_sat.png"
color = "srgb"
light = { kind = "directional", direction = [0.1, 0.7, 0.9], irradiance = [0.1, 0.2, 0.30000000000000004] }
camera = { position = [1.25, -2.5, 17.0], fx = 101.5, fy = 99.25, cx = 63.1 }
[[photo]]
image = "002.jpg"
light = { kind = "flash", intensity = [7.0, 8.0, 9.0] }
camera = { model = "rectified", resolution = [40, 20] }
"#
        )
    }

    #[test]
    fn save_then_open_round_trips() {
        let (dir, path) = write_manifest(&rich_capture_text());
        let original = Capture::open(&path).unwrap();
        assert!(original.warnings.is_empty(), "{:?}", original.warnings);
        let saved = dir.path().join("again.toml");
        original.save_manifest(&saved).unwrap();
        let back = Capture::open(&saved).unwrap();
        assert_eq!(
            back,
            original,
            "{}",
            std::fs::read_to_string(&saved).unwrap()
        );
        // Relative paths are kept when the manifest stays in the capture's folder.
        let text = std::fs::read_to_string(&saved).unwrap();
        assert!(text.contains("\"sub/001_mask.png\""), "{text}");
    }

    #[test]
    fn saving_elsewhere_keeps_the_images_reachable() {
        let (_dir, path) = write_manifest(&rich_capture_text());
        let original = Capture::open(&path).unwrap();
        let elsewhere = tempfile::tempdir().unwrap();
        let saved = elsewhere.path().join(MANIFEST_NAME);
        original.save_manifest(&saved).unwrap();
        let back = Capture::open(elsewhere.path()).unwrap();
        assert_eq!(back.root, std::path::absolute(elsewhere.path()).unwrap());
        for (a, b) in original.photos.iter().zip(&back.photos) {
            assert_eq!(original.path_of(&a.image), back.path_of(&b.image));
            assert_eq!(
                a.mask.as_ref().map(|m| original.path_of(m)),
                b.mask.as_ref().map(|m| back.path_of(m))
            );
            assert_eq!(
                (&a.camera, &a.light, a.exposure, a.color),
                (&b.camera, &b.light, b.exposure, b.color)
            );
        }
    }

    #[test]
    fn a_folder_without_manifest_is_an_error_saying_what_was_expected() {
        let dir = tempfile::tempdir().unwrap();
        let m = Capture::open(dir.path()).unwrap_err().to_string();
        assert!(
            m.contains(&dir.path().display().to_string()) && m.contains("expected a capture.toml"),
            "{m}"
        );
        let missing = dir.path().join("nothing-here");
        let m = Capture::open(&missing).unwrap_err().to_string();
        assert!(m.contains("nothing-here"), "{m}");
    }
}

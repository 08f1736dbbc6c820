//! Importer for the flash photo sets of MaterialGAN and svbrdf-diff-renderer (DESIGN.md
//! "Importers"; format and pixel convention in data/real/README.md).
//!
//! A folder holds rectified images `NN.png` (two-digit index), either directly or in numeric
//! subfolders (`256/`, `1024/`), optionally `NN_saturated_mask.png` beside them (nonzero =
//! saturated), and the calibration, in centimetres, in one of two forms:
//!
//! - `camera_pos.txt`, `light_pos.txt` (one `x,y,z` line per image, or one line for all),
//!   `light_power.txt` (`r,g,b`, per image or one line), `image_size.txt` (side S of the square
//!   sample);
//! - `parameters.json` or `optim.json` with `camera_pos`, `light_pos`, `light_pow` (one triple or
//!   a list of triples indexed by image index), `image_size` or `im_size`, and optionally `idx`
//!   (the image indices to use, as svbrdf-diff-renderer does).
//!
//! The result is a [`Capture`] in cm over an S x S sample, with a rectified camera at
//! `camera_pos` and a point light at `light_pos` of intensity `light_pow` (a flash when light
//! and camera coincide). Images are decoded with a pure 2.2 gamma, the encoding the original
//! code used (not the sRGB curve). Note `light_pow` is a nominal constant in these data sets:
//! the absolute scale of the photos is unknown.

use std::fs;
use std::path::{Path, PathBuf};

use glam::DVec3;

use super::{absolute_folder, checks};
use super::{Camera, Capture, ColorEncoding, Light, Photo, Rectified, Sample};
use crate::error::{Error, Result};

/// Files whose presence marks a MaterialGAN-format folder, in order of precedence.
pub const METADATA_FILES: [&str; 3] = ["camera_pos.txt", "parameters.json", "optim.json"];

/// The gamma the MaterialGAN code encodes its images with (data/real/README.md).
pub const ENCODING: ColorEncoding = ColorEncoding::Gamma(2.2);

/// Whether `folder` holds MaterialGAN calibration ([`METADATA_FILES`]).
pub fn is_materialgan_folder(folder: &Path) -> bool {
    METADATA_FILES
        .iter()
        .any(|name| folder.join(name).is_file())
}

/// Imports the MaterialGAN folder `folder`. `image_folder` names the subfolder with the images
/// (e.g. `"1024"`); by default the numeric subfolder with the smallest number, or the folder
/// itself when it has no numeric subfolder.
pub fn import(folder: &Path, image_folder: Option<&str>) -> Result<Capture> {
    let metadata = Metadata::read(folder)?;
    let images = choose_image_folder(folder, image_folder)?;
    let indices = match &metadata.indices {
        Some(indices) => indices.clone(),
        None => match metadata.longest_list() {
            1 => (0..count_images(folder, &images)).collect(),
            n => (0..n).collect(),
        },
    };
    if indices.is_empty() {
        return Err(Error::invalid(
            folder.join(&images),
            "images",
            "no 00.png found",
        ));
    }
    let photos = indices
        .iter()
        .map(|&index| {
            let image = images.join(format!("{index:02}.png"));
            let camera_position = *metadata.camera.get(index)?;
            let light_position = *metadata.light.get(index)?;
            let intensity = *metadata.power.get(index)?;
            let light = if light_position == camera_position {
                Light::Flash { intensity }
            } else {
                Light::Point {
                    position: light_position,
                    intensity,
                }
            };
            let resolution = image_resolution(&folder.join(&image))?;
            let saturated_mask = images.join(format!("{index:02}_saturated_mask.png"));
            Ok(Photo {
                camera: Camera::Rectified(Rectified {
                    position: camera_position,
                    resolution,
                }),
                light,
                exposure: 1.0,
                weight: 1.0,
                mask: None,
                saturated_mask: folder
                    .join(&saturated_mask)
                    .is_file()
                    .then_some(saturated_mask),
                color: ENCODING,
                image,
                pixels: None,
            })
        })
        .collect::<Result<Vec<Photo>>>()?;
    let root = absolute_folder(folder)?;
    let name = root.file_name().map_or_else(
        || "materialgan".to_string(),
        |n| n.to_string_lossy().into_owned(),
    );
    Ok(Capture {
        name,
        units: "cm".to_string(),
        root,
        sample: Sample {
            width: metadata.size,
            height: metadata.size,
        },
        color: Some(ENCODING),
        depth: 0.0,
        photos,
        warnings: metadata.warnings,
    })
}

/// A calibration value given once for all images or once per image index, with where it was
/// read from (for errors).
struct PerImage<T> {
    file: PathBuf,
    field: String,
    values: Vec<T>,
}

impl<T> PerImage<T> {
    /// The value for image `index`.
    fn get(&self, index: usize) -> Result<&T> {
        match self.values.as_slice() {
            [single] => Ok(single),
            values => values.get(index).ok_or_else(|| {
                Error::invalid(
                    &self.file,
                    &self.field,
                    format!(
                        "has {} entries, but image {index:02}.png needs entry {index}",
                        values.len()
                    ),
                )
            }),
        }
    }
}

/// The calibration of a folder, in either of its two forms.
struct Metadata {
    camera: PerImage<DVec3>,
    light: PerImage<DVec3>,
    power: PerImage<[f64; 3]>,
    /// Side S of the square sample, cm.
    size: f64,
    /// The JSON form's `idx`: which images to use.
    indices: Option<Vec<usize>>,
    warnings: Vec<String>,
}

impl Metadata {
    fn read(folder: &Path) -> Result<Metadata> {
        let present: Vec<&str> = METADATA_FILES
            .iter()
            .copied()
            .filter(|n| folder.join(n).is_file())
            .collect();
        let Some(&chosen) = present.first() else {
            return Err(Error::invalid(
                folder,
                "folder",
                format!("none of {} found", METADATA_FILES.join(", ")),
            ));
        };
        let mut metadata = if chosen == "camera_pos.txt" {
            Metadata::from_text(folder)?
        } else {
            Metadata::from_json(&folder.join(chosen))?
        };
        if present.len() > 1 {
            metadata.warnings.push(format!(
                "{}: calibration read from {chosen}; {} ignored",
                folder.display(),
                present[1..].join(", ")
            ));
        }
        Ok(metadata)
    }

    fn longest_list(&self) -> usize {
        self.camera
            .values
            .len()
            .max(self.light.values.len())
            .max(self.power.values.len())
    }

    /// The `.txt` form: one value per line.
    fn from_text(folder: &Path) -> Result<Metadata> {
        let size_file = folder.join("image_size.txt");
        let sizes = read_text_rows(&size_file, |[side]: [f64; 1]| checks::positive(side))?;
        if sizes.values.len() != 1 {
            return Err(Error::invalid(
                &size_file,
                "lines",
                format!("expected one number, found {} lines", sizes.values.len()),
            ));
        }
        Ok(Metadata {
            camera: read_text_rows(&folder.join("camera_pos.txt"), checks::above_sample_plane)?,
            light: read_text_rows(&folder.join("light_pos.txt"), checks::above_sample_plane)?,
            power: read_text_rows(&folder.join("light_power.txt"), checks::light_power)?,
            size: sizes.values[0],
            indices: None,
            warnings: Vec::new(),
        })
    }

    /// The JSON form (`parameters.json`, `optim.json`).
    fn from_json(path: &Path) -> Result<Metadata> {
        let text = fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
        let json: serde_json::Value = serde_json::from_str(&text)
            .map_err(|e| Error::invalid(path, format!("line {}", e.line()), e.to_string()))?;
        let object = json
            .as_object()
            .ok_or_else(|| Error::invalid(path, "top level", "expected a JSON object"))?;
        let field = |key: &str| {
            object
                .get(key)
                .ok_or_else(|| Error::invalid(path, key, "missing"))
        };
        let size_key = if object.contains_key("image_size") {
            "image_size"
        } else {
            "im_size"
        };
        let size = serde_json::from_value::<f64>(field(size_key)?.clone())
            .map_err(|e| e.to_string())
            .and_then(checks::positive)
            .map_err(|m| Error::invalid(path, size_key, m))?;
        let indices = object
            .get("idx")
            .map(|v| serde_json::from_value::<Vec<usize>>(v.clone()))
            .transpose()
            .map_err(|e| Error::invalid(path, "idx", e.to_string()))?;
        Ok(Metadata {
            camera: json_rows(
                path,
                "camera_pos",
                field("camera_pos")?,
                checks::above_sample_plane,
            )?,
            light: json_rows(
                path,
                "light_pos",
                field("light_pos")?,
                checks::above_sample_plane,
            )?,
            power: json_rows(path, "light_pow", field("light_pow")?, checks::light_power)?,
            size,
            indices,
            warnings: Vec::new(),
        })
    }
}

/// A text file of rows of `N` numbers separated by commas and/or spaces; blank lines skipped.
fn read_text_rows<const N: usize, T>(
    path: &Path,
    check: impl Fn([f64; N]) -> Result<T, String>,
) -> Result<PerImage<T>> {
    let text = fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    let values = text
        .lines()
        .enumerate()
        .filter(|(_, line)| !line.trim().is_empty())
        .map(|(i, line)| {
            let error = |message: String| Error::invalid(path, format!("line {}", i + 1), message);
            let numbers = line
                .split(|c: char| c == ',' || c.is_whitespace())
                .filter(|s| !s.is_empty())
                .map(|s| {
                    s.parse::<f64>()
                        .map_err(|_| error(format!("`{s}` is not a number")))
                })
                .collect::<Result<Vec<f64>>>()?;
            let row: [f64; N] = numbers
                .try_into()
                .map_err(|v: Vec<f64>| error(format!("expected {N} numbers, found {}", v.len())))?;
            check(row).map_err(error)
        })
        .collect::<Result<Vec<T>>>()?;
    if values.is_empty() {
        return Err(Error::invalid(path, "lines", "no values"));
    }
    Ok(PerImage {
        file: path.to_path_buf(),
        field: "lines".to_string(),
        values,
    })
}

/// A JSON value that is either one `[x, y, z]` triple or a list of them.
fn json_rows<T>(
    path: &Path,
    key: &str,
    value: &serde_json::Value,
    check: impl Fn([f64; 3]) -> Result<T, String>,
) -> Result<PerImage<T>> {
    let rows = match serde_json::from_value::<[f64; 3]>(value.clone()) {
        Ok(single) => vec![single],
        Err(_) => serde_json::from_value::<Vec<[f64; 3]>>(value.clone()).map_err(|e| {
            Error::invalid(
                path,
                key,
                format!("expected [x, y, z] or a list of them: {e}"),
            )
        })?,
    };
    if rows.is_empty() {
        return Err(Error::invalid(path, key, "empty list"));
    }
    let values = rows
        .into_iter()
        .enumerate()
        .map(|(i, row)| check(row).map_err(|m| Error::invalid(path, format!("{key}[{i}]"), m)))
        .collect::<Result<Vec<T>>>()?;
    Ok(PerImage {
        file: path.to_path_buf(),
        field: key.to_string(),
        values,
    })
}

/// The image subfolder (relative to `folder`; empty for the folder itself).
fn choose_image_folder(folder: &Path, choice: Option<&str>) -> Result<PathBuf> {
    if let Some(name) = choice {
        return if folder.join(name).is_dir() {
            Ok(PathBuf::from(name))
        } else {
            Err(Error::invalid(
                folder,
                "image folder",
                format!("has no subfolder `{name}`"),
            ))
        };
    }
    let entries = fs::read_dir(folder).map_err(|e| Error::io(folder, e))?;
    let mut numeric = Vec::new();
    for entry in entries {
        let entry = entry.map_err(|e| Error::io(folder, e))?;
        let name = entry.file_name().to_string_lossy().into_owned();
        if entry.path().is_dir() && !name.is_empty() && name.bytes().all(|b| b.is_ascii_digit()) {
            if let Ok(number) = name.parse::<u64>() {
                numeric.push((number, name));
            }
        }
    }
    Ok(numeric
        .into_iter()
        .min()
        .map_or_else(PathBuf::new, |(_, name)| PathBuf::from(name)))
}

/// How many consecutive images `00.png`, `01.png`, ... the image folder holds.
fn count_images(folder: &Path, images: &Path) -> usize {
    (0..)
        .take_while(|i| folder.join(images).join(format!("{i:02}.png")).is_file())
        .count()
}

/// `[width, height]` of an image, read from its header.
fn image_resolution(path: &Path) -> Result<[usize; 2]> {
    let (width, height) = image::image_dimensions(path).map_err(|e| match e {
        image::ImageError::IoError(io) => Error::io(path, io),
        other => Error::invalid(path, "image data", other.to_string()),
    })?;
    Ok([width as usize, height as usize])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write_png(path: &Path, size: u32, value: u8) {
        fs::create_dir_all(path.parent().unwrap()).unwrap();
        image::RgbImage::from_pixel(size, size, image::Rgb([value; 3]))
            .save(path)
            .unwrap();
    }

    /// A `.txt`-form folder: 3 images at 4 px in `4/` and 8 px in `8/`, a non-numeric folder,
    /// a saturation mask for image 01, and a light away from the camera for image 02.
    fn text_folder() -> tempfile::TempDir {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        fs::write(
            d.join("camera_pos.txt"),
            "1.0,0.5,16.0\n-2.0, 1.5, 17.5\n\n0,0,20\n",
        )
        .unwrap();
        fs::write(
            d.join("light_pos.txt"),
            "1.0,0.5,16.0\n-2.0,1.5,17.5\n3,1,20\n",
        )
        .unwrap();
        fs::write(d.join("light_power.txt"), "1500.0000,1500.0000,1400.0000\n").unwrap();
        fs::write(d.join("image_size.txt"), "6.8480\n").unwrap();
        for i in 0..3 {
            write_png(&d.join(format!("8/{i:02}.png")), 8, 10);
            write_png(&d.join(format!("4/{i:02}.png")), 4, 10);
        }
        write_png(&d.join("4/01_saturated_mask.png"), 4, 0);
        write_png(&d.join("textures/00.png"), 2, 0);
        dir
    }

    #[test]
    fn text_form_gives_rectified_flash_capture_in_cm() {
        let dir = text_folder();
        let c = import(dir.path(), None).unwrap();
        assert_eq!(c.units, "cm");
        assert_eq!(
            c.sample,
            Sample {
                width: 6.848,
                height: 6.848
            }
        );
        assert_eq!(c.color, Some(ColorEncoding::Gamma(2.2)));
        assert_eq!(c.root, std::path::absolute(dir.path()).unwrap());
        assert!(c.warnings.is_empty());
        assert_eq!(c.photos.len(), 3);
        let cameras = [
            DVec3::new(1.0, 0.5, 16.0),
            DVec3::new(-2.0, 1.5, 17.5),
            DVec3::new(0.0, 0.0, 20.0),
        ];
        for (i, (photo, position)) in c.photos.iter().zip(cameras).enumerate() {
            assert_eq!(photo.image, PathBuf::from(format!("4/{i:02}.png")));
            assert_eq!(
                photo.camera,
                Camera::Rectified(Rectified {
                    position,
                    resolution: [4, 4]
                })
            );
            assert_eq!(photo.color, ColorEncoding::Gamma(2.2));
            assert_eq!(photo.exposure, 1.0);
        }
        let intensity = [1500.0, 1500.0, 1400.0];
        assert_eq!(c.photos[0].light, Light::Flash { intensity });
        assert_eq!(c.photos[1].light, Light::Flash { intensity });
        assert_eq!(
            c.photos[2].light,
            Light::Point {
                position: DVec3::new(3.0, 1.0, 20.0),
                intensity
            }
        );
        let masks: Vec<_> = c.photos.iter().map(|p| p.saturated_mask.clone()).collect();
        assert_eq!(
            masks,
            vec![None, Some(PathBuf::from("4/01_saturated_mask.png")), None]
        );
        // Opening the folder imports it the same way.
        assert_eq!(Capture::open(dir.path()).unwrap(), c);
    }

    #[test]
    fn image_folder_can_be_chosen() {
        let dir = text_folder();
        let c = import(dir.path(), Some("8")).unwrap();
        assert_eq!(c.photos[2].image, PathBuf::from("8/02.png"));
        assert_eq!(c.photos[2].camera.resolution(), [8, 8]);
        assert!(c.photos.iter().all(|p| p.saturated_mask.is_none()));
        let m = import(dir.path(), Some("512")).unwrap_err().to_string();
        assert!(m.contains("has no subfolder `512`"), "{m}");
        // Opening the image subfolder imports that size.
        assert_eq!(Capture::open(&dir.path().join("8")).unwrap(), c);
        let empty = tempfile::tempdir().unwrap();
        let m = Capture::open(empty.path())
            .map(|_| ())
            .unwrap_err()
            .to_string();
        assert!(m.contains("one of its image subfolders"), "{m}");
    }

    #[test]
    fn json_form_uses_idx_and_im_size() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let json = r#"{"im_size": 10.88, "idx": [0, 2],
            "camera_pos": [[-2.7, 3.4, 27.3], [0.3, 3.5, 26.2], [4.8, 4.9, 24.5]],
            "light_pos": [[-2.7, 3.4, 27.3], [0.3, 3.5, 26.2], [4.8, 4.9, 24.5]],
            "light_pow": [1500, 1500, 1500]}"#;
        fs::write(d.join("optim.json"), json).unwrap();
        write_png(&d.join("00.png"), 5, 1);
        write_png(&d.join("02.png"), 5, 1);
        let c = import(d, None).unwrap();
        assert_eq!(c.sample.width, 10.88);
        assert_eq!(c.photos.len(), 2);
        assert_eq!(c.photos[1].image, PathBuf::from("02.png"));
        assert_eq!(
            c.photos[1].camera,
            Camera::Rectified(Rectified {
                position: DVec3::new(4.8, 4.9, 24.5),
                resolution: [5, 5]
            })
        );
        assert_eq!(
            c.photos[1].light,
            Light::Flash {
                intensity: [1500.0; 3]
            }
        );
    }

    #[test]
    fn json_form_with_single_triples_counts_the_images() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let json = r#"{"image_size": 9.728, "camera_pos": [1.8, 0.1, 10.9], "light_pos": [1.8, 0.1, 11.0],
            "light_pow": [1500, 1400, 1300]}"#;
        fs::write(d.join("parameters.json"), json).unwrap();
        fs::write(d.join("optim.json"), json).unwrap();
        for i in 0..2 {
            write_png(&d.join(format!("256/{i:02}.png")), 3, 1);
        }
        let c = import(d, None).unwrap();
        assert_eq!(c.photos.len(), 2);
        assert_eq!(c.sample.height, 9.728);
        assert_eq!(
            c.photos[1].light,
            Light::Point {
                position: DVec3::new(1.8, 0.1, 11.0),
                intensity: [1500.0, 1400.0, 1300.0]
            }
        );
        assert_eq!(c.warnings.len(), 1);
        assert!(c.warnings[0].contains("calibration read from parameters.json; optim.json ignored"));
    }

    #[test]
    fn bad_metadata_names_file_and_line_or_field() {
        let dir = text_folder();
        let d = dir.path();
        fs::write(d.join("camera_pos.txt"), "1.0,0.5,16.0\n1.0,0.5\n").unwrap();
        let m = import(d, None).unwrap_err().to_string();
        assert!(
            m.contains("camera_pos.txt: line 2: expected 3 numbers, found 2"),
            "{m}"
        );
        fs::write(d.join("camera_pos.txt"), "1.0,0.5,16.0\n1.0,0.5,-3\n").unwrap();
        let m = import(d, None).unwrap_err().to_string();
        assert!(
            m.contains("camera_pos.txt: line 2: must be above the sample plane"),
            "{m}"
        );
        fs::write(d.join("camera_pos.txt"), "1.0,0.5,16.0\n1.0,abc,3\n").unwrap();
        let m = import(d, None).unwrap_err().to_string();
        assert!(
            m.contains("camera_pos.txt: line 2: `abc` is not a number"),
            "{m}"
        );
        // Two camera lines but three light lines: image 02 has no camera.
        fs::write(d.join("camera_pos.txt"), "1.0,0.5,16.0\n1.0,0.5,3\n").unwrap();
        let m = import(d, None).unwrap_err().to_string();
        assert!(
            m.contains("camera_pos.txt: lines: has 2 entries, but image 02.png needs entry 2"),
            "{m}"
        );
        fs::remove_file(d.join("image_size.txt")).unwrap();
        let m = import(d, None).unwrap_err().to_string();
        assert!(m.contains("image_size.txt"), "{m}");
        let json_dir = tempfile::tempdir().unwrap();
        fs::write(json_dir.path().join("parameters.json"), r#"{"image_size": 9, "camera_pos": [[1, 2, 3]], "light_pos": [1, 2], "light_pow": [1, 1, 1]}"#).unwrap();
        let m = import(json_dir.path(), None).unwrap_err().to_string();
        assert!(
            m.contains("parameters.json: light_pos: expected [x, y, z] or a list of them"),
            "{m}"
        );
    }

    #[test]
    fn a_missing_image_is_an_error_naming_it() {
        let dir = text_folder();
        fs::remove_file(dir.path().join("4/01.png")).unwrap();
        let m = import(dir.path(), None).unwrap_err().to_string();
        assert!(m.contains("4/01.png"), "{m}");
    }

    #[test]
    fn imported_capture_saves_as_a_manifest_elsewhere() {
        let dir = text_folder();
        let c = import(dir.path(), None).unwrap();
        let out = tempfile::tempdir().unwrap();
        c.save_manifest(&out.path().join("capture.toml")).unwrap();
        let back = Capture::open(out.path()).unwrap();
        assert!(back.warnings.is_empty(), "{:?}", back.warnings);
        assert_eq!(back.photos.len(), 3);
        for (a, b) in c.photos.iter().zip(&back.photos) {
            assert_eq!(c.path_of(&a.image), back.path_of(&b.image));
            assert_eq!(
                a.saturated_mask.as_ref().map(|m| c.path_of(m)),
                b.saturated_mask.as_ref().map(|m| back.path_of(m))
            );
            assert_eq!(
                (&a.camera, &a.light, a.color),
                (&b.camera, &b.light, b.color)
            );
        }
    }

    /// The real sets of ../shared/data/real (read-only, never copied; skipped when absent).
    #[test]
    fn real_sets_import_with_nine_photos_at_256() {
        let real = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/real");
        if !real.is_dir() {
            return;
        }
        for (set, side) in [
            ("real_cards-blue", 6.848),
            ("bath_tile", 9.728),
            ("yellow_box", 10.88),
        ] {
            let c = Capture::open(&real.join(set)).unwrap();
            assert_eq!(c.photos.len(), 9, "{set}");
            assert!(
                (c.sample.width - side).abs() < 1e-12 && c.sample.height == c.sample.width,
                "{set}"
            );
            for (i, p) in c.photos.iter().enumerate() {
                assert_eq!(p.image, PathBuf::from(format!("256/{i:02}.png")), "{set}");
                assert_eq!(p.camera.resolution(), [256, 256], "{set}");
                assert!(
                    matches!(
                        p.light,
                        Light::Flash {
                            intensity: [1500.0, 1500.0, 1500.0]
                        }
                    ),
                    "{set}"
                );
                assert!(p.saturated_mask.is_some(), "{set}");
                assert!(
                    p.camera.position().z > 10.0 && p.camera.position().z < 30.0,
                    "{set}"
                );
            }
        }
    }
}

//! Photo sets: manifest, cameras, lights, images, importers (DESIGN.md "Photo-set manifest" and
//! "Importers").
//!
//! A [`Capture`] is what every later stage reads: the flat sample (a rectangle centred at the
//! origin of the plane z = 0, normal +z), and per photo its image, camera, light, exposure,
//! masks and colour encoding, with every default already applied.

pub mod atomic_file;
pub mod camera;
pub(crate) mod checks;
pub mod image_io;
pub mod light;
mod manifest;
pub mod materialgan;
pub mod materialgan_writer;

use std::fs;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use glam::DVec3;

pub use camera::{Camera, Frame, Pinhole, Rectified};
pub use image_io::{ColorEncoding, LinearImage};
pub use light::{Incident, Light};

use crate::error::{Error, Result};

/// File name of the manifest inside a capture folder.
pub const MANIFEST_NAME: &str = "capture.toml";

/// The flat sample: a `width` x `height` rectangle (capture units) centred at the origin of the
/// plane z = 0, `width` along x, `height` along y.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Sample {
    /// Extent along x.
    pub width: f64,
    /// Extent along y.
    pub height: f64,
}

impl Sample {
    /// Whether the point `x` of the plane z = 0 lies on the sample (edges included).
    pub fn contains(&self, x: DVec3) -> bool {
        x.x.abs() <= self.width / 2.0 && x.y.abs() <= self.height / 2.0
    }
}

/// One photo with every manifest default resolved.
#[derive(Clone, Debug, PartialEq)]
pub struct Photo {
    /// Image file, relative to [`Capture::root`] (or absolute).
    pub image: PathBuf,
    /// The manifest's `[camera]` with this photo's overrides applied.
    pub camera: Camera,
    /// The photo's light.
    pub light: Light,
    /// Gain that multiplies the prediction (PHYSICS.md "Conventions"); default 1.
    pub exposure: f64,
    /// Relative weight of this photo's pixels in the loss (manifest `weight`, default 1): lower
    /// it for a photo known to be noisier or less trusted.
    pub weight: f64,
    /// Optional keep-mask (zero pixels are ignored), relative to [`Capture::root`].
    pub mask: Option<PathBuf>,
    /// Optional saturation mask (nonzero pixels are saturated and ignored), relative to
    /// [`Capture::root`]. An extension of DESIGN.md's manifest, written by the MaterialGAN
    /// importer for its `NN_saturated_mask.png` files.
    pub saturated_mask: Option<PathBuf>,
    /// How the image's values encode linear radiance: the photo's `color`, else the manifest's
    /// `color`, else the file type's default ([`ColorEncoding::default_for`]).
    pub color: ColorEncoding,
    /// The image (and keep-mask) held in memory instead of read from `image` and `mask`
    /// ([`Capture::from_tables`]); `image` then only names the photo (its stem).
    pub pixels: Option<Arc<InMemoryPhoto>>,
}

/// A photo's pixels given in memory (the Python package's arrays).
#[derive(Clone, Debug, PartialEq)]
pub struct InMemoryPhoto {
    /// What errors about these pixels name in place of a file (`images[3]`).
    pub name: String,
    /// Linear RGB, as [`image_io::load_image`] decodes a file.
    pub image: LinearImage,
    /// Per pixel: false leaves it out of the fit (zero in a keep-mask image); `None`: keep all.
    pub keep: Option<Vec<bool>>,
}

impl Photo {
    /// The image's file stem (`000` for `000.exr`), which names this photo's rendered outputs
    /// (DESIGN.md "Command-line contract", `render`). Unique within a capture.
    pub fn stem(&self) -> String {
        self.image
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default()
    }
}

/// A photo set: the manifest (`capture.toml`) or an imported folder, fully resolved.
#[derive(Clone, Debug, PartialEq)]
pub struct Capture {
    /// Name of the photo set (the manifest's `name`, an imported folder's name).
    pub name: String,
    /// Unit of every length (sample size, positions); light intensities are per this unit.
    pub units: String,
    /// Folder that relative image and mask paths are resolved against (the manifest's folder).
    pub root: PathBuf,
    /// The flat sample's rectangle.
    pub sample: Sample,
    /// The manifest's top-level `color`: the default encoding of every photo, if given.
    pub color: Option<ColorEncoding>,
    /// How far the sample's surface lies below the plane the cameras and lights were
    /// calibrated on (the manifest's `[sample] depth`, `--depth`; capture units, >= 0): a
    /// marker board a little above the material. Positions are stored as calibrated;
    /// [`Capture::in_material_frame`] applies the offset.
    pub depth: f64,
    /// The photos, in manifest order.
    pub photos: Vec<Photo>,
    /// Things worth telling the user that are not errors (unknown manifest keys, ignored
    /// fields). Not written by [`Capture::save_manifest`].
    pub warnings: Vec<String>,
}

impl Capture {
    /// Opens a photo set. `path` is a manifest file, a folder holding [`MANIFEST_NAME`], a
    /// MaterialGAN flash-capture folder ([`materialgan::import`] with its default image size,
    /// the smallest), or one image subfolder of it (`yellow_box/1024`: that size).
    pub fn open(path: &Path) -> Result<Capture> {
        let metadata = fs::metadata(path).map_err(|e| Error::io(path, e))?;
        if metadata.is_file() {
            return manifest::read(path);
        }
        let manifest = path.join(MANIFEST_NAME);
        if manifest.is_file() {
            return manifest::read(&manifest);
        }
        if materialgan::is_materialgan_folder(path) {
            return materialgan::import(path, None);
        }
        match (path.parent(), path.file_name()) {
            (Some(parent), Some(images)) if materialgan::is_materialgan_folder(parent) => {
                materialgan::import(parent, Some(&images.to_string_lossy()))
            }
            _ => Err(Error::invalid(
                path,
                "folder",
                format!(
                    "expected a {MANIFEST_NAME} manifest, a MaterialGAN flash capture ({}) \
                     with NN.png images, or one of its image subfolders",
                    materialgan::METADATA_FILES.join(", ")
                ),
            )),
        }
    }

    /// A photo set from a manifest's tables `entries` (what `capture.toml` holds: `name`,
    /// `units`, `[sample]`, `[camera]`, `[[photo]]` with `light`, `exposure`, `camera`, ...)
    /// and each photo's `pixels` in photo order, in place of image files. Checked, defaulted
    /// and reported as a manifest is ([`Capture::open`]); errors name `source` and the field.
    pub fn from_tables(
        source: &Path,
        entries: toml::Table,
        pixels: Vec<InMemoryPhoto>,
    ) -> Result<Capture> {
        let mut capture = manifest::from_table(source, absolute_folder(Path::new("."))?, entries)?;
        if capture.photos.len() != pixels.len() {
            return Err(Error::invalid(
                source,
                "photo",
                format!(
                    "{} photos but {} images; expected one image per photo",
                    capture.photos.len(),
                    pixels.len()
                ),
            ));
        }
        for (photo, pixels) in capture.photos.iter_mut().zip(pixels) {
            photo.pixels = Some(Arc::new(pixels));
        }
        Ok(capture)
    }

    /// Writes the manifest atomically, such that [`Capture::open`] reads back an equal capture
    /// (apart from `warnings`, and `root`, which becomes the manifest's folder). Image and mask
    /// paths stay relative when the manifest goes to `root`, and become absolute otherwise.
    pub fn save_manifest(&self, path: &Path) -> Result<()> {
        manifest::write(self, path)
    }

    /// The capture with every position measured from the sample's surface: camera positions
    /// (and pinhole `look_at`) and point-light positions raised by [`Capture::depth`], depth 0.
    /// A rectified image covers the sample rectangle on the surface itself (the
    /// svbrdf-diff-renderer capture code warps the material plane, `depth` below its markers).
    pub fn in_material_frame(&self) -> std::borrow::Cow<'_, Capture> {
        if self.depth == 0.0 {
            return std::borrow::Cow::Borrowed(self);
        }
        let lift = DVec3::new(0.0, 0.0, self.depth);
        let mut lifted = self.clone();
        lifted.depth = 0.0;
        for photo in &mut lifted.photos {
            match &mut photo.camera {
                Camera::Pinhole(c) => {
                    c.position += lift;
                    c.look_at += lift;
                }
                Camera::Rectified(c) => c.position += lift,
            }
            if let Light::Point { position, .. } = &mut photo.light {
                *position += lift;
            }
        }
        std::borrow::Cow::Owned(lifted)
    }

    /// Resolves an image or mask path of this capture against [`Capture::root`].
    pub fn path_of(&self, relative: &Path) -> PathBuf {
        self.root.join(relative)
    }
}

/// The folder a file lives in, `.` for a bare file name.
fn folder_of(path: &Path) -> &Path {
    match path.parent() {
        Some(parent) if !parent.as_os_str().is_empty() => parent,
        _ => Path::new("."),
    }
}

/// `folder` made absolute (against the working directory), as an error naming it on failure.
fn absolute_folder(folder: &Path) -> Result<PathBuf> {
    std::path::absolute(folder).map_err(|e| Error::io(folder, e))
}

//! Per-pixel shading records, computed once per photo set (DESIGN.md "shading").
//!
//! Everything downstream of the capture (render, loss, fit) loops over these records and never
//! over images. Geometry is stored per sub-pixel sample (structure of arrays); targets and
//! weights are stored per pixel. A pixel's prediction is the mean over its `samples_per_pixel`
//! sub-samples of `f(wi, wo) * irradiance`.
//!
//! Layout: pixel `p` of the whole set (photo after photo, each row-major from the top row) owns
//! sub-samples `p * samples_per_pixel .. (p + 1) * samples_per_pixel`. With
//! `samples_per_pixel = k * k`, sub-sample `j = sy * k + sx` sits at the centre of cell
//! `(sx, sy)` of a k x k grid over the pixel: pixel position `(c + (sx + 0.5)/k, r + (sy + 0.5)/k)`
//! (pixel coordinates as in `capture::camera`). The radiance model is PHYSICS.md "Conventions"
//! (radiance of a pixel).

mod pyramid;
pub mod region;

use glam::DVec3;
use rayon::prelude::*;
use std::borrow::Cow;
use std::path::PathBuf;

use crate::capture::image_io::{load_image, load_mask};
use crate::capture::{Capture, Photo};
use crate::error::{Error, Result};

/// One photo's place in the record arrays.
#[derive(Clone, Debug)]
pub struct PhotoSpan {
    /// File stem of the photo's image (`000` for `000.exr`), used to name rendered outputs.
    pub stem: String,
    /// Image width in pixels (the camera's resolution).
    pub width: usize,
    /// Image height in pixels.
    pub height: usize,
    /// Index of this photo's first pixel in the per-pixel arrays (row-major, row 0 at the top).
    pub first_pixel: usize,
}

impl PhotoSpan {
    /// This photo's pixels in the per-pixel arrays.
    pub fn pixels(&self) -> std::ops::Range<usize> {
        self.first_pixel..self.first_pixel + self.width * self.height
    }
}

/// Why a pixel does not enter the loss (weight 0). Counted per photo set for reports.
///
/// Each excluded pixel is counted once, under the first reason that applies, in the order
/// outside_sample, masked, saturated, non_finite, negative.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct ExclusionCounts {
    /// Zero in the photo's keep-mask.
    pub masked: usize,
    /// Some channel at the format maximum, or nonzero in the photo's saturation mask.
    pub saturated: usize,
    /// Some channel NaN or infinite (floating-point images).
    pub non_finite: usize,
    /// Some channel below zero (floating-point images): not a radiance, e.g. over-subtracted
    /// dark frames.
    pub negative: usize,
    /// No sub-sample of the pixel sees the sample rectangle.
    pub outside_sample: usize,
}

impl std::ops::AddAssign for ExclusionCounts {
    fn add_assign(&mut self, other: ExclusionCounts) {
        self.masked += other.masked;
        self.saturated += other.saturated;
        self.non_finite += other.non_finite;
        self.negative += other.negative;
        self.outside_sample += other.outside_sample;
    }
}

/// Shading records of a whole photo set, structure of arrays.
#[derive(Clone, Debug, Default)]
pub struct ShadingRecords {
    /// Where each photo's pixels are, in capture order.
    pub photos: Vec<PhotoSpan>,
    /// Stratified sub-pixel samples per pixel (a perfect square: 1, 4, 9, ...).
    pub samples_per_pixel: usize,
    /// Per sub-sample: unit direction toward the light, local frame (z = sample normal).
    /// `+z` for sub-samples that miss the sample.
    pub wi: Vec<[f64; 3]>,
    /// Per sub-sample: unit direction toward the camera, local frame.
    /// `+z` for sub-samples that miss the sample.
    pub wo: Vec<[f64; 3]>,
    /// Per sub-sample: texture coordinates `(u, v)` in [0, 1]^2 of the point of the sample it
    /// sees, `u` along +x from the sample's left edge and `v` along -y from its top edge (as
    /// the rows of a rectified photo), which pick the texel of a maps material
    /// ([`crate::maps`]); `(0, 0)` for sub-samples that miss the sample. Empty for records made
    /// without a capture (tests, direction-pair lists), which only uniform materials render.
    pub uv: Vec<[f64; 2]>,
    /// Per sub-sample: the factor that turns `f` (1/sr) into radiance, exposure included:
    /// `I * wi.z / d^2 * exposure` for a point light. Zero where the sub-sample misses the
    /// sample or the light is below the horizon.
    pub irradiance: Vec<[f64; 3]>,
    /// Per pixel: linear radiance of the photo (zeros when built without images, and for
    /// non-finite pixels).
    pub target: Vec<[f64; 3]>,
    /// Per pixel: loss weight, 0 for excluded pixels (mask, saturation, non-finite, outside).
    pub weight: Vec<f64>,
    /// How many pixels were excluded, by reason.
    pub excluded: ExclusionCounts,
}

/// The geometry of one sub-sample: `(wi, wo, irradiance, uv)` as in [`ShadingRecords`].
type SubSample = ([f64; 3], [f64; 3], [f64; 3], [f64; 2]);

/// Geometry of a sub-sample that misses the sample: valid directions, no light.
const MISS: SubSample = ([0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [0.0; 3], [0.0; 2]);

impl ShadingRecords {
    /// Number of pixels over all photos.
    pub fn pixel_count(&self) -> usize {
        self.weight.len()
    }

    /// Records of raw direction pairs `(wi, wo)` without a capture: one photo `stem` of one
    /// row, one pixel per pair with one sub-sample of unit irradiance, so a render returns `f`
    /// (1/sr) of each pair.
    pub fn of_pairs(stem: &str, pairs: &[([f64; 3], [f64; 3])]) -> ShadingRecords {
        let n = pairs.len();
        ShadingRecords {
            photos: vec![PhotoSpan {
                stem: stem.into(),
                width: n,
                height: 1,
                first_pixel: 0,
            }],
            samples_per_pixel: 1,
            wi: pairs.iter().map(|p| p.0).collect(),
            wo: pairs.iter().map(|p| p.1).collect(),
            irradiance: vec![[1.0; 3]; n],
            target: vec![[0.0; 3]; n],
            weight: vec![1.0; n],
            ..ShadingRecords::default()
        }
    }

    /// The same records with the loss weight of every photo outside `keep` (indices into
    /// `photos`) set to 0: fits and losses on the result see only the kept photos, while pixel
    /// indices, and so the random streams of stochastic models, stay those of the full set.
    pub fn restricted_to_photos(&self, keep: impl Fn(usize) -> bool) -> ShadingRecords {
        let mut restricted = self.clone();
        for (index, photo) in self.photos.iter().enumerate() {
            if !keep(index) {
                restricted.weight[photo.pixels()].fill(0.0);
            }
        }
        restricted
    }

    /// `predicted` (one value per pixel) minus the photo at every loss pixel, 0 elsewhere:
    /// what the residual images of a fit show. In place: at 1024^2 the values of a photo set
    /// are a few hundred megabytes.
    pub fn residuals(&self, mut predicted: Vec<[f64; 3]>) -> Vec<[f64; 3]> {
        for ((p, t), w) in predicted.iter_mut().zip(&self.target).zip(&self.weight) {
            *p = if *w > 0.0 {
                [0, 1, 2].map(|c| p[c] - t[c])
            } else {
                [0.0; 3]
            };
        }
        predicted
    }

    /// Computes the records of `capture` with `pixel_samples` stratified sub-samples per pixel
    /// (a perfect square k*k, see the module docs).
    ///
    /// Each sub-sample sees the point `x` of the plane z = 0 given by the photo's camera; when
    /// `x` lies outside the sample rectangle (or a pinhole ray does not reach the plane from
    /// above) it is a miss with zero irradiance, and a pixel whose sub-samples all miss gets
    /// weight 0 (`outside_sample`). Otherwise `wo = normalize(camera - x)` and `wi`, irradiance
    /// come from the light ([`crate::capture::Light::incident`]), times the photo's exposure.
    ///
    /// With `load_targets`, every photo's image (and masks) is loaded: `target` is its linear
    /// radiance and `weight` is 0 for masked, saturated and non-finite pixels. Without it (to
    /// synthesise photos), targets are zero and only pixels outside the sample get weight 0.
    pub fn build(
        capture: &Capture,
        pixel_samples: usize,
        load_targets: bool,
    ) -> Result<ShadingRecords> {
        let grid = (1..=pixel_samples)
            .find(|k| k * k >= pixel_samples)
            .filter(|k| k * k == pixel_samples);
        let Some(grid) = grid else {
            return Err(Error::argument(
                "pixel_samples",
                format!("must be a perfect square (1, 4, 9, ...), got {pixel_samples}"),
            ));
        };
        let capture = &*capture.in_material_frame();
        let mut records = ShadingRecords {
            samples_per_pixel: pixel_samples,
            ..ShadingRecords::default()
        };
        records.reserve(capture)?;
        for (index, photo) in capture.photos.iter().enumerate() {
            let [width, height] = photo.camera.resolution();
            let span = PhotoSpan {
                stem: photo.stem(),
                width,
                height,
                first_pixel: records.pixel_count(),
            };
            records.add_geometry(capture, photo, &span, grid);
            if load_targets {
                records.add_targets(capture, index, &span)?;
            }
            records.photos.push(span);
        }
        Ok(records)
    }

    /// Reserves the arrays for every photo of `capture` at once (no regrowth while photos are
    /// appended); a set too large for memory is an error rather than an abort.
    fn reserve(&mut self, capture: &Capture) -> Result<()> {
        let pixels = capture.photos.iter().try_fold(0usize, |sum, photo| {
            let [width, height] = photo.camera.resolution();
            width.checked_mul(height).and_then(|n| sum.checked_add(n))
        });
        let sub_samples = pixels.and_then(|n| n.checked_mul(self.samples_per_pixel));
        let (Some(pixels), Some(sub_samples)) = (pixels, sub_samples) else {
            return Err(Error::argument(
                "pixel_samples",
                "the photo set has too many pixels to count",
            ));
        };
        let too_large = |_| {
            Error::argument(
                "pixel_samples",
                format!(
                    "{pixels} pixels x {} sub-samples do not fit in memory",
                    self.samples_per_pixel
                ),
            )
        };
        for per_sub_sample in [&mut self.wi, &mut self.wo, &mut self.irradiance] {
            per_sub_sample
                .try_reserve_exact(sub_samples)
                .map_err(too_large)?;
        }
        self.uv.try_reserve_exact(sub_samples).map_err(too_large)?;
        self.target.try_reserve_exact(pixels).map_err(too_large)?;
        self.weight.try_reserve_exact(pixels).map_err(too_large)
    }

    /// Appends the sub-sample geometry of one photo, and its pixels with the photo's weight where some
    /// sub-sample sees the sample and 0 (counted as outside) elsewhere.
    fn add_geometry(&mut self, capture: &Capture, photo: &Photo, span: &PhotoSpan, grid: usize) {
        let spp = grid * grid;
        let pixels = span.pixels();
        let first = pixels.start * spp;
        let sub_samples = pixels.end * spp;
        self.wi.resize(sub_samples, MISS.0);
        self.wo.resize(sub_samples, MISS.1);
        self.irradiance.resize(sub_samples, MISS.2);
        self.uv.resize(sub_samples, MISS.3);
        self.target.resize(pixels.end, [0.0; 3]);
        self.weight.resize(pixels.end, 0.0);
        let row = span.width * spp;
        self.wi[first..]
            .par_chunks_mut(row)
            .zip(self.wo[first..].par_chunks_mut(row))
            .zip(self.irradiance[first..].par_chunks_mut(row))
            .zip(self.uv[first..].par_chunks_mut(row))
            .zip(self.weight[pixels.start..].par_chunks_mut(span.width))
            .enumerate()
            .for_each(|(r, ((((wi, wo), irradiance), uv), weight))| {
                for (c, pixel_weight) in weight.iter_mut().enumerate() {
                    let mut seen = false;
                    for j in 0..spp {
                        let pixel = [
                            c as f64 + ((j % grid) as f64 + 0.5) / grid as f64,
                            r as f64 + ((j / grid) as f64 + 0.5) / grid as f64,
                        ];
                        if let Some((i, o, e, x)) = sub_sample(capture, photo, pixel) {
                            let s = c * spp + j;
                            (wi[s], wo[s], irradiance[s], uv[s]) = (i, o, e, x);
                            seen = true;
                        }
                    }
                    *pixel_weight = if seen { photo.weight } else { 0.0 };
                }
            });
        self.excluded.outside_sample += self.weight[pixels].iter().filter(|&&w| w == 0.0).count();
    }

    /// Loads photo `index`'s image and masks (or takes them from memory) into its pixels'
    /// targets and weights.
    fn add_targets(&mut self, capture: &Capture, index: usize, span: &PhotoSpan) -> Result<()> {
        let photo = &capture.photos[index];
        let (path, image) = match &photo.pixels {
            Some(pixels) => (PathBuf::from(&pixels.name), Cow::Borrowed(&pixels.image)),
            None => {
                let path = capture.path_of(&photo.image);
                let image = load_image(&path, photo.color)?;
                (path, Cow::Owned(image))
            }
        };
        if (image.width, image.height) != (span.width, span.height) {
            return Err(Error::invalid(
                &path,
                "resolution",
                format!(
                    "the image is {}x{} but photo[{index}]'s camera has resolution {}x{}",
                    image.width, image.height, span.width, span.height
                ),
            ));
        }
        let load = |mask: &Option<PathBuf>| {
            mask.as_ref()
                .map(|m| load_mask(&capture.path_of(m), span.width, span.height))
                .transpose()
        };
        let keep = match &photo.pixels {
            Some(pixels) => pixels.keep.clone(),
            None => load(&photo.mask)?,
        };
        let saturated_mask = load(&photo.saturated_mask)?;
        let pixels = span.pixels();
        let mut counts = ExclusionCounts::default();
        let targets = self.target[pixels.clone()].iter_mut();
        for (p, (target, weight)) in targets.zip(&mut self.weight[pixels]).enumerate() {
            let value = image.rgb[p].map(f64::from);
            let finite = value.iter().all(|v| v.is_finite());
            *target = if finite { value } else { [0.0; 3] };
            if *weight == 0.0 {
                continue; // outside the sample, already counted
            }
            let reason = if keep.as_ref().is_some_and(|k| !k[p]) {
                &mut counts.masked
            } else if image.saturated[p] || saturated_mask.as_ref().is_some_and(|s| s[p]) {
                &mut counts.saturated
            } else if !finite {
                &mut counts.non_finite
            } else if value.iter().any(|v| *v < 0.0) {
                &mut counts.negative
            } else {
                continue;
            };
            *reason += 1;
            *weight = 0.0;
        }
        self.excluded += counts;
        Ok(())
    }
}

/// `(wi, wo, irradiance * exposure, uv)` of the sub-sample at pixel position `pixel`, or
/// `None` when it does not see the sample.
fn sub_sample(capture: &Capture, photo: &Photo, pixel: [f64; 2]) -> Option<SubSample> {
    let x = photo
        .camera
        .surface_point(&capture.sample, pixel)
        .filter(|x| capture.sample.contains(*x))?;
    let camera = photo.camera.position();
    let incident = photo.light.incident(camera, x);
    let wo: DVec3 = (camera - x).normalize();
    Some((
        incident.wi.to_array(),
        wo.to_array(),
        incident.irradiance.map(|e| e * photo.exposure),
        [
            x.x / capture.sample.width + 0.5,
            0.5 - x.y / capture.sample.height,
        ],
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::capture::image_io::{srgb_to_linear, write_exr};
    use crate::capture::{Camera, ColorEncoding, Light, Pinhole, Rectified, Sample};
    use std::path::{Path, PathBuf};

    fn photo(image: &str, camera: Camera, light: Light) -> Photo {
        Photo {
            image: PathBuf::from(image),
            camera,
            light,
            exposure: 1.0,
            weight: 1.0,
            mask: None,
            saturated_mask: None,
            color: ColorEncoding::default_for(Path::new(image)),
            pixels: None,
        }
    }

    fn capture(root: &Path, sample: Sample, photos: Vec<Photo>) -> Capture {
        Capture {
            name: "test".into(),
            units: "cm".into(),
            root: root.to_path_buf(),
            sample,
            color: None,
            depth: 0.0,
            photos,
            warnings: Vec::new(),
        }
    }

    fn rectified(position: DVec3, resolution: [usize; 2]) -> Camera {
        Camera::Rectified(Rectified {
            position,
            resolution,
        })
    }

    fn close(a: [f64; 3], b: [f64; 3], tolerance: f64) -> bool {
        (DVec3::from_array(a) - DVec3::from_array(b)).length() <= tolerance
    }

    #[test]
    fn pixel_samples_must_be_a_perfect_square() {
        let c = capture(
            Path::new("."),
            Sample {
                width: 1.0,
                height: 1.0,
            },
            Vec::new(),
        );
        for bad in [0, 2, 3, 8, 15] {
            let m = ShadingRecords::build(&c, bad, false)
                .unwrap_err()
                .to_string();
            assert!(m.contains("pixel_samples: must be a perfect square"), "{m}");
        }
        for good in [1, 4, 9, 16] {
            assert_eq!(
                ShadingRecords::build(&c, good, false)
                    .unwrap()
                    .samples_per_pixel,
                good
            );
        }
    }

    #[test]
    fn absurd_resolutions_are_errors_not_aborts() {
        let light = Light::Flash {
            intensity: [1.0; 3],
        };
        let sample = Sample {
            width: 1.0,
            height: 1.0,
        };
        for (resolution, expected) in [
            ([usize::MAX / 2, 4], "too many pixels to count"),
            ([1 << 40, 1 << 20], "do not fit in memory"),
        ] {
            let p = photo("a.png", rectified(DVec3::Z, resolution), light.clone());
            let c = capture(Path::new("."), sample, vec![p]);
            let m = ShadingRecords::build(&c, 1, false).unwrap_err().to_string();
            assert!(m.contains("pixel_samples") && m.contains(expected), "{m}");
        }
    }

    #[test]
    fn flash_above_the_centre_of_a_rectified_capture() {
        let camera = DVec3::new(0.0, 0.0, 4.0);
        let mut p = photo(
            "a.png",
            rectified(camera, [5, 5]),
            Light::Flash {
                intensity: [16.0, 8.0, 4.0],
            },
        );
        p.exposure = 2.0;
        let c = capture(
            Path::new("."),
            Sample {
                width: 5.0,
                height: 5.0,
            },
            vec![p],
        );
        let r = ShadingRecords::build(&c, 1, false).unwrap();
        assert_eq!(r.pixel_count(), 25);
        assert_eq!((r.wi.len(), r.wo.len(), r.irradiance.len()), (25, 25, 25));
        let centre = 2 * 5 + 2;
        assert_eq!(r.wi[centre], [0.0, 0.0, 1.0]);
        assert_eq!(r.wo[centre], [0.0, 0.0, 1.0]);
        // I / d^2 * exposure with d = 4.
        assert_eq!(r.irradiance[centre], [2.0, 1.0, 0.5]);
        // Top-left pixel sees x = (-2, +2): row 0 is +y, column 0 is -x.
        let to_camera = DVec3::new(2.0, -2.0, 4.0);
        assert!(close(r.wo[0], to_camera.normalize().to_array(), 1e-15));
        assert_eq!(r.wi[0], r.wo[0]);
        let expected = 16.0 * (4.0 / to_camera.length()) / to_camera.length_squared() * 2.0;
        assert!((r.irradiance[0][0] - expected).abs() < 1e-14);
        assert_eq!(r.weight, vec![1.0; 25]);
        assert_eq!(r.excluded, ExclusionCounts::default());
        assert_eq!(r.target, vec![[0.0; 3]; 25]);
    }

    #[test]
    fn sub_samples_are_stratified_cell_centres_in_row_major_order() {
        let camera = DVec3::new(0.0, 0.0, 4.0);
        let p = photo(
            "a.png",
            rectified(camera, [5, 5]),
            Light::Flash {
                intensity: [1.0; 3],
            },
        );
        let c = capture(
            Path::new("."),
            Sample {
                width: 5.0,
                height: 5.0,
            },
            vec![p],
        );
        let r = ShadingRecords::build(&c, 4, false).unwrap();
        assert_eq!(r.wo.len(), 100);
        let centre = 2 * 5 + 2;
        let seen: Vec<[f64; 2]> = (0..4)
            .map(|j| {
                let wo = DVec3::from_array(r.wo[centre * 4 + j]);
                let x = camera - wo * (camera.z / wo.z);
                [x.x, x.y]
            })
            .collect();
        let expected = [[-0.25, 0.25], [0.25, 0.25], [-0.25, -0.25], [0.25, -0.25]];
        for (s, e) in seen.iter().zip(expected) {
            assert!(
                (s[0] - e[0]).abs() < 1e-12 && (s[1] - e[1]).abs() < 1e-12,
                "{seen:?}"
            );
        }
    }

    #[test]
    fn pinhole_looking_down_sees_the_sample_where_project_says() {
        // fov 90 deg over 40 px: fy = 20, so from h = 10 the 10 x 10 sample spans pixels 10..30.
        let h = 10.0;
        let cam = Pinhole::with_fov(
            DVec3::new(0.0, 0.0, h),
            DVec3::ZERO,
            DVec3::Y,
            90.0,
            [40, 40],
        );
        let sample = Sample {
            width: 10.0,
            height: 10.0,
        };
        let corners = [
            (-5.0, 5.0, [10.0, 10.0]),
            (5.0, 5.0, [30.0, 10.0]),
            (-5.0, -5.0, [10.0, 30.0]),
            (5.0, -5.0, [30.0, 30.0]),
        ];
        for (x, y, pixel) in corners {
            let p = cam.project(DVec3::new(x, y, 0.0)).unwrap();
            assert!(
                (p[0] - pixel[0]).abs() < 1e-12 && (p[1] - pixel[1]).abs() < 1e-12,
                "{p:?}"
            );
        }
        let p = photo(
            "a.exr",
            Camera::Pinhole(cam),
            Light::Flash {
                intensity: [1.0; 3],
            },
        );
        let c = capture(Path::new("."), sample, vec![p]);
        let r = ShadingRecords::build(&c, 1, false).unwrap();
        for row in 0..40 {
            for col in 0..40 {
                let inside = (10..30).contains(&row) && (10..30).contains(&col);
                assert_eq!(
                    r.weight[row * 40 + col],
                    if inside { 1.0 } else { 0.0 },
                    "{row} {col}"
                );
            }
        }
        assert_eq!(r.excluded.outside_sample, 1600 - 400);
        // Pixel (10, 10) sees x = (-4.75, 4.75).
        let expected = (DVec3::new(0.0, 0.0, h) - DVec3::new(-4.75, 4.75, 0.0)).normalize();
        assert!(close(r.wo[10 * 40 + 10], expected.to_array(), 1e-12));
        // Misses are harmless: +z directions and no light.
        assert_eq!((r.wi[0], r.wo[0], r.irradiance[0], r.uv[0]), MISS);
    }

    #[test]
    fn tilted_pinhole_weights_match_the_projected_sample_outline() {
        let cam = Pinhole::with_fov(
            DVec3::new(6.0, -9.0, 14.0),
            DVec3::new(0.5, 0.3, 0.0),
            DVec3::Z,
            50.0,
            [64, 48],
        );
        let sample = Sample {
            width: 8.0,
            height: 6.0,
        };
        // Outline in pixels, counter-clockwise in the world (so clockwise on the y-down image).
        let outline: Vec<[f64; 2]> = [(-4.0, -3.0), (4.0, -3.0), (4.0, 3.0), (-4.0, 3.0)]
            .iter()
            .map(|&(x, y)| cam.project(DVec3::new(x, y, 0.0)).unwrap())
            .collect();
        let inside = |p: [f64; 2]| {
            let sides = (0..4).map(|i| {
                let (a, b) = (outline[i], outline[(i + 1) % 4]);
                (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0])
            });
            let signs: Vec<bool> = sides.map(|s| s > 0.0).collect();
            signs.iter().all(|&s| s == signs[0])
        };
        let c = capture(
            Path::new("."),
            sample,
            vec![photo(
                "a.exr",
                Camera::Pinhole(cam),
                Light::Flash {
                    intensity: [1.0; 3],
                },
            )],
        );
        let r = ShadingRecords::build(&c, 1, false).unwrap();
        let mut covered = 0;
        for row in 0..48 {
            for col in 0..64 {
                let expected = inside([col as f64 + 0.5, row as f64 + 0.5]);
                assert_eq!(r.weight[row * 64 + col] == 1.0, expected, "{row} {col}");
                covered += usize::from(expected);
            }
        }
        assert!(covered > 200 && covered < 64 * 48 - 200, "{covered}");
    }

    #[test]
    fn directional_light_gives_constant_irradiance() {
        let light = Light::Directional {
            direction: DVec3::new(0.0, 3.0, 4.0),
            irradiance: [5.0; 3],
        };
        let c = capture(
            Path::new("."),
            Sample {
                width: 2.0,
                height: 2.0,
            },
            vec![photo(
                "a.png",
                rectified(DVec3::new(0.0, 0.0, 3.0), [4, 4]),
                light,
            )],
        );
        let r = ShadingRecords::build(&c, 4, false).unwrap();
        assert!(r.irradiance.iter().all(|e| close(*e, [4.0; 3], 1e-14)));
        assert!(r.wi.iter().all(|w| close(*w, [0.0, 0.6, 0.8], 1e-15)));
    }

    /// A 4 x 3 rectified photo set in `dir` with PNG pixels `values` (grey levels).
    fn png_capture(dir: &Path, values: &[u8]) -> Capture {
        image::GrayImage::from_raw(4, 3, values.to_vec())
            .unwrap()
            .save(dir.join("p.png"))
            .unwrap();
        let p = photo(
            "p.png",
            rectified(DVec3::new(0.0, 0.0, 5.0), [4, 3]),
            Light::Flash {
                intensity: [1.0; 3],
            },
        );
        capture(
            dir,
            Sample {
                width: 4.0,
                height: 3.0,
            },
            vec![p],
        )
    }

    #[test]
    fn targets_are_linear_and_masks_exclude_exactly_their_zero_pixels() {
        let dir = tempfile::tempdir().unwrap();
        let values = [10, 20, 255, 40, 50, 60, 70, 255, 90, 100, 110, 120];
        let mut c = png_capture(dir.path(), &values);
        let keep = [1, 1, 1, 1, 0, 1, 1, 0, 1, 0, 1, 1];
        image::GrayImage::from_raw(4, 3, keep.iter().map(|&k| k * 200).collect())
            .unwrap()
            .save(dir.path().join("m.png"))
            .unwrap();
        c.photos[0].mask = Some(PathBuf::from("m.png"));
        let r = ShadingRecords::build(&c, 1, true).unwrap();
        for (p, &v) in values.iter().enumerate() {
            assert_eq!(
                r.target[p],
                [srgb_to_linear(f64::from(v) / 255.0) as f32 as f64; 3]
            );
        }
        // Pixel 2 is saturated; pixel 7 is saturated but masked, which takes precedence.
        let expected: Vec<f64> = (0..12)
            .map(|p| if keep[p] == 0 || p == 2 { 0.0 } else { 1.0 })
            .collect();
        assert_eq!(r.weight, expected);
        assert_eq!(
            r.excluded,
            ExclusionCounts {
                masked: 3,
                saturated: 1,
                non_finite: 0,
                negative: 0,
                outside_sample: 0
            }
        );
    }

    #[test]
    fn saturation_masks_and_non_finite_pixels_are_counted() {
        let dir = tempfile::tempdir().unwrap();
        let mut c = png_capture(dir.path(), &[1; 12]);
        let flagged = [0, 0, 0, 9, 0, 0, 0, 0, 0, 0, 0, 1];
        image::GrayImage::from_raw(4, 3, flagged.to_vec())
            .unwrap()
            .save(dir.path().join("s.png"))
            .unwrap();
        c.photos[0].saturated_mask = Some(PathBuf::from("s.png"));
        let mut hdr = vec![[0.5f32; 3]; 12];
        hdr[5] = [f32::NAN, 0.0, 0.0];
        hdr[6] = [0.0, f32::INFINITY, 0.0];
        hdr[7] = [0.5, -1e-3, 0.5];
        write_exr(&dir.path().join("h.exr"), &hdr, 4, 3).unwrap();
        let mut second = c.photos[0].clone();
        (second.image, second.saturated_mask, second.color) =
            (PathBuf::from("h.exr"), None, ColorEncoding::Linear);
        c.photos.push(second);
        let r = ShadingRecords::build(&c, 1, true).unwrap();
        assert_eq!(r.photos[1].pixels(), 12..24);
        assert_eq!(
            r.excluded,
            ExclusionCounts {
                masked: 0,
                saturated: 2,
                non_finite: 2,
                negative: 1,
                outside_sample: 0
            }
        );
        let zero: Vec<usize> = (0..24).filter(|&p| r.weight[p] == 0.0).collect();
        assert_eq!(zero, vec![3, 11, 17, 18, 19]);
        assert_eq!(
            (r.target[17], r.target[18], r.target[12]),
            ([0.0; 3], [0.0; 3], [0.5; 3])
        );
    }

    #[test]
    fn pixels_in_memory_give_the_records_of_their_image_file() {
        let dir = tempfile::tempdir().unwrap();
        let mut hdr = vec![[0.5f32; 3]; 12];
        hdr[5] = [f32::NAN, 0.0, 0.0];
        hdr[7] = [0.25, 2.0, 0.5];
        write_exr(&dir.path().join("h.exr"), &hdr, 4, 3).unwrap();
        let mut c = png_capture(dir.path(), &[1; 12]);
        (c.photos[0].image, c.photos[0].color) = (PathBuf::from("h.exr"), ColorEncoding::Linear);
        let from_file = ShadingRecords::build(&c, 4, true).unwrap();
        let image = load_image(&dir.path().join("h.exr"), ColorEncoding::Linear).unwrap();
        let in_memory = |keep: Option<Vec<bool>>| {
            let mut c = c.clone();
            c.photos[0].image = PathBuf::from("not-a-file");
            c.photos[0].pixels = Some(std::sync::Arc::new(crate::capture::InMemoryPhoto {
                name: "images[0]".into(),
                image: image.clone(),
                keep,
            }));
            ShadingRecords::build(&c, 4, true)
        };
        let same = in_memory(None).unwrap();
        assert_eq!(same.target, from_file.target);
        assert_eq!(same.weight, from_file.weight);
        assert_eq!(same.excluded, from_file.excluded);
        assert_eq!(
            (same.wi, same.irradiance),
            (from_file.wi, from_file.irradiance)
        );
        // A keep-mask in memory leaves its pixels out, as a mask image does.
        let mut keep = vec![true; 12];
        keep[0] = false;
        let masked = in_memory(Some(keep)).unwrap();
        assert_eq!((masked.weight[0], masked.excluded.masked), (0.0, 1));
        // A wrong size names the pixels in memory.
        let mut c = c.clone();
        c.photos[0].camera = rectified(DVec3::new(0.0, 0.0, 5.0), [4, 4]);
        c.photos[0].pixels = Some(std::sync::Arc::new(crate::capture::InMemoryPhoto {
            name: "images[0]".into(),
            image,
            keep: None,
        }));
        let m = ShadingRecords::build(&c, 1, true).unwrap_err().to_string();
        assert!(
            m.starts_with("images[0]: resolution: the image is 4x3"),
            "{m}"
        );
    }

    #[test]
    fn a_photo_of_the_wrong_size_is_an_error_naming_both_sizes() {
        let dir = tempfile::tempdir().unwrap();
        let mut c = png_capture(dir.path(), &[1; 12]);
        c.photos[0].camera = rectified(DVec3::new(0.0, 0.0, 5.0), [4, 4]);
        let m = ShadingRecords::build(&c, 1, true).unwrap_err().to_string();
        assert!(
            m.contains("p.png") && m.contains("4x3") && m.contains("4x4"),
            "{m}"
        );
        // Without targets the image is not read at all.
        assert!(ShadingRecords::build(&c, 1, false).is_ok());
    }

    #[test]
    fn partly_covered_pixels_keep_weight_with_zero_irradiance_sub_samples() {
        // Sample edge at x = 4.75 falls at pixel position 29.5: pixel 29's right sub-samples miss.
        let cam = Pinhole::with_fov(
            DVec3::new(0.0, 0.0, 10.0),
            DVec3::ZERO,
            DVec3::Y,
            90.0,
            [40, 40],
        );
        let c = capture(
            Path::new("."),
            Sample {
                width: 9.5,
                height: 10.0,
            },
            vec![photo(
                "a.exr",
                Camera::Pinhole(cam),
                Light::Flash {
                    intensity: [1.0; 3],
                },
            )],
        );
        let r = ShadingRecords::build(&c, 4, false).unwrap();
        let pixel = 20 * 40 + 29;
        assert_eq!(r.weight[pixel], 1.0);
        let lit: Vec<bool> = (0..4)
            .map(|j| r.irradiance[pixel * 4 + j][0] > 0.0)
            .collect();
        assert_eq!(lit, vec![true, false, true, false]);
        assert_eq!(r.weight[pixel + 1], 0.0);
    }

    /// The README's sanity check on the real sets (skipped when absent): the brightest spot of
    /// a flash photo lies near the point below the co-located camera and flash (10-40 px at 256
    /// px, offset by albedo and the flash-lens offset). Averaged over each set, it must be near
    /// and clearly nearer than under a flipped or transposed image orientation.
    #[test]
    fn real_sets_brightest_spot_is_below_the_flash() {
        let real = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/real");
        if !real.is_dir() {
            return;
        }
        for set in ["real_cards-blue", "bath_tile", "yellow_box"] {
            let c = Capture::open(&real.join(set)).unwrap();
            let r = ShadingRecords::build(&c, 1, true).unwrap();
            assert!(r.excluded.saturated > 0, "{set}");
            // Mean distance to the brightest spot: as built, flipped in y, flipped in x, transposed.
            let mut mean = [0.0; 4];
            for (photo, span) in c.photos.iter().zip(&r.photos) {
                let side = span.width as f64;
                let luminance: Vec<f64> = r.target[span.pixels()]
                    .iter()
                    .map(|t| t.iter().sum())
                    .collect();
                let spot = brightest_block(&luminance, span.width, 32);
                let [x, y] = photo
                    .camera
                    .project(&c.sample, photo.camera.position())
                    .unwrap();
                for (m, p) in mean
                    .iter_mut()
                    .zip([[x, y], [x, side - y], [side - x, y], [y, x]])
                {
                    *m += ((spot[0] - p[0]).powi(2) + (spot[1] - p[1]).powi(2)).sqrt()
                        / c.photos.len() as f64;
                }
            }
            assert!(mean[0] < 45.0, "{set}: {mean:?}");
            assert!(
                mean[1..].iter().all(|&wrong| mean[0] < 0.5 * wrong),
                "{set}: {mean:?}"
            );
        }
    }

    /// Centre (pixel coordinates) of the brightest `block` x `block` mean of a square image.
    fn brightest_block(values: &[f64], side: usize, block: usize) -> [f64; 2] {
        let mut best = (f64::MIN, [0.0; 2]);
        for r in (0..=side - block).step_by(block / 2) {
            for c in (0..=side - block).step_by(block / 2) {
                let sum: f64 = (r..r + block)
                    .flat_map(|y| (c..c + block).map(move |x| y * side + x))
                    .map(|p| values[p])
                    .sum();
                if sum > best.0 {
                    best = (sum, [(c + block / 2) as f64, (r + block / 2) as f64]);
                }
            }
        }
        best.1
    }
}

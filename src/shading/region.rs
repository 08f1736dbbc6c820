//! Restricting a fit to part of the sample (`--region`, `--mask`): a spatially varying sample
//! is fitted with one homogeneous material over a patch that looks uniform.
//!
//! | option | region | units and origin |
//! | --- | --- | --- |
//! | `--region x0,y0,x1,y1` | the rectangle `x0 <= x <= x1`, `y0 <= y <= y1` | sample coordinates: capture units (cm for MaterialGAN folders), origin at the sample's centre, x to the right of a rectified image, y to its top (row 0 is +y) |
//! | `--mask IMAGE` | nonzero pixels of an image laid over the whole sample rectangle (row 0 at +y, column 0 at -x, as a rectified photo); any resolution | the image's pixel `(c, r)` covers `x = ((c + 0.5)/W - 0.5) w`, `y = -((r + 0.5)/H - 0.5) h` |
//!
//! A photo pixel belongs to the region when the point of the sample its centre sees does;
//! the others get weight 0. [`SampleRegion::apply`] also returns every pixel's sample point,
//! for the uniformity check of [`crate::fit::point::uniformity`].

use std::path::{Path, PathBuf};

use glam::DVec3;

use super::ShadingRecords;
use crate::capture::image_io::load_image;
use crate::capture::{Capture, ColorEncoding, Sample};
use crate::error::{Error, Result};

/// The part of the sample a fit uses.
#[derive(Clone, Debug, PartialEq)]
pub enum SampleRegion {
    /// `[x0, y0, x1, y1]` in sample coordinates, `x0 < x1`, `y0 < y1`.
    Rectangle([f64; 4]),
    /// A keep-mask over the sample rectangle.
    Mask {
        path: PathBuf,
        width: usize,
        height: usize,
        keep: Vec<bool>,
    },
}

/// A region applied to a photo set's records.
#[derive(Clone, Debug)]
pub struct AppliedRegion {
    pub region: SampleRegion,
    /// Per pixel of the records: the sample point `[x, y]` its centre sees (`None` off the
    /// sample).
    pub points: Vec<Option<[f64; 2]>>,
    /// Pixels that entered the loss before the region was applied and are outside it.
    pub excluded: usize,
    /// The region's bounding box in sample coordinates, clipped to the sample.
    pub bounds: [f64; 4],
}

impl SampleRegion {
    /// Parses `x0,y0,x1,y1`.
    pub fn parse_rectangle(text: &str) -> Result<SampleRegion> {
        let bad = |m: String| Error::argument("--region", format!("`{text}`: {m}"));
        let numbers = text
            .split(',')
            .map(|s| s.trim().parse::<f64>())
            .collect::<std::result::Result<Vec<f64>, _>>()
            .map_err(|_| bad("expected four numbers x0,y0,x1,y1".into()))?;
        let [x0, y0, x1, y1]: [f64; 4] = numbers
            .try_into()
            .map_err(|v: Vec<f64>| bad(format!("expected four numbers, found {}", v.len())))?;
        if ![x0, y0, x1, y1].iter().all(|v| v.is_finite()) || x0 >= x1 || y0 >= y1 {
            return Err(bad(
                "expected finite numbers with x0 < x1 and y0 < y1".into()
            ));
        }
        Ok(SampleRegion::Rectangle([x0, y0, x1, y1]))
    }

    /// Loads a mask image (nonzero = keep).
    pub fn load_mask(path: &Path) -> Result<SampleRegion> {
        let image = load_image(path, ColorEncoding::Linear)?;
        let keep: Vec<bool> = image
            .rgb
            .iter()
            .map(|p| p.iter().any(|&v| v != 0.0))
            .collect();
        if !keep.contains(&true) {
            return Err(Error::invalid(
                path,
                "pixels",
                "every pixel is zero: the region is empty",
            ));
        }
        Ok(SampleRegion::Mask {
            path: path.to_path_buf(),
            width: image.width,
            height: image.height,
            keep,
        })
    }

    /// Whether the sample point `[x, y]` lies in the region.
    pub fn contains(&self, sample: &Sample, [x, y]: [f64; 2]) -> bool {
        match self {
            SampleRegion::Rectangle([x0, y0, x1, y1]) => {
                (*x0..=*x1).contains(&x) && (*y0..=*y1).contains(&y)
            }
            SampleRegion::Mask {
                width,
                height,
                keep,
                ..
            } => {
                let u = (x / sample.width + 0.5) * *width as f64;
                let v = (0.5 - y / sample.height) * *height as f64;
                let (c, r) = (u.floor(), v.floor());
                c >= 0.0
                    && r >= 0.0
                    && (c as usize) < *width
                    && (r as usize) < *height
                    && keep[r as usize * width + c as usize]
            }
        }
    }

    /// Bounding box of the region on the sample, in sample coordinates.
    fn bounds(&self, sample: &Sample) -> [f64; 4] {
        let (hw, hh) = (sample.width / 2.0, sample.height / 2.0);
        match self {
            SampleRegion::Rectangle([x0, y0, x1, y1]) => {
                [x0.max(-hw), y0.max(-hh), x1.min(hw), y1.min(hh)]
            }
            SampleRegion::Mask {
                width,
                height,
                keep,
                ..
            } => {
                let mut b = [
                    f64::INFINITY,
                    f64::INFINITY,
                    f64::NEG_INFINITY,
                    f64::NEG_INFINITY,
                ];
                for (i, _) in keep.iter().enumerate().filter(|(_, k)| **k) {
                    let (c, r) = ((i % width) as f64, (i / width) as f64);
                    let x = [c / *width as f64, (c + 1.0) / *width as f64]
                        .map(|u| (u - 0.5) * sample.width);
                    let y = [r / *height as f64, (r + 1.0) / *height as f64]
                        .map(|v| (0.5 - v) * sample.height);
                    b = [
                        b[0].min(x[0]),
                        b[1].min(y[1]),
                        b[2].max(x[1]),
                        b[3].max(y[0]),
                    ];
                }
                b
            }
        }
    }

    /// Sets the weight of every pixel of `records` (built from `capture`) outside the region
    /// to 0; an error when no pixel of the loss is left.
    pub fn apply(self, capture: &Capture, records: &mut ShadingRecords) -> Result<AppliedRegion> {
        let points = pixel_points(capture);
        let mut excluded = 0;
        for (weight, point) in records.weight.iter_mut().zip(&points) {
            if *weight > 0.0 && !point.is_some_and(|p| self.contains(&capture.sample, p)) {
                *weight = 0.0;
                excluded += 1;
            }
        }
        if !records.weight.iter().any(|w| *w > 0.0) {
            let (field, what) = match &self {
                SampleRegion::Rectangle(r) => ("--region".to_string(), format!("{r:?}")),
                SampleRegion::Mask { path, .. } => {
                    ("--mask".to_string(), path.display().to_string())
                }
            };
            return Err(Error::argument(
                field,
                format!(
                    "no usable pixel of the photos lies in the region {what} (sample \
                     coordinates: origin at the centre, the sample spans +-{} x +-{})",
                    capture.sample.width / 2.0,
                    capture.sample.height / 2.0
                ),
            ));
        }
        Ok(AppliedRegion {
            bounds: self.bounds(&capture.sample),
            region: self,
            points,
            excluded,
        })
    }
}

/// The sample point `[x, y]` seen by the centre of every pixel of every photo (records
/// order), `None` where it misses the sample.
pub fn pixel_points(capture: &Capture) -> Vec<Option<[f64; 2]>> {
    let capture = capture.in_material_frame();
    let mut points = Vec::new();
    for photo in &capture.photos {
        let [width, height] = photo.camera.resolution();
        for r in 0..height {
            for c in 0..width {
                let centre = [c as f64 + 0.5, r as f64 + 0.5];
                let point: Option<DVec3> = photo
                    .camera
                    .surface_point(&capture.sample, centre)
                    .filter(|x| capture.sample.contains(*x));
                points.push(point.map(|x| [x.x, x.y]));
            }
        }
    }
    points
}

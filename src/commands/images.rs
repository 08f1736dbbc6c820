//! Writing per-photo images of a photo set: linear EXR plus a tone-mapped PNG.

use crate::capture::image_io::{write_exr, write_png_tonemapped};
use crate::error::Result;
use crate::shading::ShadingRecords;
use std::path::Path;

/// Exposure that maps the 99.5th percentile of all channel values to 1 (so highlights clip
/// only slightly and the PNGs of one set share one exposure).
pub fn display_exposure(values: &[[f64; 3]]) -> f64 {
    let mut all: Vec<f64> = values
        .iter()
        .flat_map(|v| v.iter().copied())
        .filter(|v| v.is_finite() && *v > 0.0)
        .collect();
    if all.is_empty() {
        return 1.0;
    }
    let k = ((all.len() as f64 * 0.995) as usize).min(all.len() - 1);
    let (_, p, _) = all.select_nth_unstable_by(k, |a, b| a.total_cmp(b));
    1.0 / *p
}

/// Write `folder/<stem>.exr` and `folder/<stem>.png` for every photo of `records`, with pixel
/// values `per_pixel` (one per pixel of the records). Returns the file stems written.
pub fn write_photo_images(
    folder: &Path,
    records: &ShadingRecords,
    per_pixel: &[[f64; 3]],
    exposure: f64,
    suffix: &str,
) -> Result<()> {
    for photo in &records.photos {
        let n = photo.width * photo.height;
        let rgb: Vec<[f32; 3]> = per_pixel[photo.first_pixel..photo.first_pixel + n]
            .iter()
            .map(|v| v.map(|c| c as f32))
            .collect();
        let stem = format!("{}{suffix}", photo.stem);
        write_exr(
            &folder.join(format!("{stem}.exr")),
            &rgb,
            photo.width,
            photo.height,
        )?;
        write_png_tonemapped(
            &folder.join(format!("{stem}.png")),
            &rgb,
            photo.width,
            photo.height,
            exposure,
        )?;
    }
    Ok(())
}

//! Writing per-photo images of a photo set: linear EXR plus a tone-mapped PNG.

use crate::capture::image_io::{write_exr, write_png_tonemapped};
use crate::error::Result;
use crate::shading::ShadingRecords;
use std::path::Path;

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

//! Write a photo set in the MaterialGAN / svbrdf-diff-renderer flash format, the inverse of
//! [`super::materialgan::import`]: `NN.png` 8-bit images encoded with a pure 2.2 power law and
//! clipped at 1 (`pixel/255 = clamp(L, 0, 1)^(1/2.2)`, the convention of the original code, see
//! `shared/data/real/README.md`), plus `camera_pos.txt`, `light_pos.txt`, `light_power.txt` and
//! `image_size.txt` (cm). Used to make test sets that look like real phone captures.

use super::camera::Camera;
use super::light::Light;
use super::Capture;
use crate::error::{Error, Result};
use std::fmt::Write as _;
use std::path::Path;

/// Write `capture` with per-pixel linear radiance `pixels` (photo after photo, row-major) into
/// `folder`. The capture must have rectified cameras over a square sample and point or flash
/// lights of one common intensity, as the format has no room for anything else.
pub fn write(folder: &Path, capture: &Capture, pixels: &[[f64; 3]]) -> Result<()> {
    let unsupported = |field: String, msg: &str| {
        Error::invalid(
            capture.root.join(super::MANIFEST_NAME),
            field,
            format!("{msg} (the MaterialGAN format has no room for it)"),
        )
    };
    if (capture.sample.width - capture.sample.height).abs() > 1e-9 * capture.sample.width {
        return Err(unsupported("sample".into(), "the sample must be square"));
    }
    let (mut cameras, mut lights, mut power) = (String::new(), String::new(), None);
    let mut offset = 0;
    for (i, photo) in capture.photos.iter().enumerate() {
        let Camera::Rectified(camera) = &photo.camera else {
            return Err(unsupported(
                format!("photo[{i}].camera.model"),
                "the camera must be rectified",
            ));
        };
        let (position, intensity) = match &photo.light {
            Light::Flash { intensity } => (camera.position, *intensity),
            Light::Point {
                position,
                intensity,
            } => (*position, *intensity),
            Light::Directional { .. } => {
                return Err(unsupported(
                    format!("photo[{i}].light.kind"),
                    "lights must be point lights or flashes",
                ))
            }
        };
        let intensity = intensity.map(|v| v * photo.exposure);
        if power.is_some_and(|p: [f64; 3]| p != intensity) {
            return Err(unsupported(
                format!("photo[{i}].light.intensity"),
                "all photos must share one light power",
            ));
        }
        power = Some(intensity);
        let _ = writeln!(
            cameras,
            "{},{},{}",
            camera.position.x, camera.position.y, camera.position.z
        );
        let _ = writeln!(lights, "{},{},{}", position.x, position.y, position.z);
        let [w, h] = camera.resolution;
        let mut image = image::RgbImage::new(w as u32, h as u32);
        for (k, px) in image.pixels_mut().enumerate() {
            let v = pixels[offset + k];
            *px = image::Rgb(v.map(|c| (c.clamp(0.0, 1.0).powf(1.0 / 2.2) * 255.0).round() as u8));
        }
        offset += w * h;
        let path = folder.join(format!("{i:02}.png"));
        image.save(&path).map_err(|e| Error::io(&path, e))?;
    }
    let power =
        power.ok_or_else(|| unsupported("photo".into(), "there must be at least one photo"))?;
    let files = [
        ("camera_pos.txt", cameras),
        ("light_pos.txt", lights),
        (
            "light_power.txt",
            format!("{},{},{}\n", power[0], power[1], power[2]),
        ),
        ("image_size.txt", format!("{}\n", capture.sample.width)),
    ];
    for (name, text) in files {
        let path = folder.join(name);
        std::fs::write(&path, text).map_err(|e| Error::io(&path, e))?;
    }
    Ok(())
}

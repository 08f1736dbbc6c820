//! A relit sequence on disk: per frame `<name>.exr` (linear radiance) and `<name>.png`
//! (exposure-scaled, sRGB-encoded), and `preview.gif`, every frame of the sequence looping;
//! under an environment also [`ENVIRONMENT`], the map as lit frame 0, for other renderers.
//! Every file is written atomically ([`write_atomically`]).

use super::Frame;
use crate::capture::atomic_file::write_atomically;
use crate::capture::image_io::{tonemap_srgb8, write_exr, write_png_tonemapped};
use crate::error::{Error, Result};
use std::path::Path;

/// The animated preview's file name.
pub const PREVIEW: &str = "preview.gif";

/// The environment map of frame 0 ([`super::environment::Environment::write`]).
pub const ENVIRONMENT: &str = "environment.exr";

/// Time each frame of the preview is shown.
const FRAME_MILLISECONDS: u32 = 80;

/// Writes `frames` into `folder` (which must exist); PNGs and the preview multiply radiance by
/// `exposure` before encoding.
pub fn write_frames(folder: &Path, frames: &[Frame], exposure: f64) -> Result<()> {
    let linear: Vec<Vec<[f32; 3]>> = frames
        .iter()
        .map(|frame| frame.rgb.iter().map(|v| v.map(|c| c as f32)).collect())
        .collect();
    for (frame, rgb) in frames.iter().zip(&linear) {
        let [width, height] = frame.resolution;
        write_exr(
            &folder.join(format!("{}.exr", frame.name)),
            rgb,
            width,
            height,
        )?;
        let png = folder.join(format!("{}.png", frame.name));
        write_png_tonemapped(&png, rgb, width, height, exposure)?;
    }
    write_gif(&folder.join(PREVIEW), frames, &linear, exposure)
}

/// The looping GIF of `frames` (their linear values `linear`), each shown
/// [`FRAME_MILLISECONDS`].
fn write_gif(path: &Path, frames: &[Frame], linear: &[Vec<[f32; 3]>], exposure: f64) -> Result<()> {
    use image::codecs::gif::{GifEncoder, Repeat};
    use image::{Delay, RgbaImage};
    let encoding = |e: image::ImageError| Error::io(path, e);
    let images = frames.iter().zip(linear).map(|(frame, rgb)| {
        let [width, height] = frame.resolution.map(|n| n as u32);
        let rgba: Vec<u8> = tonemap_srgb8(rgb, exposure)
            .chunks_exact(3)
            .flat_map(|p| [p[0], p[1], p[2], u8::MAX])
            .collect();
        let image = RgbaImage::from_raw(width, height, rgba).expect("one RGBA value per pixel");
        image::Frame::from_parts(
            image,
            0,
            0,
            Delay::from_numer_denom_ms(FRAME_MILLISECONDS, 1),
        )
    });
    write_atomically(path, |file| {
        // Speed 10 of 30: NeuQuant on a sample of the pixels, which keeps a 512^2 sequence to
        // about a second per frame.
        let mut encoder = GifEncoder::new_with_speed(file, 10);
        encoder.set_repeat(Repeat::Infinite).map_err(encoding)?;
        encoder.encode_frames(images).map_err(encoding)
    })
}

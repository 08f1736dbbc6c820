//! Images in and out, with explicit colour decoding.
//!
//! PHYSICS.md "Conventions": photos in PNG/JPEG are sRGB-encoded unless stated otherwise, EXR is
//! linear; the fit works on linear radiance. ENGINEERING-NOTES.md "Images": the `image` crate's
//! `to_rgb32f` does not linearise, so the transfer function is applied here, and some capture
//! tools (MaterialGAN) store a pure 2.2 gamma, hence [`ColorEncoding::Gamma`].

use std::fmt;
use std::path::Path;
use std::str::FromStr;

use image::ImageEncoder;

use super::atomic_file::write_atomically;
use crate::error::{Error, Result};

/// How the stored pixel values of an image relate to linear radiance.
///
/// In a manifest it is the string `"srgb"`, `"linear"` or `"gamma:G"` (e.g. `"gamma:2.2"`,
/// meaning `linear = stored^G`). The default depends on the file type
/// ([`ColorEncoding::default_for`]): EXR is linear, PNG/JPEG are sRGB.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(try_from = "String", into = "String")]
pub enum ColorEncoding {
    /// The piecewise sRGB curve (IEC 61966-2-1).
    Srgb,
    /// A pure power law with this exponent (finite, > 0): `linear = stored^gamma`.
    Gamma(f64),
    /// Stored values are linear radiance.
    Linear,
}

impl ColorEncoding {
    /// The encoding assumed when neither the photo nor the manifest names one: EXR files are
    /// linear, every other image (PNG, JPEG) is sRGB (PHYSICS.md "Conventions").
    pub fn default_for(image: &Path) -> ColorEncoding {
        match ImageKind::of(image) {
            Some(ImageKind::Exr) => ColorEncoding::Linear,
            _ => ColorEncoding::Srgb,
        }
    }

    /// Stored value -> linear value.
    pub fn decode(self, stored: f64) -> f64 {
        match self {
            ColorEncoding::Srgb => srgb_to_linear(stored),
            ColorEncoding::Gamma(gamma) => gamma_to_linear(stored, gamma),
            ColorEncoding::Linear => stored,
        }
    }

    /// Linear value -> stored value (inverse of [`ColorEncoding::decode`]).
    pub fn encode(self, linear: f64) -> f64 {
        match self {
            ColorEncoding::Srgb => linear_to_srgb(linear),
            ColorEncoding::Gamma(gamma) => linear_to_gamma(linear, gamma),
            ColorEncoding::Linear => linear,
        }
    }
}

impl fmt::Display for ColorEncoding {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ColorEncoding::Srgb => f.write_str("srgb"),
            ColorEncoding::Gamma(gamma) => write!(f, "gamma:{gamma}"),
            ColorEncoding::Linear => f.write_str("linear"),
        }
    }
}

impl FromStr for ColorEncoding {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, String> {
        match text {
            "srgb" => Ok(ColorEncoding::Srgb),
            "linear" => Ok(ColorEncoding::Linear),
            _ => {
                let gamma = text
                    .strip_prefix("gamma:")
                    .and_then(|g| g.parse::<f64>().ok())
                    .ok_or_else(|| {
                        format!("`{text}` is not a colour encoding; expected \"srgb\", \"linear\" or \"gamma:G\" (e.g. \"gamma:2.2\")")
                    })?;
                if gamma.is_finite() && gamma > 0.0 {
                    Ok(ColorEncoding::Gamma(gamma))
                } else {
                    Err(format!("gamma must be finite and positive, got {gamma}"))
                }
            }
        }
    }
}

impl TryFrom<String> for ColorEncoding {
    type Error = String;

    fn try_from(text: String) -> Result<Self, String> {
        text.parse()
    }
}

impl From<ColorEncoding> for String {
    fn from(encoding: ColorEncoding) -> String {
        encoding.to_string()
    }
}

/// sRGB-encoded value -> linear (piecewise curve: linear segment below 0.04045).
pub fn srgb_to_linear(v: f64) -> f64 {
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

/// Linear value -> sRGB-encoded (inverse of [`srgb_to_linear`]).
pub fn linear_to_srgb(v: f64) -> f64 {
    if v <= 0.0031308 {
        v * 12.92
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

/// Gamma-encoded value -> linear: `v^gamma`, mirrored for negative values (which only
/// floating-point images can hold).
pub fn gamma_to_linear(v: f64, gamma: f64) -> f64 {
    v.signum() * v.abs().powf(gamma)
}

/// Linear value -> gamma-encoded: `v^(1/gamma)`, mirrored for negative values.
pub fn linear_to_gamma(v: f64, gamma: f64) -> f64 {
    v.signum() * v.abs().powf(1.0 / gamma)
}

/// A decoded image: linear RGB, row-major, row 0 at the top.
#[derive(Clone, Debug, PartialEq)]
pub struct LinearImage {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Linear RGB per pixel, index `row * width + column`.
    pub rgb: Vec<[f32; 3]>,
    /// Per pixel: some channel is at the integer format's maximum (255 or 65535), so the true
    /// value is unknown. Always false for EXR.
    pub saturated: Vec<bool>,
}

/// File types the loader understands, decided by the file extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum ImageKind {
    Exr,
    /// PNG or JPEG, decoded by the `image` crate.
    Integer,
}

impl ImageKind {
    fn of(path: &Path) -> Option<ImageKind> {
        let extension = path.extension()?.to_str()?.to_ascii_lowercase();
        match extension.as_str() {
            "exr" => Some(ImageKind::Exr),
            "png" | "jpg" | "jpeg" => Some(ImageKind::Integer),
            _ => None,
        }
    }

    fn of_supported(path: &Path) -> Result<ImageKind> {
        ImageKind::of(path).ok_or_else(|| {
            Error::invalid(
                path,
                "file type",
                "unsupported image extension; expected .exr, .png, .jpg or .jpeg",
            )
        })
    }
}

/// Loads an image and decodes it to linear RGB with `encoding`.
///
/// EXR: the R, G, B channels of the first layer (alpha and other channels ignored).
/// PNG/JPEG: 8 or 16 bit, greyscale expanded to RGB, alpha ignored; a pixel is saturated when
/// any channel holds the format maximum.
/// Errors name the file and say what was expected (a missing file, a folder, a truncated or
/// mislabelled file).
pub fn load_image(path: &Path, encoding: ColorEncoding) -> Result<LinearImage> {
    let kind = ImageKind::of_supported(path)?;
    let metadata = std::fs::metadata(path)
        .map_err(|e| Error::io(path, format!("{e}; expected an image file here")))?;
    if metadata.is_dir() {
        return Err(Error::invalid(
            path,
            "file type",
            "is a folder; expected an image file",
        ));
    }
    match kind {
        ImageKind::Exr => load_exr(path, encoding, metadata.len()),
        ImageKind::Integer => load_integer_image(path, encoding),
    }
}

/// Most pixels an EXR file of one byte may claim: deflate (ZIP), the best-compressing of
/// OpenEXR's codecs on constant data, shrinks at most 1032:1, and every pixel holds at least
/// one 2-byte sample, so a real file has at most 1032 / 2 pixels per byte; twice that is
/// allowed.
const EXR_PIXELS_PER_FILE_BYTE: usize = 1032;

/// Refuses an EXR whose header claims more pixels than its size can hold (a damaged or
/// hostile header would otherwise make the decoder allocate its claimed size and abort).
fn check_exr_size(path: &Path, file_bytes: u64) -> Result<()> {
    let invalid = |message: String| Error::invalid(path, "EXR data", message);
    let meta = exr::meta::MetaData::read_from_file(path, false)
        .map_err(|e| invalid(format!("{e}; expected an OpenEXR file")))?;
    let limit = usize::try_from(file_bytes)
        .unwrap_or(usize::MAX)
        .saturating_mul(EXR_PIXELS_PER_FILE_BYTE);
    for header in &meta.headers {
        let (width, height) = (header.layer_size.0, header.layer_size.1);
        if width
            .checked_mul(height)
            .is_none_or(|pixels| pixels > limit)
        {
            return Err(invalid(format!(
                "the header claims {width}x{height} pixels, more than a {file_bytes}-byte \
                 file can hold; expected an undamaged OpenEXR file"
            )));
        }
    }
    Ok(())
}

fn load_exr(path: &Path, encoding: ColorEncoding, file_bytes: u64) -> Result<LinearImage> {
    use exr::prelude::{ReadChannels, ReadLayers};
    check_exr_size(path, file_bytes)?;
    let image = exr::prelude::read()
        .no_deep_data()
        .largest_resolution_level()
        .rgb_channels(
            |resolution, _| LinearImage {
                width: resolution.width(),
                height: resolution.height(),
                rgb: vec![[0.0; 3]; resolution.area()],
                saturated: vec![false; resolution.area()],
            },
            |image: &mut LinearImage, position, (r, g, b): (f32, f32, f32)| {
                image.rgb[position.y() * image.width + position.x()] = [r, g, b];
            },
        )
        .first_valid_layer()
        .all_attributes()
        .from_file(path)
        .map_err(|e| match e {
            exr::error::Error::Io(io) => Error::io(path, io),
            other => Error::invalid(
                path,
                "EXR data",
                format!("{other}; expected a complete OpenEXR file with R, G, B channels"),
            ),
        })?;
    let mut decoded = image.layer_data.channel_data.pixels;
    if encoding != ColorEncoding::Linear {
        for value in decoded.rgb.iter_mut().flatten() {
            *value = encoding.decode(f64::from(*value)) as f32;
        }
    }
    Ok(decoded)
}

fn load_integer_image(path: &Path, encoding: ColorEncoding) -> Result<LinearImage> {
    use image::ColorType;
    let decoded = image::ImageReader::open(path)
        .and_then(|reader| reader.with_guessed_format())
        .map_err(|e| Error::io(path, e))?
        .decode()
        .map_err(|e| {
            Error::invalid(
                path,
                "image data",
                format!("{e}; expected a complete PNG or JPEG file"),
            )
        })?;
    let (width, height) = (decoded.width() as usize, decoded.height() as usize);
    let (rgb, saturated) = match decoded.color() {
        ColorType::L16 | ColorType::La16 | ColorType::Rgb16 | ColorType::Rgba16 => {
            decode_integer_samples(decoded.into_rgb16().as_raw(), encoding)
        }
        _ => decode_integer_samples(decoded.into_rgb8().as_raw(), encoding),
    };
    Ok(LinearImage {
        width,
        height,
        rgb,
        saturated,
    })
}

/// Integer sample types of PNG/JPEG (u8, u16) with their maximum.
trait IntegerSample: Copy + Into<u32> {
    const MAX: u32;
}
impl IntegerSample for u8 {
    const MAX: u32 = u8::MAX as u32;
}
impl IntegerSample for u16 {
    const MAX: u32 = u16::MAX as u32;
}

/// Interleaved RGB integer samples -> linear RGB (through a lookup table of every code value)
/// and per-pixel saturation.
fn decode_integer_samples<T: IntegerSample>(
    samples: &[T],
    encoding: ColorEncoding,
) -> (Vec<[f32; 3]>, Vec<bool>) {
    let table: Vec<f32> = (0..=T::MAX)
        .map(|code| encoding.decode(f64::from(code) / f64::from(T::MAX)) as f32)
        .collect();
    samples
        .chunks_exact(3)
        .map(|pixel| {
            let codes = [pixel[0].into(), pixel[1].into(), pixel[2].into()];
            (codes.map(|c| table[c as usize]), codes.contains(&T::MAX))
        })
        .unzip()
}

/// Loads a mask image and returns, per pixel, whether it is nonzero (any channel). For a
/// keep-mask this is "true = keep, zero = ignore"; for a saturation mask "true = saturated".
/// The mask must have the photo's resolution `width` x `height`.
pub fn load_mask(path: &Path, width: usize, height: usize) -> Result<Vec<bool>> {
    let mask = load_image(path, ColorEncoding::Linear)?;
    if (mask.width, mask.height) != (width, height) {
        return Err(Error::invalid(
            path,
            "resolution",
            format!(
                "the mask is {}x{} but its photo is {width}x{height}",
                mask.width, mask.height
            ),
        ));
    }
    Ok(mask
        .rgb
        .iter()
        .map(|p| p.iter().any(|&v| v != 0.0))
        .collect())
}

/// Checks that `rgb` holds exactly `width * height` pixels and the image is not empty.
fn check_pixel_count(path: &Path, rgb: &[[f32; 3]], width: usize, height: usize) -> Result<()> {
    if width == 0 || height == 0 || rgb.len() != width * height {
        return Err(Error::invalid(
            path,
            "pixels",
            format!("{} pixels given for a {width}x{height} image", rgb.len()),
        ));
    }
    Ok(())
}

/// Writes linear f32 RGB (row-major, row 0 at the top) as an EXR file, atomically.
pub fn write_exr(path: &Path, rgb: &[[f32; 3]], width: usize, height: usize) -> Result<()> {
    use exr::prelude::{Image, SpecificChannels, Vec2, WritableImage};
    check_pixel_count(path, rgb, width, height)?;
    let channels = SpecificChannels::rgb(|Vec2(x, y)| {
        let [r, g, b] = rgb[y * width + x];
        (r, g, b)
    });
    let image = Image::from_channels((width, height), channels);
    write_atomically(path, |file| {
        image
            .write()
            .to_buffered(file)
            .map_err(|e| Error::io(path, e))
    })
}

/// Writes a viewable 8-bit sRGB PNG of linear RGB ([`tonemap_srgb8`]), atomically.
pub fn write_png_tonemapped(
    path: &Path,
    rgb: &[[f32; 3]],
    width: usize,
    height: usize,
    exposure: f64,
) -> Result<()> {
    check_pixel_count(path, rgb, width, height)?;
    let too_large = || {
        Error::invalid(
            path,
            "pixels",
            format!("{width}x{height} is too large for PNG"),
        )
    };
    let (png_width, png_height) = (
        u32::try_from(width).map_err(|_| too_large())?,
        u32::try_from(height).map_err(|_| too_large())?,
    );
    write_png_rgb8(path, &tonemap_srgb8(rgb, exposure), png_width, png_height)
}

/// Exposure that maps the 99.5th percentile of all channel values to 1 (so highlights clip
/// only slightly and the PNGs of one set share one exposure).
///
/// The percentile is exact but found without a copy of the values (at 1024^2 a photo set's are
/// a few hundred megabytes): the positive values are counted by the top `BUCKET_BITS` bits of
/// their IEEE 754 representation, which orders positive numbers as their values do, and only
/// the values of the bucket that holds the percentile are selected among.
pub fn display_exposure(values: &[[f64; 3]]) -> f64 {
    const BUCKET_BITS: u32 = 20;
    let positive = || {
        values
            .iter()
            .flatten()
            .copied()
            .filter(|v| v.is_finite() && *v > 0.0)
    };
    let bucket = |v: f64| (v.to_bits() >> (64 - BUCKET_BITS)) as usize;
    let mut counts = vec![0usize; 1 << BUCKET_BITS];
    for v in positive() {
        counts[bucket(v)] += 1;
    }
    let n: usize = counts.iter().sum();
    if n == 0 {
        return 1.0;
    }
    let k = ((n as f64 * 0.995) as usize).min(n - 1);
    let (mut below, mut b) = (0, 0);
    while below + counts[b] <= k {
        below += counts[b];
        b += 1;
    }
    let mut inside: Vec<f64> = positive().filter(|&v| bucket(v) == b).collect();
    let (_, p, _) = inside.select_nth_unstable_by(k - below, |a, b| a.total_cmp(b));
    1.0 / *p
}

/// Linear RGB as displayable 8-bit sRGB bytes (interleaved RGB): each value is multiplied by
/// `exposure`, clamped to [0, 1] (NaN counts as 0) and sRGB-encoded.
pub fn tonemap_srgb8(rgb: &[[f32; 3]], exposure: f64) -> Vec<u8> {
    rgb.iter()
        .flatten()
        .map(|&v| {
            let scaled = f64::from(v) * exposure;
            let clamped = if scaled.is_nan() {
                0.0
            } else {
                scaled.clamp(0.0, 1.0)
            };
            (linear_to_srgb(clamped) * 255.0).round() as u8
        })
        .collect()
}

/// Writes 8-bit RGB bytes (row-major, row 0 at the top, already display-encoded) as a PNG,
/// atomically.
pub fn write_png_rgb8(path: &Path, bytes: &[u8], width: u32, height: u32) -> Result<()> {
    write_atomically(path, |file| {
        image::codecs::png::PngEncoder::new(file)
            .write_image(bytes, width, height, image::ExtendedColorType::Rgb8)
            .map_err(|e| Error::io(path, e))
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::strategy::Strategy;

    /// The 99.5th percentile by sorting a copy, as [`display_exposure`] defines it.
    fn sorted_exposure(values: &[[f64; 3]]) -> f64 {
        let mut all: Vec<f64> = values
            .iter()
            .flatten()
            .copied()
            .filter(|v| v.is_finite() && *v > 0.0)
            .collect();
        if all.is_empty() {
            return 1.0;
        }
        all.sort_by(f64::total_cmp);
        1.0 / all[((all.len() as f64 * 0.995) as usize).min(all.len() - 1)]
    }

    proptest::proptest! {
        /// Values spread over many octaves, with repeats, zeros, negatives and non-finite
        /// values mixed in: the bucketed selection finds the sorted copy's percentile exactly.
        #[test]
        fn display_exposure_is_the_sorted_percentile(
            values in proptest::collection::vec(
                proptest::prop_oneof![
                    8 => (-30.0f64..10.0).prop_map(f64::exp2),
                    1 => proptest::strategy::Just(0.0),
                    1 => proptest::strategy::Just(-1.0),
                    1 => proptest::strategy::Just(f64::NAN),
                    1 => proptest::strategy::Just(f64::INFINITY),
                    2 => proptest::strategy::Just(0.25),
                ],
                0..600,
            )
        ) {
            let pixels: Vec<[f64; 3]> = values.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
            proptest::prop_assert_eq!(display_exposure(&pixels), sorted_exposure(&pixels));
        }
    }

    #[test]
    fn srgb_half_is_0_2140_linear_and_round_trips() {
        assert!(
            (srgb_to_linear(0.5) - 0.21404).abs() < 1e-5,
            "{}",
            srgb_to_linear(0.5)
        );
        assert!((linear_to_srgb(0.21404114) - 0.5).abs() < 1e-7);
        // Both segments and the breakpoints, and the end points exactly.
        assert_eq!(srgb_to_linear(0.0), 0.0);
        assert!((srgb_to_linear(1.0) - 1.0).abs() < 1e-15);
        assert!((srgb_to_linear(0.02) - 0.02 / 12.92).abs() < 1e-15);
        for i in 0..=1000 {
            let v = f64::from(i) / 1000.0;
            assert!((linear_to_srgb(srgb_to_linear(v)) - v).abs() < 1e-12, "{v}");
            assert!((srgb_to_linear(linear_to_srgb(v)) - v).abs() < 1e-12, "{v}");
        }
        // The curve is continuous at its breakpoint up to the standard's own 2e-9 step (a
        // wrong constant shows up here).
        let below = srgb_to_linear(0.04045);
        let above = srgb_to_linear(0.04045 + 1e-12);
        assert!((below - above).abs() < 1e-8, "{below} {above}");
    }

    #[test]
    fn gamma_matches_the_power_law_and_round_trips() {
        assert!((gamma_to_linear(0.5, 2.2) - 0.5f64.powf(2.2)).abs() < 1e-15);
        assert!((gamma_to_linear(0.5, 2.2) - 0.217638).abs() < 1e-6);
        assert!((linear_to_gamma(0.5f64.powf(2.2), 2.2) - 0.5).abs() < 1e-15);
        for i in -100..=100 {
            let v = f64::from(i) / 50.0;
            assert!(
                (linear_to_gamma(gamma_to_linear(v, 2.2), 2.2) - v).abs() < 1e-12,
                "{v}"
            );
        }
        let e = ColorEncoding::Gamma(1.8);
        assert!((e.decode(e.encode(0.3)) - 0.3).abs() < 1e-15);
        assert_eq!(ColorEncoding::Linear.decode(0.3), 0.3);
    }

    #[test]
    fn encoding_names_parse_print_and_default_by_file_type() {
        for (text, encoding) in [
            ("srgb", ColorEncoding::Srgb),
            ("linear", ColorEncoding::Linear),
            ("gamma:2.2", ColorEncoding::Gamma(2.2)),
        ] {
            assert_eq!(text.parse::<ColorEncoding>().unwrap(), encoding);
            assert_eq!(encoding.to_string(), text);
        }
        for bad in [
            "sRGB",
            "gamma:",
            "gamma:-1",
            "gamma:0",
            "gamma:inf",
            "gamma:x",
            "",
        ] {
            assert!(bad.parse::<ColorEncoding>().is_err(), "{bad}");
        }
        #[derive(serde::Serialize, serde::Deserialize)]
        struct Holder {
            color: ColorEncoding,
        }
        let h: Holder = toml::from_str("color = \"gamma:2.4\"").unwrap();
        assert_eq!(h.color, ColorEncoding::Gamma(2.4));
        assert_eq!(toml::to_string(&h).unwrap().trim(), "color = \"gamma:2.4\"");
        assert_eq!(
            ColorEncoding::default_for(Path::new("a/b.EXR")),
            ColorEncoding::Linear
        );
        assert_eq!(
            ColorEncoding::default_for(Path::new("a/b.png")),
            ColorEncoding::Srgb
        );
        assert_eq!(
            ColorEncoding::default_for(Path::new("a/b.jpg")),
            ColorEncoding::Srgb
        );
    }

    #[test]
    fn exr_write_read_round_trip_is_bit_exact() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("x.exr");
        let (w, h) = (5, 3);
        let special = [
            1.0e-40_f32,
            3.4e38,
            -2.5,
            0.1,
            1.0 / 3.0,
            0.0,
            65504.5,
            1e-7,
        ];
        let rgb: Vec<[f32; 3]> = (0..w * h)
            .map(|i| {
                let f = |k: usize| special[(3 * i + k) % special.len()] * (1.0 + i as f32 / 7.0);
                [f(0), f(1), f(2)]
            })
            .collect();
        write_exr(&path, &rgb, w, h).unwrap();
        let back = load_image(&path, ColorEncoding::default_for(&path)).unwrap();
        assert_eq!((back.width, back.height), (w, h));
        let bits = |v: &[[f32; 3]]| v.iter().flatten().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&back.rgb), bits(&rgb));
        assert!(back.saturated.iter().all(|&s| !s));
    }

    #[test]
    fn exr_with_a_non_linear_encoding_is_decoded() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("x.exr");
        write_exr(&path, &[[0.5, 0.25, 1.0]], 1, 1).unwrap();
        let back = load_image(&path, ColorEncoding::Gamma(2.0)).unwrap();
        assert_eq!(back.rgb[0], [0.25, 0.0625, 1.0]);
    }

    #[test]
    fn eight_bit_png_is_saturated_when_any_channel_is_255() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("x.png");
        // Pixels: red at 255, green at 255, blue at 255, every channel at 254.
        let raw: Vec<u8> = vec![255, 3, 4, 5, 255, 6, 7, 8, 255, 254, 254, 254];
        image::RgbImage::from_raw(4, 1, raw)
            .unwrap()
            .save(&path)
            .unwrap();
        let img = load_image(&path, ColorEncoding::Gamma(2.2)).unwrap();
        assert_eq!(img.saturated, vec![true, true, true, false]);
        let expected = (254.0f64 / 255.0).powf(2.2) as f32;
        assert_eq!(img.rgb[3], [expected; 3]);
    }

    #[test]
    fn sixteen_bit_png_decodes_and_flags_saturation() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("x.png");
        // Pixels: all max, one channel max, one below max, mid grey.
        let raw: Vec<u16> = vec![
            65535, 65535, 65535, 10, 65535, 20, 65534, 65534, 65534, 32768, 0, 1,
        ];
        image::ImageBuffer::<image::Rgb<u16>, _>::from_raw(2, 2, raw)
            .unwrap()
            .save(&path)
            .unwrap();
        let img = load_image(&path, ColorEncoding::Srgb).unwrap();
        assert_eq!(img.saturated, vec![true, true, false, false]);
        let expected = srgb_to_linear(32768.0 / 65535.0) as f32;
        assert_eq!(img.rgb[3][0], expected);
        assert_eq!(img.rgb[3][1], 0.0);
        assert!(img.rgb[2][0] < 1.0 && img.rgb[2][0] > 0.9999);
        // 16-bit precision is kept: 65534 must not collapse onto 255/255.
        assert_ne!(img.rgb[2][0], 1.0);
    }

    #[test]
    fn eight_bit_grey_png_is_expanded_and_gamma_decoded() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("g.png");
        image::GrayImage::from_raw(3, 1, vec![0, 128, 255])
            .unwrap()
            .save(&path)
            .unwrap();
        let img = load_image(&path, ColorEncoding::Gamma(2.2)).unwrap();
        let mid = (128.0f64 / 255.0).powf(2.2) as f32;
        assert_eq!(img.rgb, vec![[0.0; 3], [mid; 3], [1.0; 3]]);
        assert_eq!(img.saturated, vec![false, false, true]);
    }

    #[test]
    fn an_exr_header_claiming_more_pixels_than_the_file_holds_is_refused() {
        // Found by tests/fuzz_parsers.rs: one flipped byte in the data window made the
        // decoder allocate 174 GB and abort.
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("huge.exr");
        write_exr(&path, &[[0.5; 3]; 12], 4, 3).unwrap();
        let mut bytes = std::fs::read(&path).unwrap();
        let name = b"dataWindow\0box2i\0";
        let at = bytes.windows(name.len()).position(|w| w == name).unwrap() + name.len();
        // After the attribute's size (4 bytes): x_min, y_min, x_max, y_max as i32.
        bytes[at + 16..at + 20].copy_from_slice(&100_000_000i32.to_le_bytes());
        std::fs::write(&path, &bytes).unwrap();
        let err = load_image(&path, ColorEncoding::Linear)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("huge.exr") && err.contains("4x100000001"),
            "{err}"
        );
    }

    #[test]
    fn unreadable_images_name_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let missing = dir.path().join("missing.png");
        assert!(load_image(&missing, ColorEncoding::Srgb)
            .unwrap_err()
            .to_string()
            .contains("missing.png"));
        let garbage = dir.path().join("garbage.png");
        std::fs::write(&garbage, b"not a png").unwrap();
        let err = load_image(&garbage, ColorEncoding::Srgb)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("garbage.png") && err.contains("image data"),
            "{err}"
        );
        let tiff = dir.path().join("x.tiff");
        let err = load_image(&tiff, ColorEncoding::Srgb)
            .unwrap_err()
            .to_string();
        assert!(err.contains("x.tiff") && err.contains("file type"), "{err}");
    }

    #[test]
    fn mask_keeps_nonzero_pixels_and_checks_resolution() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("m.png");
        image::GrayImage::from_raw(2, 2, vec![0, 1, 255, 0])
            .unwrap()
            .save(&path)
            .unwrap();
        assert_eq!(
            load_mask(&path, 2, 2).unwrap(),
            vec![false, true, true, false]
        );
        let err = load_mask(&path, 3, 2).unwrap_err().to_string();
        assert!(
            err.contains("m.png") && err.contains("2x2") && err.contains("3x2"),
            "{err}"
        );
    }

    #[test]
    fn tonemapped_png_scales_clamps_and_encodes() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.png");
        let half_srgb = srgb_to_linear(0.5) as f32;
        let rgb = [
            [half_srgb / 2.0, 10.0, -1.0],
            [f32::NAN, 0.0, f32::INFINITY],
        ];
        write_png_tonemapped(&path, &rgb, 2, 1, 2.0).unwrap();
        let back = image::open(&path).unwrap().into_rgb8();
        assert_eq!(back.as_raw(), &vec![128, 255, 0, 0, 0, 255]);
        let err = write_png_tonemapped(&path, &rgb, 3, 1, 1.0)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("t.png") && err.contains("2 pixels given for a 3x1 image"),
            "{err}"
        );
    }
}

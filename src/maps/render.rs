//! Rendering a maps material over shading records: each sub-sample evaluates the material of
//! the texel it sees ([`super::TexelGrid::texel`]) in the frame of that texel's shading normal,
//! through the scalar `f64` reference kernel and the renderer's own pixel loop (so pixels are
//! the same sub-sample means, with the same random streams, as [`crate::render::render_pixels`]).

use super::lobe::TexelLobe;
use super::{AnyMaterial, MaterialMaps};
use crate::capture::Capture;
use crate::error::{Error, Result};
use crate::fit::point::exposure::exposed_records;
use crate::render::{accumulate, render_pixels};
use crate::scalar::{Rgb, Vec3};
use crate::shading::ShadingRecords;
use rayon::prelude::*;
use std::path::Path;

/// Predicted radiance of `pixels` for `maps`. Needs records built from a capture (with texture
/// coordinates).
pub fn render_maps(
    maps: &MaterialMaps,
    records: &ShadingRecords,
    pixels: &[usize],
    seed: u64,
) -> Result<Vec<[f64; 3]>> {
    if records.uv.len() != records.wi.len() {
        return Err(Error::argument(
            "material",
            "a maps material renders only photo sets (records with texture coordinates)",
        ));
    }
    let texel_of = |s: usize| maps.grid.texel(records.uv[s]);
    let spp = records.samples_per_pixel;
    let lit = |p: usize| (p * spp..(p + 1) * spp).filter(|&s| records.irradiance[s] != [0.0; 3]);
    // The pixels (positions in `pixels`) of each band of texels, by their first lit sub-sample,
    // across all photos, sorted by band (a counting sort into one array): each band's lobes
    // are built once.
    let band_of: Vec<u32> = (pixels.par_iter())
        .map(|&p| {
            lit(p)
                .next()
                .map_or(0, |s| (texel_of(s) / LOBE_BAND_TEXELS) as u32)
        })
        .collect();
    let mut offsets = vec![0usize; maps.grid.len().div_ceil(LOBE_BAND_TEXELS) + 1];
    for &b in &band_of {
        offsets[b as usize + 1] += 1;
    }
    for b in 1..offsets.len() {
        offsets[b] += offsets[b - 1];
    }
    let mut by_band = vec![0u32; pixels.len()];
    let mut next = offsets.clone();
    for (k, &b) in band_of.iter().enumerate() {
        by_band[next[b as usize]] = k as u32;
        next[b as usize] += 1;
    }
    drop(band_of);
    let mut out = vec![[0.0; 3]; pixels.len()];
    for band in offsets.windows(2).map(|w| &by_band[w[0]..w[1]]) {
        if band.is_empty() {
            continue;
        }
        let band_pixels: Vec<usize> = band.iter().map(|&k| pixels[k as usize]).collect();
        // A pixel's other sub-samples may see texels just past the band.
        let (first, last) = (band_pixels.iter().flat_map(|&p| lit(p)).map(texel_of))
            .fold((usize::MAX, 0), |(a, b), t| (a.min(t), b.max(t)));
        let lobes = TexelLobe::of_texels(maps, first.min(last)..last + 1);
        // Each pixel draws from its own stream, so the bands leave the values as they were.
        let values = accumulate(records, &band_pixels, [0.0; 3], seed, |_, s, rng| {
            let lobe = &lobes[texel_of(s) - first];
            let (wi, wo) = (Vec3::from_f64(records.wi[s]), Vec3::from_f64(records.wo[s]));
            // The records' irradiance holds the geometric cosine wi.z: replaced by the shading
            // frame's (a ratio of exactly 1 without a normal map).
            let Some((i, o)) = lobe.local(wi, wo) else {
                return Rgb([0.0; 3]);
            };
            let cosine_ratio = i.z / wi.z;
            Rgb(lobe.value(i, o, rng).map(|v| v * cosine_ratio))
        });
        for (&k, value) in band.iter().zip(values) {
            out[k as usize] = value;
        }
    }
    Ok(out)
}

/// Texels whose lobes [`render_maps`] holds at a time: it renders the pixels that see each band
/// of this many texels (in row-major order) with that band's lobes, built once. A `tabulated`
/// texel's lobe is about 2 kB, so the lobes of every texel of a 1024^2 grid took 2 GB at once,
/// more than the fit itself.
const LOBE_BAND_TEXELS: usize = 1 << 16;

/// Predicted radiance of every pixel of every photo for a uniform or maps material.
pub fn render_any(
    material: &AnyMaterial,
    records: &ShadingRecords,
    seed: u64,
) -> Result<Vec<[f64; 3]>> {
    let all: Vec<usize> = (0..records.pixel_count()).collect();
    match material {
        AnyMaterial::Uniform(material) => Ok(render_pixels(material, records, &all, seed)),
        AnyMaterial::Maps(maps) => render_maps(maps, records, &all, seed),
    }
}

/// Refuses maps (read from `path`) whose texels are not square on the capture's sample.
pub fn check_fits_capture(material: &AnyMaterial, path: &Path, capture: &Capture) -> Result<()> {
    match material {
        AnyMaterial::Maps(maps) => maps.check_sample(path, &capture.sample),
        AnyMaterial::Uniform(_) => Ok(()),
    }
}

/// The records `render` renders `material` (read from `path`: a fit file's fitted `exposure`
/// applied) over for every photo of `capture`, with `pixel_samples` sub-samples per pixel.
pub fn render_records(
    material: &AnyMaterial,
    path: &Path,
    capture: &Capture,
    pixel_samples: usize,
) -> Result<ShadingRecords> {
    check_fits_capture(material, path, capture)?;
    let records = ShadingRecords::build(capture, pixel_samples, false)?;
    Ok(exposed_records(&records, fitted_exposure(path)).into_owned())
}

/// The `exposure` a fit file at `path` fitted, 1 for a material file or without one.
fn fitted_exposure(path: &Path) -> f64 {
    std::fs::read_to_string(path)
        .ok()
        .and_then(|text| serde_json::from_str::<serde_json::Value>(&text).ok())
        .and_then(|value| value.get("exposure")?.get("value")?.as_f64())
        .filter(|s| s.is_finite() && *s > 0.0)
        .unwrap_or(1.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::capture::{Camera, Capture, ColorEncoding, Light, Photo, Rectified, Sample};
    use crate::maps::TexelGrid;
    use crate::material::{FresnelSpec, Material};
    use glam::DVec3;
    use std::path::{Path, PathBuf};

    fn flash_capture(side: usize) -> Capture {
        let photos = [(0.0, 0.0), (2.0, 1.0), (-1.5, -2.0)]
            .iter()
            .map(|&(x, y)| Photo {
                image: PathBuf::from("a.exr"),
                camera: Camera::Rectified(Rectified {
                    position: DVec3::new(x, y, 12.0),
                    resolution: [side, side],
                }),
                light: Light::Flash {
                    intensity: [100.0; 3],
                },
                exposure: 1.0,
                weight: 1.0,
                mask: None,
                saturated_mask: None,
                color: ColorEncoding::Linear,
                pixels: None,
            })
            .collect();
        Capture {
            name: "maps".into(),
            units: "cm".into(),
            root: Path::new(".").to_path_buf(),
            sample: Sample {
                width: 8.0,
                height: 8.0,
            },
            color: None,
            depth: 0.0,
            photos,
            warnings: Vec::new(),
        }
    }

    fn material(alpha: f64, f0: f64, diffuse: f64) -> Material {
        Material {
            model: crate::bsdf::Model::KullaConty,
            ndf: Default::default(),
            height: Default::default(),
            alpha: [alpha; 2],
            fresnel: FresnelSpec::Schlick { f0: [f0; 3] },
            diffuse: [diffuse; 3],
        }
    }

    #[test]
    fn one_texel_maps_render_as_the_uniform_material() {
        let records = ShadingRecords::build(&flash_capture(16), 4, false).unwrap();
        let uniform = material(0.4, 0.8, 0.2);
        let all: Vec<usize> = (0..records.pixel_count()).collect();
        let want = render_pixels(&uniform, &records, &all, 3);
        let got = render_maps(&MaterialMaps::uniform(&uniform), &records, &all, 3).unwrap();
        assert_eq!(got, want, "bit for bit: same kernel, same pixel loop");
    }

    #[test]
    fn each_half_of_a_two_texel_map_renders_as_its_own_material() {
        // The right half is anisotropic: its texel's alpha_x and alpha_y reach the kernel as
        // the uniform material's do.
        let records = ShadingRecords::build(&flash_capture(16), 1, false).unwrap();
        let left = material(0.15, 0.9, 0.0);
        let right = Material {
            alpha: [0.7, 0.2],
            ..material(0.7, 0.3, 0.5)
        };
        let maps = MaterialMaps {
            grid: TexelGrid {
                width: 2,
                height: 1,
            },
            diffuse: Some(vec![left.diffuse, right.diffuse]),
            specular: Some(vec![[0.9; 3], [0.3; 3]]),
            roughness: Some(vec![[0.15; 2], [0.7, 0.2]]),
            ..MaterialMaps::uniform(&left)
        };
        let all: Vec<usize> = (0..records.pixel_count()).collect();
        let got = render_maps(&maps, &records, &all, 0).unwrap();
        let (want_left, want_right) = (
            render_pixels(&left, &records, &all, 0),
            render_pixels(&right, &records, &all, 0),
        );
        for p in all {
            let column = p % 16;
            let want = if column < 8 {
                want_left[p]
            } else {
                want_right[p]
            };
            assert_eq!(got[p], want, "pixel {p}");
        }
    }

    #[test]
    fn a_tilted_normal_moves_the_highlight_toward_where_it_mirrors_the_flash() {
        // A flash straight above the centre: with the geometric normal the brightest pixel is
        // the centre; a normal tilted toward +x faces the flash from a point left of it.
        let mut capture = flash_capture(33);
        capture.photos.truncate(1);
        let records = ShadingRecords::build(&capture, 1, false).unwrap();
        let shiny = material(0.05, 0.9, 0.0);
        let tilted = MaterialMaps {
            normal: Some(vec![crate::maps::normal_from_slopes(-0.2, 0.0).re()]),
            ..MaterialMaps::uniform(&shiny)
        };
        let all: Vec<usize> = (0..records.pixel_count()).collect();
        let brightest = |image: &[[f64; 3]]| {
            (0..image.len())
                .max_by(|&a, &b| image[a][0].total_cmp(&image[b][0]))
                .unwrap()
        };
        let flat = brightest(&render_pixels(&shiny, &records, &all, 0));
        let moved = brightest(&render_maps(&tilted, &records, &all, 0).unwrap());
        assert_eq!((flat % 33, flat / 33), (16, 16));
        // With the normal (0.2, 0, 1)/|.| the flash is mirrored back where the direction to it
        // is that normal: x / 12 = -0.2, x = -2.4 cm, pixel (4 - 2.4) / 8 * 33 = 6.6.
        assert_eq!((moved % 33, moved / 33), (6, 16));
    }
}

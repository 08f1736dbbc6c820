//! Relit previews of a material (docs/relight.md): a uniform or maps material, on the flat
//! sample or a sphere ([`geometry`]), under an environment map ([`environment`]), a point
//! light circling it, or the lights of its photo set ([`lights`]), rendered by Monte Carlo
//! ([`shade`]) into frames that [`output`] writes as EXR, PNG and an animated GIF.
//!
//! Every pixel is the mean of `samples` samples, each at a uniformly jittered position in the
//! pixel (so silhouettes and texel edges are anti-aliased) and drawing all its random numbers
//! from the pixel's own stream ([`rng_stream`] of the seed and the pixel index); rows are
//! shaded in parallel with rayon, so a frame is the same, bit for bit, whatever the thread
//! count. Every frame uses the same streams, so the noise of a sequence stays in place from
//! frame to frame instead of flickering. Pixels whose samples all miss the sphere are
//! background, zero.

pub mod distribution;
pub mod environment;
pub mod geometry;
pub mod lights;
pub mod output;
pub mod shade;

use crate::maps::lobe::TexelLobe;
use crate::maps::MaterialMaps;
use crate::progress::Progress;
use crate::random::rng_stream;
use geometry::Geometry;
use rand::Rng as _;
use rayon::prelude::*;
use shade::Lighting;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

/// What is rendered, and how finely.
#[derive(Clone, Copy, Debug)]
pub struct Scene<'a> {
    pub material: &'a MaterialMaps,
    pub geometry: Geometry,
    /// Image width in pixels ([`Geometry::resolution`] gives the height).
    pub size: usize,
    /// Samples per pixel.
    pub samples: usize,
    pub seed: u64,
}

/// One rendered frame: linear radiance, row-major, row 0 at the top.
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    /// File stem of the frame's images.
    pub name: String,
    /// `[width, height]`.
    pub resolution: [usize; 2],
    pub rgb: Vec<[f64; 3]>,
}

/// Renders one frame per `(name, light)` of `frames`, showing progress.
pub fn render(scene: &Scene, frames: &[(String, Lighting)]) -> Vec<Frame> {
    let lobes = TexelLobe::all(scene.material);
    let resolution = scene.geometry.resolution(scene.size, scene.material.grid);
    let [width, height] = resolution;
    let progress = Mutex::new(Progress::new("relight", (frames.len() * height) as u64));
    let rows_done = AtomicUsize::new(0);
    let rendered = frames
        .iter()
        .map(|(name, lighting)| {
            let mut rgb = vec![[0.0; 3]; width * height];
            rgb.par_chunks_mut(width)
                .enumerate()
                .for_each(|(row, out)| {
                    for (column, value) in out.iter_mut().enumerate() {
                        *value = pixel(scene, &lobes, resolution, lighting, [column, row]);
                    }
                    let done = rows_done.fetch_add(1, Ordering::Relaxed) + 1;
                    if let Ok(mut progress) = progress.try_lock() {
                        progress.update(done as u64, || name.clone());
                    }
                });
            Frame {
                name: name.clone(),
                resolution,
                rgb,
            }
        })
        .collect();
    progress
        .lock()
        .expect("no panics while holding the lock")
        .finish();
    rendered
}

/// One frame of `scene` under `env` as it is (not turned), sampled by MIS.
pub fn render_under(scene: &Scene, env: &environment::Environment) -> Frame {
    let lighting = Lighting::Environment {
        env,
        turn: shade::Turn::by(0.0),
        sampling: shade::Sampling::Mis,
    };
    render(scene, &[(String::new(), lighting)]).remove(0)
}

/// The mean of the samples of the pixel at `[column, row]`.
fn pixel(
    scene: &Scene,
    lobes: &[TexelLobe],
    resolution: [usize; 2],
    lighting: &Lighting,
    [column, row]: [usize; 2],
) -> [f64; 3] {
    let mut rng = rng_stream(scene.seed, (row * resolution[0] + column) as u64);
    let mut sum = [0.0; 3];
    for _ in 0..scene.samples {
        let at = [
            column as f64 + rng.random::<f64>(),
            row as f64 + rng.random::<f64>(),
        ];
        let Some(point) = scene.geometry.point(resolution, at) else {
            continue;
        };
        let lobe = &lobes[scene.material.grid.texel(point.uv)];
        let value = lighting.sample(&point, lobe, &mut rng);
        for c in 0..3 {
            sum[c] += value[c];
        }
    }
    sum.map(|s| s / scene.samples as f64)
}

#[cfg(test)]
mod tests;

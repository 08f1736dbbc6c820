//! The printed board around the sample, as a camera sees it: matte paper (Lambertian) with
//! black modules, lit by each photo's light. `synth --board` adds it to the rendered sample so
//! that synthetic phone photos carry the tags `capture` needs (issue #18, "Synthetic truth").

use super::Board;
use crate::capture::Capture;
use glam::DVec3;
use rayon::prelude::*;
use std::f64::consts::FRAC_1_PI;

/// Albedo of the white paper (office paper is about 0.8).
pub const PAPER_WHITE: f64 = 0.8;
/// Albedo of the printed black modules (laser toner is about 0.04).
pub const PAPER_BLACK: f64 = 0.04;
/// Albedo of the table beyond the printed board.
pub const TABLE: f64 = 0.15;

/// Per pixel of every photo of `capture` (records order: photo by photo, row-major), the mean
/// over the same `k x k` stratified sub-samples as `ShadingRecords::build` of the paper's
/// radiance `albedo / pi * irradiance * exposure`, for sub-samples that see the board plane
/// outside the sample; zero for sub-samples on the sample (the renderer's part).
pub fn paper_radiance(board: &Board, capture: &Capture, pixel_samples: usize) -> Vec<[f64; 3]> {
    let grid = (pixel_samples as f64).sqrt().round() as usize;
    let capture = &*capture.in_material_frame();
    let extent = board.extent();
    let mut out = Vec::new();
    for photo in &capture.photos {
        let [width, height] = photo.camera.resolution();
        let camera = photo.camera.position();
        let rows: Vec<Vec<[f64; 3]>> = (0..height)
            .into_par_iter()
            .map(|r| {
                (0..width)
                    .map(|c| {
                        let mut sum = [0.0; 3];
                        for j in 0..grid * grid {
                            let position = [
                                c as f64 + ((j % grid) as f64 + 0.5) / grid as f64,
                                r as f64 + ((j / grid) as f64 + 0.5) / grid as f64,
                            ];
                            let Some(x) = photo.camera.surface_point(&capture.sample, position)
                            else {
                                continue;
                            };
                            if capture.sample.contains(x) {
                                continue;
                            }
                            let on_board = x.x >= extent[0]
                                && x.x <= extent[1]
                                && x.y >= extent[2]
                                && x.y <= extent[3];
                            let albedo = match board.is_black(x.x, x.y) {
                                _ if !on_board => TABLE,
                                Some(true) => PAPER_BLACK,
                                _ => PAPER_WHITE,
                            };
                            let e = photo
                                .light
                                .incident(camera, DVec3::new(x.x, x.y, 0.0))
                                .irradiance;
                            for i in 0..3 {
                                sum[i] += albedo * FRAC_1_PI * e[i] * photo.exposure;
                            }
                        }
                        sum.map(|v| v / (grid * grid) as f64)
                    })
                    .collect()
            })
            .collect();
        out.extend(rows.into_iter().flatten());
    }
    out
}

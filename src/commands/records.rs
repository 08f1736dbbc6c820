//! `bouncefit records CAPTURE`: the cameras of a photo set as the tool understands them,
//! for checking the projection against an independent implementation (`cv2.projectPoints` in
//! `tests/crosscheck/`).
//!
//! Per photo it prints (one JSON object on stdout):
//!
//! | field | meaning |
//! | --- | --- |
//! | `stem`, `resolution`, `exposure`, `light` | as the capture resolves them |
//! | `camera` | the resolved camera (`model` pinhole: `position`, `look_at`, `up`, `fx`, `fy`, `cx`, `cy`; rectified: `position`) |
//! | `world_to_camera` | pinhole only: OpenCV's extrinsics, `rotation` rows `right`, `-up`, `forward` of [`crate::capture::Frame`] and `translation = -rotation * position` |
//! | `corners` | the sample's corners `(-w/2, -h/2)`, `(w/2, -h/2)`, `(w/2, h/2)`, `(-w/2, h/2)` on z = 0 and their pixel positions |
//! | `points` | `--points` points drawn uniformly on the sample (seeded, the same for every photo) and their pixel positions |
//!
//! Pixel positions come from [`crate::capture::Camera::project`] (pixel `(c, r)` covers
//! `[c, c+1] x [r, r+1]`); `null` for a point behind a pinhole camera.

use super::inputs::open_capture;
use crate::capture::{Camera, Capture};
use crate::error::Result;
use crate::random::rng_stream;
use glam::DVec3;
use rand::Rng;
use serde_json::{json, Value};
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct RecordsArgs {
    /// Photo set: a folder with capture.toml, a capture.toml, or a MaterialGAN-format folder.
    pub capture: PathBuf,
    /// Random points on the sample to project, besides its corners.
    #[arg(long, default_value_t = 16)]
    pub points: usize,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
}

pub fn run_records(args: &RecordsArgs) -> Result<()> {
    let capture = open_capture(&args.capture)?;
    let (w, h) = (capture.sample.width, capture.sample.height);
    let corners = [(-0.5, -0.5), (0.5, -0.5), (0.5, 0.5), (-0.5, 0.5)]
        .map(|(u, v)| DVec3::new(u * w, v * h, 0.0))
        .to_vec();
    let mut rng = rng_stream(args.seed, 0);
    let points: Vec<DVec3> = (0..args.points)
        .map(|_| {
            let (u, v): (f64, f64) = (rng.random(), rng.random());
            DVec3::new((u - 0.5) * w, (v - 0.5) * h, 0.0)
        })
        .collect();
    let photos: Vec<Value> = capture
        .photos
        .iter()
        .map(|photo| {
            let mut record = json!({
                "stem": photo.stem(),
                "resolution": photo.camera.resolution(),
                "exposure": photo.exposure,
                "light": photo.light,
                "camera": photo.camera,
                "corners": projected(&capture, &photo.camera, &corners),
                "points": projected(&capture, &photo.camera, &points),
            });
            if let Camera::Pinhole(pinhole) = &photo.camera {
                let frame = pinhole.frame();
                let rotation = [frame.right, -frame.up, frame.forward];
                record["world_to_camera"] = json!({
                    "rotation": rotation.map(|row| row.to_array()),
                    "translation": rotation.map(|row| -row.dot(pinhole.position)),
                });
            }
            record
        })
        .collect();
    let out = json!({
        "capture": args.capture.display().to_string(),
        "units": capture.units,
        "sample": capture.sample,
        "photos": photos,
    });
    println!("{out}");
    Ok(())
}

/// `{"world": [[x, y, z], ...], "pixel": [[px, py] or null, ...]}`.
fn projected(capture: &Capture, camera: &Camera, world: &[DVec3]) -> Value {
    json!({
        "world": world.iter().map(|p| p.to_array()).collect::<Vec<_>>(),
        "pixel": world
            .iter()
            .map(|p| camera.project(&capture.sample, *p))
            .collect::<Vec<_>>(),
    })
}

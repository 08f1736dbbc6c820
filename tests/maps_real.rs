//! Material maps of the three real phone-flash captures (issue #17): fitted on 8 photos, they
//! must predict the 9th better than a uniform material and than the mean of the other photos.
//!
//! The captures live in `../shared/data/real`, beside the project, and have no licence: they
//! are read from there, never copied into the project; the test skips with a message where
//! they are absent. To keep the test suite's time down the photos are halved to 128x128 in a
//! temporary folder (2 x 2 means in linear light, as the data's own 256 folder was made from
//! its 1024 one); `scripts/maps-real.sh` gives the figures at 256x256.

mod common;

use common::{read_json, run_ok, shared};
use image::{Rgb, RgbImage};
use std::fs;
use std::path::Path;

/// The MaterialGAN encoding of the photos: a pure 2.2 power law.
const GAMMA: f64 = 2.2;

/// `set`'s calibration files and its 256x256 photos halved into `out/128`, with their
/// saturation masks: a halved pixel is saturated where any of its four was.
fn halved_capture(set: &Path, out: &Path) {
    let photos = out.join("128");
    fs::create_dir_all(&photos).unwrap();
    for entry in fs::read_dir(set).unwrap() {
        let path = entry.unwrap().path();
        if path.is_file() {
            fs::copy(&path, out.join(path.file_name().unwrap())).unwrap();
        }
    }
    for i in 0.. {
        let source = set.join(format!("256/{i:02}.png"));
        if !source.exists() {
            break;
        }
        let photo = image::open(&source).unwrap().to_rgb8();
        let mask = image::open(set.join(format!("256/{i:02}_saturated_mask.png")))
            .unwrap()
            .to_luma8();
        let side = photo.width() / 2;
        let mut halved = RgbImage::new(side, side);
        let mut saturated = image::GrayImage::new(side, side);
        for (x, y, pixel) in halved.enumerate_pixels_mut() {
            let block = [(0, 0), (0, 1), (1, 0), (1, 1)].map(|(dx, dy)| (2 * x + dx, 2 * y + dy));
            let clipped = block.iter().any(|&(u, v)| {
                mask.get_pixel(u, v)[0] > 0 || photo.get_pixel(u, v).0.contains(&255)
            });
            *pixel = Rgb([0, 1, 2].map(|c| {
                let linear: f64 = block
                    .iter()
                    .map(|&(u, v)| (photo.get_pixel(u, v)[c] as f64 / 255.0).powf(GAMMA))
                    .sum::<f64>()
                    / 4.0;
                // 254 at most: clipping is carried by the mask, not re-detected.
                (linear.powf(1.0 / GAMMA) * 255.0).round().min(254.0) as u8
            }));
            saturated.put_pixel(x, y, image::Luma([if clipped { 255 } else { 0 }]));
        }
        halved.save(photos.join(format!("{i:02}.png"))).unwrap();
        saturated
            .save(photos.join(format!("{i:02}_saturated_mask.png")))
            .unwrap();
    }
}

/// `(held-out relative error, mean-photo baseline)` of a `single` maps fit of `capture` on
/// every photo but 8, predicting photo 8.
fn held_out(capture: &Path, depth: &str, out: &Path, extra: &[&str]) -> (f64, f64) {
    let mut args = vec![
        "fit",
        capture.to_str().unwrap(),
        "--maps",
        "--models",
        "single",
        "--holdout-photo",
        "8",
        "--depth",
        depth,
        "-o",
        out.to_str().unwrap(),
        "--quiet",
    ];
    args.extend(extra);
    run_ok(&args);
    let holdout = &read_json(out)["holdout"];
    (
        holdout["relative_error"].as_f64().unwrap(),
        holdout["mean_photo_error"].as_f64().unwrap(),
    )
}

/// The maps must beat one texel (the same fit with `--texels 1x1`, a uniform material) by 5%
/// on every set, and the mean photo by 30% where they do (issue #17's bound). Measured at
/// 128x128 (held-out error of the maps, of one texel, of the mean photo): yellow_box 0.149,
/// 0.165, 0.274; real_cards-blue 0.362, 0.421, 0.649; bath_tile 0.290, 0.654, 0.276 (the bath
/// tile's maps do not beat the mean photo, as issue #17 notes, so its bound is the uniform
/// material alone). With the texel lookup of the prediction flipped upside down (and the
/// fit's left as it is) yellow_box's maps gave 0.163, which fails the 5%.
#[test]
fn maps_of_real_captures_predict_a_held_out_photo_better_than_a_uniform_material() {
    let Some(real) = shared("data/real") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    // (set, depth of its marker board in cm, largest held-out error as a share of the baseline)
    for (set, depth, of_baseline) in [
        ("yellow_box", "0.1", Some(0.7)),
        ("real_cards-blue", "0", Some(0.7)),
        ("bath_tile", "0.1", None),
    ] {
        let capture = dir.path().join(set);
        halved_capture(&real.join(set), &capture);
        let (maps, baseline) = held_out(
            &capture,
            depth,
            &dir.path().join(format!("{set}-maps.json")),
            &[],
        );
        let (uniform, _) = held_out(
            &capture,
            depth,
            &dir.path().join(format!("{set}-uniform.json")),
            &["--texels", "1x1", "--bases", "1"],
        );
        eprintln!("{set}: held-out error {maps:.4}, uniform {uniform:.4}, baseline {baseline:.4}");
        assert!(
            maps < 0.95 * uniform,
            "{set}: maps predict photo 8 with error {maps}, a uniform material with {uniform}"
        );
        if let Some(share) = of_baseline {
            assert!(
                maps < share * baseline,
                "{set}: held-out error {maps} is not below {share} x the baseline {baseline}"
            );
        }
    }
}

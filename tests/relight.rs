//! `bouncefit relight` end to end: a fit of a small synthetic copper set relit under the
//! bundled sky, a turntable and its own photos' lights, a maps material on the flat sample;
//! and bad input (exit 2, the file named, no output folder left).

mod common;
use bouncefit::capture::image_io::{load_image, ColorEncoding};
use common::*;
use image::AnimationDecoder;
use std::path::{Path, PathBuf};

/// A 16x16 version of the bundled copper-flash set, synthesised and fitted in `dir`; returns
/// the fit file.
fn small_fit(dir: &Path) -> PathBuf {
    let template = std::fs::read_to_string(repo("datasets/sources/copper-flash.capture.toml"))
        .unwrap()
        .replace("resolution = [128, 128]", "resolution = [16, 16]");
    std::fs::write(dir.join("template.toml"), template).unwrap();
    synth(
        &repo("datasets/copper-flash/material.json"),
        &dir.join("template.toml"),
        &dir.join("set"),
        &[],
    );
    fit_json(&dir.join("set"), &[], dir);
    dir.join("fit.json")
}

/// `bouncefit relight INPUT -o OUT` at 24 pixels and 2 samples per pixel, with `extra` flags.
fn relight(input: &Path, out: &Path, extra: &[&str]) {
    let (input, out) = (input.to_str().unwrap(), out.to_str().unwrap());
    let small = ["relight", input, "-o", out, "--size", "24", "--spp", "2"];
    run_ok(&[&small[..], extra].concat());
}

/// The number of frames of a GIF.
fn gif_frames(path: &Path) -> usize {
    let file = std::io::BufReader::new(std::fs::File::open(path).unwrap());
    let decoder = image::codecs::gif::GifDecoder::new(file).unwrap();
    decoder.into_frames().count()
}

/// Every frame's EXR has `resolution` and finite, non-negative values, and some light.
fn check_exr(path: &Path, resolution: [usize; 2]) {
    let image = load_image(path, ColorEncoding::Linear).unwrap();
    assert_eq!(
        [image.width, image.height],
        resolution,
        "{}",
        path.display()
    );
    let values: Vec<f32> = image.rgb.iter().flatten().copied().collect();
    assert!(values.iter().all(|v| v.is_finite() && *v >= 0.0));
    assert!(
        values.iter().any(|v| *v > 0.0),
        "{} is black",
        path.display()
    );
}

#[test]
fn relight_writes_frames_and_a_preview_for_every_light() {
    let dir = tempfile::tempdir().unwrap();
    let fit = small_fit(dir.path());

    let sky = dir.path().join("sky");
    relight(&fit, &sky, &[]);
    assert_eq!(
        folder_entries(&sky),
        [
            "environment.exr",
            "frame_000.exr",
            "frame_000.png",
            "preview.gif"
        ]
    );
    check_exr(&sky.join("frame_000.exr"), [24, 24]);
    // The light written beside the frames is the bundled sky in the lat-long convention: its
    // brightest texel is the sun's, at elevation 35 and azimuth 30 degrees.
    let env = load_image(&sky.join("environment.exr"), ColorEncoding::Linear).unwrap();
    assert_eq!([env.width, env.height], [256, 128]);
    let brightest = (0..env.rgb.len())
        .max_by(|&a, &b| env.rgb[a][0].total_cmp(&env.rgb[b][0]))
        .unwrap();
    let (column, row) = (brightest % env.width, brightest / env.width);
    let (azimuth, elevation) = (
        (column as f64 + 0.5) * 360.0 / 256.0,
        90.0 - (row as f64 + 0.5) * 180.0 / 128.0,
    );
    assert!(
        (azimuth - 30.0).abs() < 3.0 && (elevation - 35.0).abs() < 3.0,
        "sun texel at azimuth {azimuth}, elevation {elevation}"
    );
    assert_eq!(gif_frames(&sky.join("preview.gif")), 1);

    let turntable = dir.path().join("turntable");
    relight(
        &fit,
        &turntable,
        &[
            "--light",
            "turntable",
            "--frames",
            "3",
            "--geometry",
            "flat",
        ],
    );
    assert_eq!(folder_entries(&turntable).len(), 7);
    for k in 0..3 {
        check_exr(&turntable.join(format!("frame_{k:03}.exr")), [24, 24]);
    }
    assert_eq!(gif_frames(&turntable.join("preview.gif")), 3);

    // The fit file names its photo set: one frame per photo, named as the photos.
    let capture = dir.path().join("capture");
    relight(&fit, &capture, &["--light", "capture"]);
    let entries = folder_entries(&capture);
    assert_eq!(entries.len(), 2 * 9 + 1, "{entries:?}");
    for stem in ["00", "04", "08"] {
        check_exr(&capture.join(format!("{stem}.exr")), [24, 24]);
    }

    // A maps material on the flat sample: the image keeps the maps' proportions.
    let maps = dir.path().join("maps");
    relight(
        &repo("datasets/two-materials/material.json"),
        &maps,
        &["--geometry", "flat", "--env", "white"],
    );
    check_exr(&maps.join("frame_000.exr"), [24, 24]);
}

#[test]
fn bad_input_exits_2_names_the_file_and_leaves_no_output() {
    let dir = tempfile::tempdir().unwrap();
    let material = repo("datasets/copper-flash/material.json");
    let out = dir.path().join("out");
    let not_exr = dir.path().join("env.exr");
    std::fs::write(&not_exr, "not an image").unwrap();
    let missing_env = dir.path().join("missing.exr");
    let cases: Vec<(Vec<String>, String)> = vec![
        (
            vec!["--env".into(), missing_env.display().to_string()],
            missing_env.display().to_string(),
        ),
        (
            vec!["--env".into(), not_exr.display().to_string()],
            not_exr.display().to_string(),
        ),
        (
            vec!["--env".into(), material.display().to_string()],
            "file type".into(),
        ),
        (
            vec!["--light".into(), "capture".into()],
            format!("{}: capture", material.display()),
        ),
        (vec!["--spp".into(), "0".into()], "--spp".into()),
        (
            vec![
                "--light".into(),
                "turntable".into(),
                "--distance".into(),
                "0.5".into(),
            ],
            "--distance".into(),
        ),
        (vec!["--no-such-option".into()], "--no-such-option".into()),
    ];
    let mut problems = Vec::new();
    for (extra, named) in &cases {
        let mut args = vec![
            "relight".to_string(),
            material.display().to_string(),
            "-o".into(),
            out.display().to_string(),
        ];
        args.extend(extra.iter().cloned());
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let (stderr, mut wrong) = run_bad_problems(&args);
        if !stderr.contains(named.as_str()) {
            wrong.push(format!(
                "{extra:?}: stderr does not name `{named}`: {stderr}"
            ));
        }
        problems.extend(wrong);
        if out.exists() {
            problems.push(format!("{extra:?} left {}", out.display()));
        }
    }
    let missing_fit = dir.path().join("no-fit.json");
    let stderr = run_bad(&[
        "relight",
        missing_fit.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(stderr.contains("no-fit.json"), "{stderr}");
    assert!(problems.is_empty(), "{}", problems.join("\n"));
    assert_eq!(
        folder_entries(dir.path()),
        ["env.exr"],
        "nothing else written"
    );
}

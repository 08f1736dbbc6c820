//! `fit --mcmc` (issue "--mcmc"): interval coverage on noisy synthetic sets, model choice
//! between `single` and a multi-bounce model, the `posterior` contract, resumption from a
//! checkpoint, and bad input.
//!
//! Budget: photo sets of 4 photos of 24x24 pixels at 1 sample per pixel (2304 pixels), 4 chains
//! of 100 warm-up and 200 kept iterations, likelihood on all pixels (the resumption test: 40 and
//! 60 iterations on a random subset of 800 pixels).

mod common;
use common::*;
use rand::{Rng, SeedableRng};
use serde_json::Value;
use std::path::Path;

/// Four photos of an 8 cm sample, 24x24 pixels: two flash photos and two with an oblique point
/// light, so that both normal-incidence reflectance and the lobe's shape are seen.
const CAPTURE: &str = r#"
name = "mcmc-test"
units = "cm"
[sample]
width = 8.0
height = 8.0
[camera]
model = "rectified"
position = [0.0, 0.0, 18.0]
resolution = [24, 24]
[[photo]]
image = "00.exr"
light = { kind = "flash", intensity = [1500.0, 1500.0, 1500.0] }
[[photo]]
image = "01.exr"
camera = { position = [3.0, 3.2, 17.2] }
light = { kind = "flash", intensity = [1500.0, 1500.0, 1500.0] }
[[photo]]
image = "02.exr"
light = { kind = "point", position = [-9.0, 2.0, 12.0], intensity = [1500.0, 1500.0, 1500.0] }
[[photo]]
image = "03.exr"
camera = { position = [-2.6, -2.1, 17.6] }
light = { kind = "point", position = [6.0, -8.0, 10.0], intensity = [1500.0, 1500.0, 1500.0] }
"#;

const MCMC: [&str; 4] = ["--mcmc", "--pixel-samples", "1", "--quiet"];

/// Render a photo set of `material` (JSON text) with relative noise `noise`.
fn synth_set(dir: &Path, name: &str, material: &str, noise: f64, seed: u64) -> std::path::PathBuf {
    let capture = dir.join("capture.toml");
    std::fs::write(&capture, CAPTURE).unwrap();
    let material_path = dir.join(format!("{name}.material.json"));
    std::fs::write(&material_path, material).unwrap();
    let set = dir.join(name);
    synth(
        &material_path,
        &capture,
        &set,
        &[
            "--noise",
            &noise.to_string(),
            "--seed",
            &seed.to_string(),
            "--pixel-samples",
            "1",
        ],
    );
    set
}

/// Warm-up and kept iterations of the coverage and model-choice runs, likelihood on all pixels.
const SCHEDULE: [&str; 6] = [
    "--mcmc-warmup",
    "100",
    "--mcmc-samples",
    "200",
    "--mcmc-pixels",
    "0",
];

/// Fit `set` with `--mcmc` and the extra arguments; returns the fit file.
fn mcmc_fit(set: &Path, out: &Path, extra: &[&str]) -> Value {
    let mut args = vec!["fit", set.to_str().unwrap(), "-o", out.to_str().unwrap()];
    args.extend_from_slice(&MCMC);
    args.extend_from_slice(extra);
    run_ok(&args);
    read_json(out)
}

fn material(model: &str, alpha: f64, f0: [f64; 3]) -> String {
    format!(
        r#"{{"model": "{model}", "alpha": {alpha}, "fresnel": {{"kind": "schlick", "f0": [{}, {}, {}]}}}}"#,
        f0[0], f0[1], f0[2]
    )
}

fn inside(ci: &Value, truth: f64) -> bool {
    ci[0].as_f64().unwrap() <= truth && truth <= ci[1].as_f64().unwrap()
}

/// `(truth - mean) / sd` with the sd read from the interval width (`ci95` = mean -+ 1.96 sd
/// for a near-Gaussian posterior).
fn z_score(mean: &Value, ci: &Value, truth: f64) -> f64 {
    let (lo, hi) = (ci[0].as_f64().unwrap(), ci[1].as_f64().unwrap());
    (truth - mean.as_f64().unwrap()) / ((hi - lo) / 3.92)
}

#[test]
fn intervals_cover_the_truth_on_noisy_synthetic_sets() {
    let dir = tempfile::tempdir().unwrap();
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(2024);
    // Per parameter (alpha, F0 r, g, b): sets whose interval holds the truth, and sum of z^2.
    let mut covered = [0; 4];
    let mut chi_square = 0.0;
    for set_index in 0..10 {
        let alpha: f64 = rng.random_range(0.1..0.6);
        let f0 = [0; 3].map(|_| rng.random_range(0.3..0.95));
        let noise: f64 = rng.random_range(0.02..0.05);
        let set = synth_set(
            dir.path(),
            &format!("set{set_index}"),
            &material("single", alpha, f0),
            noise,
            set_index,
        );
        // relative-l2 is the loss of synth's noise, proportional to radiance. This is the
        // calibration of the likelihood itself, so without the model-error adjustment (which
        // only widens; its coverage is measured by scripts/interval-coverage.sh).
        let fit = mcmc_fit(
            &set,
            &dir.path().join(format!("fit{set_index}.json")),
            &[
                &SCHEDULE[..],
                &["--loss", "relative-l2", "--model-error", "none"],
            ]
            .concat(),
        );
        let posterior = &fit["posterior"];
        let rhat = posterior["rhat_max"].as_f64().unwrap();
        assert!(rhat < 1.05, "set {set_index}: R-hat {rhat}");
        let params = &posterior["params"];
        let mut checks = vec![(&params["alpha"]["mean"], &params["alpha"]["ci95"], alpha)];
        for c in 0..3 {
            checks.push((&params["f0"]["mean"][c], &params["f0"]["ci95"][c], f0[c]));
        }
        for (k, (mean, ci, truth)) in checks.into_iter().enumerate() {
            covered[k] += inside(ci, truth) as usize;
            chi_square += z_score(mean, ci, truth).powi(2);
        }
    }
    // Calibrated intervals: each holds the truth with probability 0.95, so alpha's 10 hold it
    // at least 9 times with probability 0.91 and the 40 together at least 36 times with
    // probability 0.95 (binomial); the 40 z-scores are N(0, 1), so their sum of squares is
    // chi-square with 40 degrees of freedom, between its 0.1% and 99.9% quantiles 17.9 and 73.4.
    // Intervals half as wide give ~160, twice as wide ~10.
    eprintln!("covered {covered:?} of 10 (alpha, F0 r, g, b), sum z^2 = {chi_square:.1}");
    assert!(covered[0] >= 9, "alpha: {} of 10", covered[0]);
    assert!(covered.iter().sum::<usize>() >= 36, "{covered:?}");
    assert!(
        (17.9..73.4).contains(&chi_square),
        "sum of z^2 {chi_square}"
    );
}

#[test]
fn posterior_prefers_the_model_that_made_the_photos() {
    // Candidates: single and kulla-conty (deterministic, tabulated multi-bounce: cheap).
    let dir = tempfile::tempdir().unwrap();
    for (model, alpha, expected) in [("single", 0.5, "single"), ("heitz", 0.6, "kulla-conty")] {
        let set = synth_set(
            dir.path(),
            model,
            &material(model, alpha, [0.9, 0.7, 0.5]),
            0.02,
            5,
        );
        let out = dir.path().join(format!("{model}.json"));
        let fit = mcmc_fit(
            &set,
            &out,
            &[
                &SCHEDULE[..],
                &["--models", "single,kulla-conty", "--loss", "relative-l2"],
            ]
            .concat(),
        );
        let posterior = &fit["posterior"];
        eprintln!(
            "{model}: models {} laplace {} between-model acceptance {}",
            posterior["models"], posterior["laplace_models"], posterior["acceptance"]
        );
        let p = posterior["models"][expected].as_f64().unwrap();
        let other = if expected == "single" {
            "kulla-conty"
        } else {
            "single"
        };
        assert!(p > 0.5, "{model} photos: p({expected}) = {p}");
        assert!(
            (p + posterior["models"][other].as_f64().unwrap() - 1.0).abs() < 1e-12,
            "probabilities sum to 1"
        );
        assert!(posterior["laplace_models"][expected].as_f64().unwrap() > 0.5);
        // The fit file's material is the MAP of the most probable model.
        assert_eq!(fit["model"], expected);
        assert_eq!(
            posterior["per_model"][expected]["samples"]
                .as_u64()
                .unwrap() as f64,
            (p * posterior["samples"].as_f64().unwrap()).round()
        );
    }
}

#[test]
fn a_resumed_run_repeats_an_uninterrupted_one() {
    let dir = tempfile::tempdir().unwrap();
    let set = synth_set(
        dir.path(),
        "resume",
        &material("single", 0.4, [0.8, 0.6, 0.4]),
        0.03,
        9,
    );
    let models = [
        "--models",
        "single,kulla-conty",
        "--mcmc-warmup",
        "40",
        "--mcmc-samples",
        "60",
        "--mcmc-pixels",
        "800",
    ];
    let straight = mcmc_fit(&set, &dir.path().join("straight.json"), &models);
    let checkpoint = dir.path().join("state.json");
    let resumed_path = dir.path().join("resumed.json");
    let mut stopped = models.to_vec();
    stopped.extend(["--checkpoint", checkpoint.to_str().unwrap()]);
    let mut first = stopped.clone();
    // Stop inside the kept iterations (40 warm-up + 30).
    first.extend(["--mcmc-stop-after", "70"]);
    let mut args = vec![
        "fit",
        set.to_str().unwrap(),
        "-o",
        resumed_path.to_str().unwrap(),
    ];
    args.extend_from_slice(&MCMC);
    args.extend_from_slice(&first);
    run_ok(&args);
    assert!(checkpoint.exists() && !resumed_path.exists());
    let saved = read_json(&checkpoint);
    assert!(saved["chains"]
        .as_array()
        .unwrap()
        .iter()
        .all(|c| c["iterations"] == 70));
    stopped.push("--resume");
    let resumed = mcmc_fit(&set, &resumed_path, &stopped);
    assert!(
        !checkpoint.exists(),
        "a finished run removes its checkpoint"
    );
    for key in [
        "params",
        "models",
        "laplace_models",
        "per_model",
        "acceptance",
        "rhat_max",
        "ess_min",
        "samples",
        "noise",
    ] {
        assert_eq!(
            straight["posterior"][key], resumed["posterior"][key],
            "{key}"
        );
    }
    assert_eq!(straight["alpha"], resumed["alpha"]);
    // A checkpoint of another run (here: more kept iterations) is refused.
    let again = dir.path().join("again.json");
    args[3] = again.to_str().unwrap();
    run_ok(&args);
    // Starting afresh over a stopped run's checkpoint is refused without --force.
    let err = run_bad(&args);
    assert!(
        err.contains("state.json") && err.contains("--resume") && err.contains("--force"),
        "{err}"
    );
    let mut other = args.clone();
    other.retain(|a| !["--mcmc-stop-after", "70", "--mcmc-samples", "60"].contains(a));
    other.extend(["--resume", "--mcmc-samples", "61"]);
    let err = run_bad(&other);
    assert!(
        err.contains("state.json") && err.contains("fingerprint"),
        "{err}"
    );
    assert!(!again.exists());
}

#[test]
fn bad_mcmc_options_are_refused_without_output() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("fit.json");
    let set = repo("datasets/copper-flash");
    for (extra, field) in [
        (vec!["--noise-sigma=-1"], "--noise-sigma"),
        (vec!["--noise-sigma", "nan"], "--noise-sigma"),
        (vec!["--loss", "ssim"], "--loss"),
        (vec!["--chains", "0"], "--chains"),
        (vec!["--mcmc-samples", "2"], "--mcmc-samples"),
        (vec!["--resume"], "checkpoint"),
        (vec!["--discrepancy-floor", "2"], "--discrepancy-floor"),
        (vec!["--discrepancy-floor", "nan"], "--discrepancy-floor"),
        (
            vec!["--discrepancy-floor", "0.01", "--model-error", "none"],
            "--discrepancy-floor",
        ),
    ] {
        let mut args = vec![
            "fit",
            set.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
            "--mcmc",
            "--quiet",
        ];
        args.extend(extra);
        let err = run_bad(&args);
        assert!(err.contains(field), "{field}: {err}");
        assert!(!out.exists());
    }
}

/// Nine photos of an 8 cm sample, 24x24 pixels: five flash photos from different camera
/// positions and four oblique point lights; `{e0}`..`{e8}` are the photos' exposures.
fn nine_photo_capture(exposures: &[f64; 9]) -> String {
    let cameras = [
        [0.0, 0.0],
        [3.0, 3.2],
        [-2.6, -2.1],
        [2.4, -2.8],
        [-3.1, 2.5],
    ];
    let lights = [
        [-9.0, 2.0, 12.0],
        [6.0, -8.0, 10.0],
        [7.0, 7.0, 11.0],
        [-5.0, -7.0, 13.0],
    ];
    let mut text = String::from(
        "name = \"nine\"\nunits = \"cm\"\n[sample]\nwidth = 8.0\nheight = 8.0\n[camera]\n\
         model = \"rectified\"\nposition = [0.0, 0.0, 18.0]\nresolution = [24, 24]\n",
    );
    for (i, exposure) in exposures.iter().enumerate() {
        text += &format!("[[photo]]\nimage = \"{i:02}.exr\"\nexposure = {exposure}\n");
        if let Some([x, y]) = cameras.get(i) {
            text += &format!(
                "camera = {{ position = [{x}, {y}, 17.5] }}\n\
                 light = {{ kind = \"flash\", intensity = [1500.0, 1500.0, 1500.0] }}\n"
            );
        } else {
            let [x, y, z] = lights[i - cameras.len()];
            text += &format!(
                "light = {{ kind = \"point\", position = [{x}, {y}, {z}], \
                 intensity = [1500.0, 1500.0, 1500.0] }}\n"
            );
        }
    }
    text
}

#[test]
fn per_photo_exposure_errors_widen_intervals_to_the_jackknife_spread() {
    // Photos rendered at exposure 1, fitted under manifest exposures off by 3% (seeded normal
    // factors): an error shared by each photo's pixels, which the likelihood alone reads as
    // signal. The default adjustment must widen F0's interval to the spread that the
    // delete-one-photo jackknife of the point fit measures (Efron & Stein 1981: the jackknife
    // variance (n - 1)/n sum (t_i - t_mean)^2), an estimator of the same variance by refits
    // instead of scores; `--model-error none` must stay far narrower.
    let dir = tempfile::tempdir().unwrap();
    let capture = dir.path().join("capture.toml");
    std::fs::write(&capture, nine_photo_capture(&[1.0; 9])).unwrap();
    let material_path = dir.path().join("m.material.json");
    std::fs::write(&material_path, material("single", 0.3, [0.9, 0.6, 0.4])).unwrap();
    let set = dir.path().join("set");
    synth(
        &material_path,
        &capture,
        &set,
        &["--noise", "0.01", "--seed", "5", "--pixel-samples", "1"],
    );
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(77);
    let exposures: [f64; 9] =
        [0; 9].map(|_| 1.0 + 0.03 * rng.sample::<f64, _>(rand_distr::StandardNormal));
    std::fs::write(set.join("capture.toml"), nine_photo_capture(&exposures)).unwrap();

    let sd_of = |fit: &Value| {
        let ci = &fit["posterior"]["params"]["f0"]["ci95"][0];
        (ci[1].as_f64().unwrap() - ci[0].as_f64().unwrap()) / 3.92
    };
    let adjusted = mcmc_fit(&set, &dir.path().join("photos.json"), &SCHEDULE);
    let model_only = mcmc_fit(
        &set,
        &dir.path().join("none.json"),
        &[&SCHEDULE[..], &["--model-error", "none"]].concat(),
    );
    let leave_one_out: Vec<f64> = (0..9)
        .map(|left_out| {
            let mut kept = exposures.to_vec();
            kept.remove(left_out);
            let fold = dir.path().join(format!("fold{left_out}"));
            std::fs::create_dir_all(&fold).unwrap();
            let full = nine_photo_capture(&exposures);
            // Drop photo `left_out`'s block (its header line up to the next header).
            let blocks: Vec<&str> = full.split("[[photo]]\n").collect();
            let mut text = blocks[0].to_string();
            for (i, block) in blocks[1..].iter().enumerate() {
                if i != left_out {
                    text += "[[photo]]\n";
                    text += block;
                }
            }
            std::fs::write(fold.join("capture.toml"), text).unwrap();
            for i in (0..9).filter(|&i| i != left_out) {
                let name = format!("{i:02}.exr");
                std::fs::copy(set.join(&name), fold.join(&name)).unwrap();
            }
            let fit = fit_json(
                &fold,
                &["--pixel-samples", "1"],
                &dir.path().join(format!("jk{left_out}.json")),
            );
            fit["f0"][0].as_f64().unwrap()
        })
        .collect();
    let mean = leave_one_out.iter().sum::<f64>() / 9.0;
    let jackknife = (8.0 / 9.0
        * leave_one_out
            .iter()
            .map(|t| (t - mean).powi(2))
            .sum::<f64>())
    .sqrt();
    let (with, without) = (sd_of(&adjusted), sd_of(&model_only));
    eprintln!("F0 red sd: jackknife {jackknife:.5}, adjusted {with:.5}, model only {without:.5}");
    // The two estimators of the between-photo variance agree within the jackknife's own
    // finite-sample spread (8 degrees of freedom: a 95% range of about 0.55x to 1.45x in sd).
    assert!(
        (0.55..1.6).contains(&(with / jackknife)),
        "{with} against {jackknife}"
    );
    assert!(without < 0.4 * jackknife, "{without} against {jackknife}");
}

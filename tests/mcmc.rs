//! `fit --mcmc` (issue "--mcmc"): interval coverage on noisy synthetic sets, model choice
//! between `single` and a multi-bounce model, the `posterior` contract, resumption from a
//! checkpoint, and bad input.
//!
//! Budget: photo sets of 4 photos of 24x24 pixels at 1 sample per pixel (2304 pixels), 4 chains
//! of 100 warm-up and 200 kept iterations, likelihood on all pixels.

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

const MCMC: [&str; 10] = [
    "--mcmc",
    "--mcmc-warmup",
    "100",
    "--mcmc-samples",
    "200",
    "--mcmc-pixels",
    "0",
    "--pixel-samples",
    "1",
    "--quiet",
];

/// Render a photo set of `material` (JSON text) with relative noise `noise`.
fn synth_set(dir: &Path, name: &str, material: &str, noise: f64, seed: u64) -> std::path::PathBuf {
    let capture = dir.join("capture.toml");
    std::fs::write(&capture, CAPTURE).unwrap();
    let material_path = dir.join(format!("{name}.material.json"));
    std::fs::write(&material_path, material).unwrap();
    let set = dir.join(name);
    run_ok(&[
        "synth",
        "--material",
        material_path.to_str().unwrap(),
        "--capture",
        capture.to_str().unwrap(),
        "-o",
        set.to_str().unwrap(),
        "--noise",
        &noise.to_string(),
        "--seed",
        &seed.to_string(),
        "--pixel-samples",
        "1",
    ]);
    set
}

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

#[test]
fn intervals_cover_the_truth_on_noisy_synthetic_sets() {
    let dir = tempfile::tempdir().unwrap();
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(2024);
    // Covered counts for alpha and F0 r, g, b.
    let mut covered = [0; 4];
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
        let fit = mcmc_fit(&set, &dir.path().join(format!("fit{set_index}.json")), &[]);
        let posterior = &fit["posterior"];
        let rhat = posterior["rhat_max"].as_f64().unwrap();
        assert!(rhat < 1.05, "set {set_index}: R-hat {rhat}");
        let params = &posterior["params"];
        covered[0] += inside(&params["alpha"]["ci95"], alpha) as usize;
        for c in 0..3 {
            covered[1 + c] += inside(&params["f0"]["ci95"][c], f0[c]) as usize;
        }
        eprintln!(
            "set {set_index}: alpha {alpha:.4} in {}, f0 {f0:.4?} in {}, noise {noise:.3}, sigma {}",
            params["alpha"]["ci95"], params["f0"]["ci95"], posterior["noise"]["sigma"]
        );
    }
    // Exact 95% intervals cover at least 9 of 10 with probability 0.91 per parameter.
    for (name, count) in ["alpha", "f0 r", "f0 g", "f0 b"].iter().zip(covered) {
        assert!(count >= 9, "{name}: {count} of 10 intervals contain the truth");
    }
}

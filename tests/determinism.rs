//! Issue #6 item 6: the same command with the same seed gives bit-identical results with one
//! and with two rayon threads.
//!
//! Every command below runs twice, with `RAYON_NUM_THREADS=1` and `=2`, on a small synthetic
//! photo set (the copper-flash capture at 24 x 24 pixels, rendered with the stochastic
//! `bitterli` model and relative noise, so the per-pixel random streams of both the render and
//! the noise are exercised). Output folders must match byte for byte; fit files must match
//! exactly once the wall-clock fields (`seconds`, `map_seconds`, `ess_per_second`) are removed.
//! A reduction whose order followed rayon's work splitting, or a random stream tied to a
//! thread, would change the last bits of a loss and make these comparisons fail.

mod common;

use common::{bin, read_json, repo};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Fields of a fit file that measure wall-clock time and so differ between any two runs.
const TIMING_FIELDS: [&str; 3] = ["seconds", "map_seconds", "ess_per_second"];

/// Runs `bouncefit ARGS` with `threads` rayon threads and asserts success.
fn run_with_threads(threads: usize, args: &[&str]) {
    let out = bin()
        .env("RAYON_NUM_THREADS", threads.to_string())
        .args(args)
        .output()
        .expect("binary runs");
    assert!(
        out.status.success(),
        "bouncefit {args:?} with {threads} threads failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Every file under `dir` (relative path -> bytes).
fn folder_bytes(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let mut files = BTreeMap::new();
    let mut pending = vec![dir.to_path_buf()];
    while let Some(d) = pending.pop() {
        for entry in std::fs::read_dir(&d).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                pending.push(path);
            } else {
                let bytes = std::fs::read(&path).unwrap();
                files.insert(path.strip_prefix(dir).unwrap().to_path_buf(), bytes);
            }
        }
    }
    files
}

/// Asserts two output folders hold the same files with the same bytes.
fn assert_same_folders(one_thread: &Path, two_threads: &Path) {
    let (a, b) = (folder_bytes(one_thread), folder_bytes(two_threads));
    assert!(!a.is_empty(), "{} is empty", one_thread.display());
    assert_eq!(
        a.keys().collect::<Vec<_>>(),
        b.keys().collect::<Vec<_>>(),
        "different files"
    );
    for (name, bytes) in &a {
        assert!(
            bytes == &b[name],
            "{} differs between 1 and 2 threads",
            name.display()
        );
    }
}

/// A fit file without its wall-clock fields.
fn without_timings(mut value: serde_json::Value) -> serde_json::Value {
    match &mut value {
        serde_json::Value::Object(map) => {
            for field in TIMING_FIELDS {
                map.remove(field);
            }
            for v in map.values_mut() {
                *v = without_timings(v.take());
            }
        }
        serde_json::Value::Array(items) => {
            for v in items.iter_mut() {
                *v = without_timings(v.take());
            }
        }
        _ => {}
    }
    value
}

/// The synthetic photo set: copper at alpha 0.3 rendered by `bitterli` with 2% noise, 24 x 24.
fn photo_set(dir: &Path) -> PathBuf {
    let template = std::fs::read_to_string(repo("datasets/sources/copper-flash.capture.toml"))
        .unwrap()
        .replace("resolution = [128, 128]", "resolution = [24, 24]");
    assert!(template.contains("[24, 24]"), "template resolution changed");
    let capture = dir.join("small.capture.toml");
    std::fs::write(&capture, template).unwrap();
    let mut material = read_json(&repo("datasets/sources/copper-a03.material.json"));
    material["model"] = "bitterli".into();
    let material_path = dir.join("bitterli.material.json");
    std::fs::write(&material_path, material.to_string()).unwrap();

    let sets = [1, 2].map(|threads| {
        let out = dir.join(format!("set-{threads}"));
        run_with_threads(
            threads,
            &[
                "synth",
                "--material",
                material_path.to_str().unwrap(),
                "--capture",
                capture.to_str().unwrap(),
                "-o",
                out.to_str().unwrap(),
                "--noise",
                "0.02",
                "--seed",
                "7",
            ],
        );
        out
    });
    assert_same_folders(&sets[0], &sets[1]);
    sets[0].clone()
}

/// Runs `fit SET EXTRA` with 1 and 2 threads; asserts identical fit files (minus timings) and
/// residual images; returns the one-thread fit file.
fn assert_fit_deterministic(dir: &Path, set: &Path, name: &str, extra: &[&str]) -> PathBuf {
    let outputs = [1, 2].map(|threads| {
        let out = dir.join(format!("{name}-{threads}"));
        std::fs::create_dir_all(&out).unwrap();
        let fit = out.join("fit.json");
        let mut args = vec![
            "fit",
            set.to_str().unwrap(),
            "-o",
            fit.to_str().unwrap(),
            "--quiet",
            "--seed",
            "11",
        ];
        args.extend_from_slice(extra);
        run_with_threads(threads, &args);
        out
    });
    let fits = outputs
        .clone()
        .map(|out| without_timings(read_json(&out.join("fit.json"))));
    assert!(fits[0]["loss"].as_f64().unwrap() > 0.0, "{}", fits[0]);
    assert!(!fits[0]["trace"].as_array().unwrap().is_empty());
    assert_eq!(fits[0], fits[1], "{name}: fit files differ");
    assert_same_folders(
        &outputs[0].join("fit.residuals"),
        &outputs[1].join("fit.residuals"),
    );
    outputs[0].join("fit.json")
}

#[test]
fn analytic_fit_and_render_do_not_depend_on_the_thread_count() {
    let dir = tempfile::tempdir().unwrap();
    let set = photo_set(dir.path());
    let fit = assert_fit_deterministic(dir.path(), &set, "single", &["--models", "single"]);
    // `kulla-conty`'s projection sums its moments over pixel chunks in parallel, in a basis
    // with a non-polynomial function of F0.
    let models = ["--models", "kulla-conty"];
    assert_fit_deterministic(dir.path(), &set, "kulla-conty", &models);
    let renders = [1, 2].map(|threads| {
        let out = dir.path().join(format!("render-{threads}"));
        run_with_threads(
            threads,
            &[
                "render",
                "--capture",
                set.to_str().unwrap(),
                "--material",
                fit.to_str().unwrap(),
                "-o",
                out.to_str().unwrap(),
            ],
        );
        out
    });
    assert_same_folders(&renders[0], &renders[1]);
}

#[test]
fn stochastic_fit_does_not_depend_on_the_thread_count() {
    let dir = tempfile::tempdir().unwrap();
    let set = photo_set(dir.path());
    assert_fit_deterministic(
        dir.path(),
        &set,
        "bitterli",
        &[
            "--models",
            "bitterli",
            "--pixel-samples",
            "1",
            "--max-iters",
            "10",
        ],
    );
}

#[test]
fn mcmc_does_not_depend_on_the_thread_count() {
    let dir = tempfile::tempdir().unwrap();
    let set = photo_set(dir.path());
    let fit = assert_fit_deterministic(
        dir.path(),
        &set,
        "mcmc",
        &[
            "--models",
            "single,kulla-conty",
            "--pixel-samples",
            "1",
            "--mcmc",
            "--chains",
            "2",
            "--mcmc-warmup",
            "20",
            "--mcmc-samples",
            "30",
            "--mcmc-pixels",
            "512",
        ],
    );
    assert!(read_json(&fit)["posterior"].is_object());
}

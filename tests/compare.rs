//! `bouncefit compare`: on small synthetic photo sets with known truth, the report ranks a
//! single-bounce fit of multi-bounce photos below a multi-bounce fit, says so in every output,
//! and does not prefer the multi-bounce model when the photos are single-bounce. Bad input exits
//! with status 2 and writes nothing.

mod common;
use common::*;
use serde_json::Value;
use std::path::{Path, PathBuf};

/// Nine 32x32 flash photos (the bundled copper-flash geometry at a quarter of the resolution)
/// of copper with `model` at roughness `alpha`, rendered into `dir/set`.
fn synthetic_set(dir: &Path, model: &str, alpha: f64) -> PathBuf {
    let template = std::fs::read_to_string(repo("datasets/sources/copper-flash.capture.toml"))
        .unwrap()
        .replace("resolution = [128, 128]", "resolution = [32, 32]");
    assert!(
        template.contains("[32, 32]"),
        "the template sets one resolution"
    );
    let capture = dir.join("capture.toml");
    std::fs::write(&capture, template).unwrap();
    let mut material = read_json(&repo("datasets/sources/copper-a03.material.json"));
    material["model"] = model.into();
    material["alpha"] = serde_json::json!([alpha, alpha]);
    let material_path = dir.join("material.json");
    std::fs::write(&material_path, material.to_string()).unwrap();
    let set = dir.join("set");
    synth(&material_path, &capture, &set, &[]);
    set
}

fn compare(set: &Path, report: &Path, extra: &[&str]) -> Value {
    let mut args = vec![
        "compare",
        set.to_str().unwrap(),
        "--models",
        "single,kulla-conty",
        "-o",
        report.to_str().unwrap(),
        "--quiet",
    ];
    args.extend_from_slice(extra);
    run_ok(&args);
    read_json(&report.join("report.json"))
}

/// The report.json row of `model`.
fn row<'a>(report: &'a Value, model: &str) -> &'a Value {
    report["models"]
        .as_array()
        .unwrap()
        .iter()
        .find(|r| r["model"] == model)
        .unwrap_or_else(|| panic!("no row for {model}"))
}

#[test]
fn multi_bounce_photos_rank_single_below_kulla_conty_in_every_output() {
    let dir = tempfile::tempdir().unwrap();
    let set = synthetic_set(dir.path(), "heitz", 0.5);
    let out = dir.path().join("report");
    let report = compare(&set, &out, &["--holdout", "3"]);

    let (single, kulla) = (row(&report, "single"), row(&report, "kulla-conty"));
    let number = |r: &Value, key: &str| r[key].as_f64().unwrap();
    // Single scattering loses the multi-bounce energy of alpha 0.5 copper: its best fit leaves
    // a larger loss, and with equal parameter counts a larger BIC.
    assert!(number(single, "loss") > number(kulla, "loss"));
    assert!(number(single, "bic") > number(kulla, "bic"));
    assert_eq!(report["selection"]["preferred"], "kulla-conty");
    assert!(number(single, "delta_bic") > 10.0);
    assert_eq!(single["evidence"], "very-strong");
    let verdicts: Vec<&str> = report["verdicts"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_str().unwrap())
        .collect();
    assert!(
        verdicts[0].starts_with("BIC prefers kulla-conty over single"),
        "{verdicts:?}"
    );
    // Held-out error for every model: three finite fold losses, mean and standard error.
    for r in [single, kulla] {
        let held_out = &r["held_out"];
        let folds: Vec<f64> = held_out["fold_losses"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        assert_eq!(folds.len(), 3);
        assert!(folds.iter().all(|l| l.is_finite() && *l > 0.0));
        let mean = folds.iter().sum::<f64>() / 3.0;
        assert!((number(held_out, "mean") - mean).abs() <= 1e-12 * mean);
        assert!(number(held_out, "standard_error") > 0.0);
    }
    // No posterior is invented without --mcmc.
    assert!(single["posterior"].is_null() && single["probability"].is_null());

    // Every file of the report.
    let photos = strings(&report["photos"]);
    assert_eq!(photos.len(), 9);
    for file in ["report.md", "report.html", "report.json", "loss_curves.png"] {
        assert!(out.join(file).is_file(), "missing {file}");
    }
    for model in ["single", "kulla-conty"] {
        let fit = read_json(&out.join(model).join("fit.json"));
        assert_eq!(fit["model"], model);
        assert_eq!(fit["selection"]["preferred"], "kulla-conty");
        for stem in &photos {
            for kind in ["target", "fit", "residual"] {
                let image = out.join(model).join(format!("{stem}_{kind}.png"));
                assert!(image.is_file(), "missing {}", image.display());
            }
        }
    }
    // Under new light: per model the relit sphere and sample, its glTF export's sphere and
    // their difference, and its lobe. What glTF describes of `single` is `single` itself, so
    // the two renders (same random streams) agree; kulla-conty's export loses the multiple
    // bounces of alpha 0.5 copper and is darker.
    let relit = &report["relit"];
    let relit_row = |model: &str| {
        let row = relit["rows"]
            .as_array()
            .unwrap()
            .iter()
            .find(|r| r["model"] == model)
            .unwrap();
        for image in ["sphere", "sample", "gltf_sphere", "gltf_difference", "lobe"] {
            let path = out.join(row[image].as_str().unwrap());
            assert_eq!(png_size(&path), (128, 128), "{image}");
        }
        number(row, "gltf_mean_difference")
    };
    let (single_loss, kulla_loss) = (relit_row("single"), relit_row("kulla-conty"));
    eprintln!(
        "glTF export minus fit, relit: single {single_loss:+.4}, kulla-conty {kulla_loss:+.4}"
    );
    assert!(single_loss.abs() < 1e-3, "{single_loss}");
    assert!(kulla_loss < -0.02, "{kulla_loss}");
    // The HTML embeds every image and the plot, and loads nothing from elsewhere.
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    let embedded = html.matches("src=\"data:image/png;base64,").count();
    let relit_images = 2 * 5 + 1;
    assert_eq!(embedded, 1 + relit_images + photos.len() * (1 + 2 * 2));
    assert_eq!(html.matches("src=\"").count(), embedded);
    for external in ["http:", "https:", "<link", "<script", "url("] {
        assert!(!html.contains(external), "HTML contains {external}");
    }
    // One Markdown table row per model.
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    for model in ["single", "kulla-conty"] {
        let rows = md
            .lines()
            .filter(|l| l.starts_with(&format!("| {model} |")))
            .count();
        assert_eq!(rows, 1, "{model} rows in report.md");
    }
    assert!(md.contains("BIC prefers kulla-conty over single"));
}

#[test]
fn single_bounce_photos_are_not_credited_to_the_multi_bounce_model() {
    let dir = tempfile::tempdir().unwrap();
    let set = synthetic_set(dir.path(), "single", 0.5);
    let report = compare(&set, &dir.path().join("report"), &[]);
    let kulla = row(&report, "kulla-conty");
    let preferred = report["selection"]["preferred"].as_str().unwrap();
    assert!(
        preferred == "single" || kulla["evidence"] == "not-distinguishable",
        "single-bounce photos, yet {preferred} preferred: {}",
        report["verdicts"]
    );
    assert!(row(&report, "single")["held_out"].is_null());
    // `fit` uses the same ranking: its fit file is of the preferred model and carries the
    // selection.
    let fit = fit_json(&set, &["--models", "single,kulla-conty"], dir.path());
    assert_eq!(fit["model"], fit["selection"]["preferred"]);
    assert_eq!(fit["selection"]["preferred"], preferred);
    let candidates = fit["selection"]["candidates"].as_array().unwrap();
    assert_eq!(candidates.len(), 2);
    for c in candidates {
        assert!(c["bic"].as_f64().unwrap().is_finite());
        assert!(c["delta_bic"].as_f64().unwrap() >= 0.0);
    }
}

#[test]
fn mcmc_adds_model_probabilities_intervals_and_the_posterior_plot() {
    let dir = tempfile::tempdir().unwrap();
    let set = synthetic_set(dir.path(), "heitz", 0.5);
    let out = dir.path().join("report");
    let report = compare(
        &set,
        &out,
        &[
            "--mcmc",
            "--chains",
            "2",
            "--mcmc-warmup",
            "60",
            "--mcmc-samples",
            "100",
            "--pixel-samples",
            "1",
        ],
    );
    let (single, kulla) = (row(&report, "single"), row(&report, "kulla-conty"));
    let probability = |r: &Value| r["probability"].as_f64().unwrap();
    // One sampler run over both models: probabilities of the two sum to 1, and the
    // multi-bounce photos (Delta-BIC in the hundreds without MCMC) go to kulla-conty.
    assert!((probability(single) + probability(kulla) - 1.0).abs() < 1e-12);
    assert!(probability(kulla) > 0.95, "{}", report["verdicts"]);
    assert!(
        report["verdicts"][2]
            .as_str()
            .unwrap()
            .starts_with("The posterior prefers kulla-conty"),
        "{}",
        report["verdicts"]
    );
    // kulla-conty's intervals, per parameter and channel, are proper and hold their means.
    let posterior = &kulla["posterior"];
    for name in ["alpha", "f0 r", "f0 g", "f0 b"] {
        let p = &posterior["params"][name];
        let (mean, lo, hi) = (
            p["mean"].as_f64().unwrap(),
            p["ci95"][0].as_f64().unwrap(),
            p["ci95"][1].as_f64().unwrap(),
        );
        assert!(lo < mean && mean < hi, "{name}: {p}");
    }
    assert!(posterior["rhat_max"].as_f64().unwrap().is_finite());
    assert!(out.join("posterior.png").is_file());
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert_eq!(
        html.matches("src=\"data:image/png;base64,").count(),
        2 + 2 * 5 + 1 + 9 * (1 + 2 * 2),
        "loss curves, posterior plot, relit and photo images are embedded"
    );
    // Every model's fit file carries the shared posterior; the checkpoint is gone.
    let fit = read_json(&out.join("single").join("fit.json"));
    assert_eq!(fit["posterior"]["models"], posterior["models"]);
    assert!(!dir.path().join("report.mcmc-checkpoint.json").exists());
}

#[test]
fn bad_input_exits_2_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let set = repo("datasets/copper-flash");
    let out = dir.path().join("report");
    let base = |extra: &[&str]| {
        let mut args = vec![
            "compare".to_string(),
            set.to_str().unwrap().into(),
            "-o".into(),
            out.to_str().unwrap().into(),
            "--quiet".into(),
        ];
        args.extend(extra.iter().map(|s| s.to_string()));
        args
    };
    let run = |extra: &[&str]| {
        let args = base(extra);
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        run_bad(&args)
    };
    assert!(run(&["--models", "single,no-such-model"]).contains("unknown model 'no-such-model'"));
    assert!(run(&["--models", "single", "--holdout", "1"]).contains("--holdout"));
    assert!(run(&["--models", "single", "--holdout", "10"]).contains("number of photos (9)"));
    assert!(run(&["--models", "single,single"]).contains("listed twice"));
    let nothing_written = || std::fs::read_dir(dir.path()).unwrap().count() == 0;
    assert!(nothing_written());
    // An existing report folder is kept without --force.
    std::fs::create_dir(&out).unwrap();
    std::fs::write(out.join("keep.txt"), "old").unwrap();
    assert!(run(&["--models", "single"]).contains("--force"));
    let entries: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
    assert_eq!(entries.len(), 1, "a staging folder was left behind");
    assert_eq!(
        std::fs::read_to_string(out.join("keep.txt")).unwrap(),
        "old"
    );
}

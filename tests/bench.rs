//! `bouncefit bench` through the command line: the `--json` contract of issue #5 item 3 on a
//! small run, the output folder, and bad input.

mod common;
use common::*;
use serde_json::Value;

/// The rows of `model` in the estimator table, by sample count.
fn rows<'a>(v: &'a Value, model: &str) -> Vec<&'a Value> {
    v["estimators"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|r| r["model"] == model)
        .collect()
}

#[test]
fn quick_json_has_the_contract_fields_and_consistent_values() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("bench");
    let stdout = run_ok(&[
        "bench",
        "--quick",
        "--json",
        "--quiet",
        "--models",
        "single,bitterli",
        "--configs",
        "16",
        "--render-resolution",
        "32",
        "--fit-halvings",
        "5",
        "--render-capture",
        repo("datasets/sources/copper-flash.capture.toml")
            .to_str()
            .unwrap(),
        "--render-material",
        repo("datasets/sources/copper-a03.material.json")
            .to_str()
            .unwrap(),
        "--fit-sets",
        repo("datasets/copper-flash").to_str().unwrap(),
        "--no-maps",
        "--relight-size",
        "32",
        "-o",
        out.to_str().unwrap(),
    ]);
    let v: Value = serde_json::from_str(&stdout).unwrap();
    // The folder holds the same document, the tables and the plot.
    assert_eq!(read_json(&out.join("bench.json")), v);
    assert!(std::fs::read_to_string(out.join("bench.txt"))
        .unwrap()
        .contains("bitterli"));
    let png = std::fs::read(out.join("bench.png")).unwrap();
    assert_eq!(&png[1..4], b"PNG");

    let estimators = v["estimators"].as_array().unwrap();
    // heitz is added as the reference: 3 models x 6 sample counts.
    assert_eq!(estimators.len(), 18);
    for r in estimators {
        for key in [
            "model",
            "samples",
            "ns_per_eval",
            "rmse",
            "bias_vs_heitz",
            "inverse_efficiency_vs_heitz",
        ] {
            assert!(r.get(key).is_some(), "missing {key} in {r}");
        }
        assert!(r["ns_per_eval"].as_f64().unwrap() > 0.0, "{r}");
    }
    let samples: Vec<u64> = rows(&v, "single")
        .iter()
        .map(|r| r["samples"].as_u64().unwrap())
        .collect();
    assert_eq!(samples, [1, 2, 4, 8, 16, 64]);

    // Analytic: the mean of n evaluations is the value itself, up to the rounding of the sum.
    for r in rows(&v, "single") {
        assert!(r["rmse"].as_f64().unwrap() < 1e-12, "{r}");
        assert!(r["inverse_efficiency_vs_heitz"].is_null(), "{r}");
        // single lacks the multiple scattering heitz has: a real difference, far above noise.
        assert!(
            r["bias_vs_heitz"].as_f64().unwrap() > 5.0 * r["bias_vs_heitz_noise"].as_f64().unwrap()
        );
    }
    // Stochastic: error at every n, falling with n (1/sqrt(64) = 1/8 in expectation).
    for model in ["heitz", "bitterli"] {
        let r = rows(&v, model);
        let (first, last) = (
            r[0]["rmse"].as_f64().unwrap(),
            r[5]["rmse"].as_f64().unwrap(),
        );
        assert!(r.iter().all(|r| r["rmse"].as_f64().unwrap() > 0.0));
        assert!(
            last < first / 2.0,
            "{model}: rmse {first} at n=1, {last} at n=64"
        );
        assert!(r[0]["inverse_efficiency_vs_heitz"].as_f64().unwrap() > 0.0);
    }
    // heitz against an independent converged heitz: a difference of the size the two runs'
    // standard errors predict (the RMS of 48 such differences over its expectation exceeds 2
    // with probability < 1e-6 for Gaussian errors), but not exactly zero.
    let heitz = rows(&v, "heitz")[0];
    let (bias, noise) = (
        heitz["bias_vs_heitz"].as_f64().unwrap(),
        heitz["bias_vs_heitz_noise"].as_f64().unwrap(),
    );
    assert!(
        bias > 0.0 && bias < 2.0 * noise,
        "bias {bias}, noise {noise}"
    );
    assert_eq!(heitz["inverse_efficiency_vs_heitz"].as_f64(), Some(1.0));

    let jobs = v["jobs"].as_array().unwrap();
    let count = |job: &str, skip: bool| {
        jobs.iter()
            .filter(|j| j["job"] == job && j["skip"] == skip)
            .count()
    };
    assert_eq!(
        (
            count("render", false),
            count("render", true),
            count("fit", false),
            count("fit", true)
        ),
        (2, 2, 2, 2)
    );
    // Skipping rows carry their render plan; single has no multiple-bounce term to skip, so
    // its skipping render is the exact one.
    for j in jobs {
        assert_eq!(j["skip"].as_bool().unwrap(), !j["plan"].is_null(), "{j}");
    }
    let single_render = jobs
        .iter()
        .find(|j| j["job"] == "render" && j["model"] == "single" && j["skip"] == true)
        .unwrap();
    assert_eq!(single_render["rel_error_vs_exact"].as_f64(), Some(0.0));
    for j in jobs {
        for key in ["job", "model", "skip", "seconds", "loss", "alpha_rel_error"] {
            assert!(j.get(key).is_some(), "missing {key} in {j}");
        }
        assert!(j["seconds"].as_f64().unwrap() > 0.0, "{j}");
        assert_eq!(j["photos"], if j["job"] == "relight" { 1 } else { 9 });
    }
    // The relight rows: a 32x32 sphere per model of --relight-models (single, kulla-conty by
    // default), each timed against single's in the same run.
    let relight: Vec<&Value> = jobs.iter().filter(|j| j["job"] == "relight").collect();
    let models: Vec<&Value> = relight.iter().map(|j| &j["model"]).collect();
    assert_eq!(models, ["single", "kulla-conty"]);
    let single_seconds = relight[0]["seconds"].as_f64().unwrap();
    for j in &relight {
        assert_eq!(j["resolution"], serde_json::json!([32, 32]));
        assert_eq!(j["pixels"], 32 * 32);
        let ratio = j["seconds_vs_single"].as_f64().unwrap();
        assert!((ratio - j["seconds"].as_f64().unwrap() / single_seconds).abs() < 1e-12);
    }
    // The kernel row times the scalar and the batch kernel on the same pairs.
    let kernel = &v["kernel"];
    for key in ["scalar_ns_per_eval", "batch_ns_per_eval", "speedup"] {
        assert!(kernel[key].as_f64().unwrap() > 0.0, "{kernel}");
    }
    for fit in jobs.iter().filter(|j| j["job"] == "fit") {
        assert_eq!(fit["resolution"], serde_json::json!([4, 4]));
        assert!(
            fit["set"].as_str().unwrap().ends_with("copper-flash"),
            "{fit}"
        );
        // Each fit's time over single's on the same set and skip; single's own is 1.
        let ratio = fit["seconds_vs_single"].as_f64().unwrap();
        let own = fit["seconds"].as_f64().unwrap();
        let single = jobs
            .iter()
            .find(|j| j["job"] == "fit" && j["model"] == "single" && j["skip"] == fit["skip"])
            .unwrap()["seconds"]
            .as_f64()
            .unwrap();
        assert!((ratio - own / single).abs() < 1e-12, "{fit}");
        assert!(fit["loss"].as_f64().unwrap() >= 0.0);
        // The bundled set was made by `single` at alpha 0.3; both models find it within 10%
        // even on 4x4 photos.
        let error = fit["alpha_rel_error"].as_f64().unwrap();
        let alpha = fit["alpha"].as_f64().unwrap();
        assert!(
            (error - (alpha - 0.3) / 0.3).abs() < 1e-12 && error.abs() < 0.1,
            "{fit}"
        );
    }
}

#[test]
fn bad_input_exits_2_before_measuring_and_leaves_no_output() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("no-such-set");
    let err = run_bad(&[
        "bench",
        "--quick",
        "--quiet",
        "--fit-sets",
        missing.to_str().unwrap(),
        "-o",
        dir.path().join("out").to_str().unwrap(),
    ]);
    assert!(err.contains("no-such-set"), "{err}");
    assert!(!dir.path().join("out").exists());

    let taken = dir.path().join("taken");
    std::fs::create_dir(&taken).unwrap();
    std::fs::write(taken.join("keep.txt"), "x").unwrap();
    let err = run_bad(&["bench", "--quick", "--quiet", "-o", taken.to_str().unwrap()]);
    assert!(err.contains("--force"), "{err}");
    assert!(taken.join("keep.txt").exists());

    let flash = repo("datasets/copper-flash");
    let err = run_bad(&[
        "bench",
        "--quick",
        "--fit-sets",
        &format!("{}:metal", flash.display()),
    ]);
    assert!(err.contains("metal") && err.contains("conductor"), "{err}");

    let err = run_bad(&["bench", "--configs", "0"]);
    assert!(err.contains("--configs"), "{err}");

    let err = run_bad(&["bench", "--quick", "--maps-texels", "0"]);
    assert!(err.contains("--maps-texels"), "{err}");
    let err = run_bad(&[
        "bench",
        "--quick",
        "--quiet",
        "--maps-models",
        "single,bitterli",
        "-o",
        dir.path().join("out").to_str().unwrap(),
    ]);
    assert!(err.contains("bitterli is stochastic"), "{err}");
    assert!(!dir.path().join("out").exists());
}

/// Maps fit jobs (issue #17's speed figure) on `datasets/two-materials`' maps rendered as 9
/// flash photos of 24x24: a row per model and texel grid with its time over single's at the
/// same grid, and a held-out photo predicted far better than by the mean of the other photos
/// (measured at 64^2 texels of the bundled set: 0.039 against 0.235).
#[test]
fn maps_fit_jobs_report_time_ratios_and_held_out_error() {
    let dir = tempfile::tempdir().unwrap();
    let template = std::fs::read_to_string(repo("datasets/sources/copper-flash.capture.toml"))
        .unwrap()
        .replace("resolution = [128, 128]", "resolution = [24, 24]");
    assert!(template.contains("[24, 24]"));
    let capture = dir.path().join("capture.toml");
    std::fs::write(&capture, template).unwrap();
    let set = dir.path().join("set");
    synth(
        &repo("datasets/two-materials/material.json"),
        &capture,
        &set,
        &["--noise", "0.01"],
    );
    let stdout = run_ok(&[
        "bench",
        "--quick",
        "--json",
        "--quiet",
        "--models",
        "single",
        "--configs",
        "4",
        "--reference-samples",
        "16",
        "--render-resolution",
        "8",
        "--fit-halvings",
        "5",
        "--fit-sets",
        repo("datasets/copper-flash").to_str().unwrap(),
        "--maps-sets",
        set.to_str().unwrap(),
        "--maps-models",
        "single,kulla-conty",
        "--maps-texels",
        "8,full",
    ]);
    let v: Value = serde_json::from_str(&stdout).unwrap();
    let maps: Vec<&Value> = v["jobs"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|j| j["job"] == "maps-fit")
        .collect();
    assert_eq!(maps.len(), 4);
    let seconds = |j: &Value| j["seconds"].as_f64().unwrap();
    for j in &maps {
        let side = if j["texels"] == serde_json::json!([8, 8]) {
            8
        } else {
            24
        };
        assert_eq!(j["texels"], serde_json::json!([side, side]), "{j}");
        assert_eq!(
            (j["photos"].as_u64(), j["skip"].as_bool()),
            (Some(9), Some(false))
        );
        let single = maps
            .iter()
            .find(|s| s["model"] == "single" && s["texels"] == j["texels"])
            .unwrap();
        let ratio = j["seconds_vs_single"].as_f64().unwrap();
        assert!((ratio - seconds(j) / seconds(single)).abs() < 1e-12, "{j}");
        let (error, baseline) = (
            j["held_out_error"].as_f64().unwrap(),
            j["held_out_baseline"].as_f64().unwrap(),
        );
        assert!(error > 0.0 && error < 0.5 * baseline, "{j}");
        assert!(j["bases"].as_u64().unwrap() >= 1 && j["cpu_seconds"].as_f64().unwrap() > 0.0);
    }
    assert_eq!(
        maps.iter().filter(|j| j["model"] == "kulla-conty").count(),
        2
    );
}

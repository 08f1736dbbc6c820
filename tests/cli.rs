//! The command-line contract of DESIGN.md: JSON fields, round trips, and bad input.

mod common;
use common::*;

const COPPER: &str = "conductor:0.2378,1.0066,1.2404:3.6264,2.5823,2.3929";

fn brdf_json(args: &[&str]) -> serde_json::Value {
    let mut all = vec!["brdf", "--json"];
    all.extend_from_slice(args);
    serde_json::from_str(&run_ok(&all)).unwrap()
}

#[test]
fn brdf_json_has_the_contract_fields_and_consistent_values() {
    let v = brdf_json(&[
        "--model",
        "single",
        "--alpha",
        "0.3",
        "--fresnel",
        COPPER,
        "--wi",
        "1,0,2",
        "--wo",
        "-0.3,0.4,1",
    ]);
    for key in [
        "model", "ndf", "alpha", "wi", "wo", "f", "f_cos", "f_single", "f_multi", "stderr",
        "samples", "seconds",
    ] {
        assert!(!v[key].is_null(), "missing {key}");
    }
    let wo = triple(&v["wo"]);
    assert!(
        (wo.iter().map(|x| x * x).sum::<f64>() - 1.0).abs() < 1e-12,
        "directions are normalised"
    );
    let (f, fc, fs, fm) = (
        triple(&v["f"]),
        triple(&v["f_cos"]),
        triple(&v["f_single"]),
        triple(&v["f_multi"]),
    );
    for c in 0..3 {
        assert!((f[c] - fs[c] - fm[c]).abs() < 1e-15);
        assert!((fc[c] - f[c] * wo[2]).abs() < 1e-15);
        assert!(f[c] > 0.0);
    }
    // Reciprocity through the CLI.
    let swapped = brdf_json(&[
        "--model",
        "single",
        "--alpha",
        "0.3",
        "--fresnel",
        COPPER,
        "--wi",
        "-0.3,0.4,1",
        "--wo",
        "1,0,2",
    ]);
    let g = triple(&swapped["f"]);
    for c in 0..3 {
        assert!((f[c] - g[c]).abs() < 1e-12 * f[c]);
    }
    let aniso = brdf_json(&[
        "--model",
        "single",
        "--ndf",
        "beckmann",
        "--alpha-x",
        "0.1",
        "--alpha-y",
        "0.5",
        "--wi",
        "0,0,1",
        "--wo",
        "0.2,0,1",
        "--height",
        "uncorrelated",
    ]);
    assert_eq!(aniso["alpha"], serde_json::json!([0.1, 0.5]));
}

#[test]
fn albedo_json_reports_energy_loss_of_single() {
    let out = run_ok(&[
        "albedo",
        "--model",
        "single",
        "--alpha",
        "1.0",
        "--theta-i",
        "60",
        "--json",
    ]);
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    for key in ["model", "theta_i_deg", "albedo", "stderr", "samples"] {
        assert!(!v[key].is_null(), "missing {key}");
    }
    let a = triple(&v["albedo"]);
    assert!(
        a[0] < 0.8 && a[0] > 0.2,
        "white albedo of single at alpha 1 is well below 1: {a:?}"
    );
    assert!(triple(&v["stderr"])[0] < 1e-3);
}

#[test]
fn heitz_through_the_cli_conserves_energy_and_reports_its_noise() {
    let out = run_ok(&[
        "albedo",
        "--model",
        "heitz",
        "--alpha",
        "1.0",
        "--theta-i",
        "60",
        "--samples",
        "4096",
        "--json",
    ]);
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    // White Fresnel: every sampled walk escapes with weight 1.
    assert_eq!(triple(&v["albedo"]), [1.0; 3]);
    let args = |wi: &'static str, wo: &'static str| {
        [
            "--model",
            "heitz",
            "--alpha",
            "0.6",
            "--fresnel",
            COPPER,
            "--wi",
            wi,
            "--wo",
            wo,
            "--samples",
            "20000",
        ]
    };
    let f = brdf_json(&args("1,0,2", "-0.3,0.4,1"));
    let g = brdf_json(&args("-0.3,0.4,1", "1,0,2"));
    let (fm, gm) = (triple(&f["f_multi"]), triple(&g["f_multi"]));
    let (se_f, se_g) = (triple(&f["stderr"]), triple(&g["stderr"]));
    assert_eq!(triple(&f["f_single"]), triple(&g["f_single"]));
    for c in 0..3 {
        assert!(fm[c] > 0.0 && se_f[c] > 0.0 && se_f[c] < 0.05 * fm[c]);
        // Reciprocal within the reported noise.
        assert!((fm[c] - gm[c]).abs() < 4.0 * (se_f[c].powi(2) + se_g[c].powi(2)).sqrt());
    }
}

#[test]
fn render_of_the_true_material_reproduces_the_bundled_photos() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("render");
    run_ok(&[
        "render",
        "--capture",
        repo("datasets/copper-flash").to_str().unwrap(),
        "--material",
        repo("datasets/copper-flash/material.json")
            .to_str()
            .unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    for i in 0..9 {
        let load = |p: std::path::PathBuf| {
            bouncefit::capture::image_io::load_image(&p, bouncefit::capture::ColorEncoding::Linear)
                .unwrap()
        };
        let rendered = load(out.join(format!("{i:02}.exr")));
        let bundled = load(repo(&format!("datasets/copper-flash/{i:02}.exr")));
        // Bit-identical pixels: the same records, the same arithmetic, the same f32 rounding.
        assert!(rendered.rgb == bundled.rgb, "photo {i} differs");
        assert!(out.join(format!("{i:02}.png")).exists());
    }
}

#[test]
fn bad_input_exits_2_with_a_named_cause_and_no_output() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let o = out.to_str().unwrap();
    let bad_manifest = dir.path().join("bad.toml");
    std::fs::write(
        &bad_manifest,
        "name = \"x\"\nunits = \"cm\"\n[sample]\nwidth = -1.0\nheight = 1.0\n",
    )
    .unwrap();
    let bad_material = dir.path().join("bad.json");
    std::fs::write(
        &bad_material,
        r#"{"model":"single","alpha":[-0.1,0.2],"fresnel":{"kind":"white"}}"#,
    )
    .unwrap();
    let capture = repo("datasets/sources/copper-flash.capture.toml");
    let material = repo("datasets/sources/copper-a03.material.json");
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (
            vec![
                "brdf", "--model", "nonsense", "--alpha", "0.1", "--wi", "0,0,1", "--wo", "0,0,1",
            ],
            "nonsense",
        ),
        (
            vec![
                "brdf", "--model", "single", "--alpha", "0.1", "--wi", "0,0,-1", "--wo", "0,0,1",
            ],
            "--wi",
        ),
        (
            vec![
                "brdf", "--model", "single", "--alpha", "-1", "--wi", "0,0,1", "--wo", "0,0,1",
            ],
            "alpha",
        ),
        (
            vec![
                "brdf",
                "--model",
                "single",
                "--alpha",
                "0.1",
                "--fresnel",
                "gold",
                "--wi",
                "0,0,1",
                "--wo",
                "0,0,1",
            ],
            "--fresnel",
        ),
        (
            vec![
                "albedo",
                "--model",
                "single",
                "--alpha",
                "0.1",
                "--theta-i",
                "95",
            ],
            "--theta-i",
        ),
        (
            vec![
                "synth",
                "--material",
                "/nonexistent/m.json",
                "--capture",
                capture.to_str().unwrap(),
                "-o",
                o,
            ],
            "/nonexistent/m.json",
        ),
        (
            vec![
                "synth",
                "--material",
                bad_material.to_str().unwrap(),
                "--capture",
                capture.to_str().unwrap(),
                "-o",
                o,
            ],
            "alpha",
        ),
        (
            vec![
                "synth",
                "--material",
                material.to_str().unwrap(),
                "--capture",
                bad_manifest.to_str().unwrap(),
                "-o",
                o,
            ],
            "bad.toml",
        ),
        (
            vec!["fit", "/nonexistent-folder", "-o", o],
            "/nonexistent-folder",
        ),
        (
            vec![
                "render",
                "--capture",
                capture.to_str().unwrap(),
                "--material",
                material.to_str().unwrap(),
                "-o",
                o,
                "--pixel-samples",
                "3",
            ],
            "pixel",
        ),
    ];
    for (args, needle) in cases {
        let stderr = run_bad(&args);
        assert!(
            stderr.contains(needle),
            "bouncefit {args:?}: message should name '{needle}':\n{stderr}"
        );
        assert!(!out.exists(), "bouncefit {args:?} left output behind");
    }
}

#[test]
fn lobe_writes_a_picture_and_an_energy_table_that_adds_up() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("lobe.png");
    for model in ["single", "kulla-conty"] {
        let out = run_ok(&[
            "lobe",
            "--model",
            model,
            "--alpha",
            "0.6",
            "--theta-i",
            "30",
            "-o",
            png.to_str().unwrap(),
            "--size",
            "64",
            "--table-alphas",
            "0.3,1.0",
            "--samples",
            "16384",
            "--json",
            "--force",
        ]);
        let v: serde_json::Value = serde_json::from_str(&out).unwrap();
        assert!(png.exists());
        let rows = v["energy"].as_array().unwrap();
        assert_eq!(rows.len(), 2);
        let total = |r: &serde_json::Value| {
            (0..4)
                .map(|k| r["by_bounce"][k][0].as_f64().unwrap())
                .sum::<f64>()
        };
        // single loses energy with roughness; Kulla-Conty returns it (white furnace within 1%).
        match model {
            "single" => assert!(total(&rows[0]) > total(&rows[1]) && total(&rows[1]) < 0.8),
            _ => rows
                .iter()
                .for_each(|r| assert!((total(r) - 1.0).abs() < 0.01, "{r}")),
        }
    }
}

#[test]
fn stochastic_models_report_errors_and_bitterli_its_fallback_rate() {
    let v: serde_json::Value = serde_json::from_str(&run_ok(&[
        "albedo",
        "--model",
        "bitterli",
        "--alpha",
        "1.5",
        "--theta-i",
        "0",
        "--samples",
        "40000",
        "--json",
    ]))
    .unwrap();
    let rate = v["fallback_rate"]
        .as_f64()
        .expect("bitterli reports its fallback rate");
    assert!((0.0..0.05).contains(&rate), "{rate}");
    let albedo = triple(&v["albedo"]);
    let stderr = triple(&v["stderr"]);
    assert!(
        stderr[0] > 0.0 && (albedo[0] - 1.0).abs() < 4.0 * stderr[0] + 1e-3,
        "white furnace {albedo:?} +- {stderr:?}"
    );
    let single: serde_json::Value = serde_json::from_str(&run_ok(&[
        "albedo",
        "--model",
        "single",
        "--alpha",
        "1.5",
        "--theta-i",
        "0",
        "--json",
    ]))
    .unwrap();
    assert!(single["fallback_rate"].is_null());
    // brdf of a stochastic model: same seed, same answer; f = f_single + f_multi with an error bar.
    let args = [
        "brdf",
        "--model",
        "heitz",
        "--alpha",
        "0.8",
        "--wi",
        "0.5,0,1",
        "--wo",
        "-0.2,0.4,1",
        "--samples",
        "2000",
        "--seed",
        "3",
        "--json",
    ];
    let (a, b): (serde_json::Value, serde_json::Value) = (
        serde_json::from_str(&run_ok(&args)).unwrap(),
        serde_json::from_str(&run_ok(&args)).unwrap(),
    );
    assert_eq!(a["f"], b["f"]);
    assert!(triple(&a["f_multi"])[0] > 0.0 && triple(&a["stderr"])[0] > 0.0);
}

#[test]
fn stress_quick_json_reports_every_model_clean() {
    let out = run_ok(&["stress", "--quick", "--json", "--quiet"]);
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let models = v["models"].as_array().unwrap();
    assert_eq!(models.len(), bouncefit::bsdf::Model::ALL.len());
    for m in models {
        for key in [
            "model",
            "queries",
            "nan",
            "inf",
            "negative",
            "energy_violations",
            "fallback_rate",
            "worst_rel_dev",
        ] {
            assert!(!m[key].is_null(), "missing {key} in {m}");
        }
        assert!(m["queries"].as_u64().unwrap() > 1000);
        for key in ["nan", "inf", "negative"] {
            assert_eq!(m[key], 0, "{}: {key}: {}", m["model"], m["first_bad"]);
        }
        // The batch kernel's part, for the models a fit renders through it, in both lane
        // precisions: clean values and tangents, rounding-level agreement with the scalar
        // kernel (the bounds of src/stress/batch.rs).
        let batch = m["batch"].as_array().unwrap();
        if ["single", "turquin", "kulla-conty", "fast-msx"].contains(&m["model"].as_str().unwrap())
        {
            let precisions: Vec<&str> = batch
                .iter()
                .map(|b| b["precision"].as_str().unwrap())
                .collect();
            assert_eq!(precisions, ["f32", "f64"], "{}", m["model"]);
            for b in batch {
                assert!(b["evaluations"].as_u64().unwrap() > 1000, "{b}");
                for key in ["nan", "inf", "negative", "tangent_nonfinite"] {
                    assert_eq!(b[key], 0, "{}: batch {key}: {b}", m["model"]);
                }
                assert!(b["tangents"].as_u64().unwrap() > 1000, "{b}");
                let bound = if b["precision"] == "f32" { 2e-5 } else { 1e-6 };
                assert!(b["worst_rel_dev"].as_f64().unwrap() < bound, "{b}");
            }
        } else {
            assert!(batch.is_empty(), "{}: {:?}", m["model"], batch);
        }
    }
    // Bitterli's recurrences take their fallback somewhere in the sweep (grazing, equal Lambdas).
    let bitterli = models.iter().find(|m| m["model"] == "bitterli").unwrap();
    assert!(bitterli["fallback_rate"].as_f64().unwrap() > 0.0);
}

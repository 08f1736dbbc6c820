//! Recovery of known parameters from synthetic photos (issue "Foundation", How we will know):
//! every bundled set from a default start, with noise, anisotropy, diffuse, Nelder-Mead, and the
//! MaterialGAN format with and without clipped pixels.

mod common;
use common::*;
use std::path::Path;

struct Recovered {
    alpha: [f64; 2],
    f0: [f64; 3],
    fit: serde_json::Value,
}

fn fit(set: &Path, extra: &[&str], out: &Path) -> Recovered {
    let fit = fit_json(set, extra, out);
    Recovered {
        alpha: [
            fit["alpha"][0].as_f64().unwrap(),
            fit["alpha"][1].as_f64().unwrap(),
        ],
        f0: triple(&fit["f0"]),
        fit,
    }
}

fn assert_close(what: &str, got: f64, truth: f64, rel: f64) {
    assert!(
        ((got - truth) / truth).abs() < rel,
        "{what}: {got} vs truth {truth} (tolerance {rel})"
    );
}

fn assert_f0(got: [f64; 3], truth: [f64; 3], abs: f64) {
    for c in 0..3 {
        assert!(
            (got[c] - truth[c]).abs() < abs,
            "F0 {got:?} vs truth {truth:?} (tolerance {abs})"
        );
    }
}

#[test]
fn bundled_copper_flash_recovers_alpha_and_f0() {
    let dir = tempfile::tempdir().unwrap();
    let truth = read_json(&repo("datasets/copper-flash/material.json"));
    for fresnel in ["schlick", "conductor"] {
        let r = fit(
            &repo("datasets/copper-flash"),
            &["--fresnel", fresnel],
            dir.path(),
        );
        assert_close(
            "alpha",
            r.alpha[0],
            truth["alpha"][0].as_f64().unwrap(),
            0.01,
        );
        assert_f0(r.f0, material_f0(&truth), 0.01);
        // The fit file carries what DESIGN.md promises.
        for key in [
            "model",
            "ndf",
            "height",
            "alpha",
            "fresnel",
            "diffuse",
            "loss",
            "iterations",
            "seconds",
            "photos",
            "trace",
        ] {
            assert!(!r.fit[key].is_null(), "fit file lacks {key}");
        }
        assert_eq!(r.fit["photos"].as_array().unwrap().len(), 9);
        assert!(
            dir.path().join("fit.residuals/00.exr").exists()
                && dir.path().join("fit.residuals/08.png").exists()
        );
        std::fs::remove_file(dir.path().join("fit.json")).unwrap();
    }
}

#[test]
fn bundled_aluminium_pinhole_recovers_alpha_and_f0() {
    let dir = tempfile::tempdir().unwrap();
    let truth = read_json(&repo("datasets/aluminium-pinhole/material.json"));
    let r = fit(
        &repo("datasets/aluminium-pinhole"),
        &["--fresnel", "conductor"],
        dir.path(),
    );
    assert_close(
        "alpha",
        r.alpha[0],
        truth["alpha"][0].as_f64().unwrap(),
        0.01,
    );
    assert_f0(r.f0, material_f0(&truth), 0.01);
    std::fs::remove_file(dir.path().join("fit.json")).unwrap();
    let r = fit(
        &repo("datasets/aluminium-pinhole"),
        &["--fresnel", "conductor", "--optimizer", "nelder-mead"],
        dir.path(),
    );
    assert_close(
        "alpha (Nelder-Mead)",
        r.alpha[0],
        truth["alpha"][0].as_f64().unwrap(),
        0.01,
    );
    assert_f0(r.f0, material_f0(&truth), 0.01);
}

#[test]
fn noisy_photos_still_land_within_five_percent() {
    let dir = tempfile::tempdir().unwrap();
    let set = dir.path().join("noisy");
    synth(
        &repo("datasets/sources/copper-a03.material.json"),
        &repo("datasets/sources/copper-flash.capture.toml"),
        &set,
        &["--noise", "0.05", "--seed", "11"],
    );
    let truth = read_json(&repo("datasets/sources/copper-a03.material.json"));
    let r = fit(&set, &[], dir.path());
    assert_close("alpha", r.alpha[0], 0.3, 0.05);
    for c in 0..3 {
        assert_close("F0", r.f0[c], material_f0(&truth)[c], 0.05);
    }
}

#[test]
fn anisotropic_roughness_and_diffuse_albedo_are_recovered() {
    let dir = tempfile::tempdir().unwrap();
    let material = dir.path().join("m.json");
    std::fs::write(
        &material,
        r#"{"model":"single","ndf":"beckmann","alpha":[0.15,0.4],
        "fresnel":{"kind":"schlick","f0":[0.8,0.6,0.3]},"diffuse":[0.05,0.1,0.2]}"#,
    )
    .unwrap();
    let set = dir.path().join("aniso");
    synth(
        &material,
        &repo("datasets/sources/aluminium-pinhole.capture.toml"),
        &set,
        &[],
    );
    let r = fit(
        &set,
        &["--anisotropic", "--diffuse", "--ndf", "beckmann"],
        dir.path(),
    );
    assert_close("alpha_x", r.alpha[0], 0.15, 0.01);
    assert_close("alpha_y", r.alpha[1], 0.4, 0.01);
    assert_f0(r.f0, [0.8, 0.6, 0.3], 0.01);
    let diffuse = triple(&r.fit["diffuse"]);
    for (got, truth) in diffuse.iter().zip([0.05, 0.1, 0.2]) {
        assert!((got - truth).abs() < 0.005, "diffuse {diffuse:?}");
    }
}

#[test]
fn materialgan_format_set_is_imported_and_fitted() {
    let dir = tempfile::tempdir().unwrap();
    let template =
        std::fs::read_to_string(repo("datasets/sources/copper-flash.capture.toml")).unwrap();
    // Dim flash: nothing clips. Bright flash: the highlights clip and are excluded.
    for (power, expect_clipping) in [("250.0", false), ("1500.0", true)] {
        let capture = dir.path().join(format!("capture-{power}.toml"));
        std::fs::write(&capture, template.replace("1500.0", power)).unwrap();
        let set = dir.path().join(format!("mg-{power}"));
        synth(
            &repo("datasets/sources/copper-a03.material.json"),
            &capture,
            &set,
            &["--format", "materialgan"],
        );
        assert!(set.join("camera_pos.txt").exists() && set.join("00.png").exists());
        let r = fit(&set, &[], dir.path());
        let saturated = r.fit["excluded"]["saturated"].as_u64().unwrap();
        assert_eq!(
            saturated > 0,
            expect_clipping,
            "saturated pixels: {saturated}"
        );
        assert_close("alpha", r.alpha[0], 0.3, 0.01);
        assert_f0(r.f0, [0.9352, 0.6235, 0.5383], 0.01);
        std::fs::remove_file(dir.path().join("fit.json")).unwrap();
    }
}

#[test]
fn log_l1_loss_recovers_alpha_too() {
    let dir = tempfile::tempdir().unwrap();
    let truth = read_json(&repo("datasets/copper-flash/material.json"));
    let r = fit(
        &repo("datasets/copper-flash"),
        &["--loss", "log-l1"],
        dir.path(),
    );
    assert_close(
        "alpha",
        r.alpha[0],
        truth["alpha"][0].as_f64().unwrap(),
        0.01,
    );
    assert_f0(r.f0, material_f0(&truth), 0.01);
    assert_eq!(r.fit["loss_kind"], "log-l1");
}

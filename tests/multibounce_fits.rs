//! Fits of photos rendered with the reference multi-bounce model `heitz` (issue "The fitter",
//! How we will know): a multi-bounce fit recovers the truth, `single` cannot and leaves a larger
//! loss. Metals: measured copper and gold (Johnson & Christy 1972 via
//! ../shared/data/conductors_nk.json, at 650 / 550 / 450 nm for R / G / B; the values are
//! written out in [`metal`], so the fits do not need `../shared`).

mod common;
use common::*;
use std::path::Path;

/// (eta, k, F0) per channel of copper (`Cu`) or gold (`Au`), Johnson & Christy 1972 at 650,
/// 550 and 450 nm as `../shared/data/conductors_nk.json` holds them (checked against it by
/// [`the_metals_are_the_shared_table`]), so the fits run where `../shared` is absent.
fn metal(symbol: &str) -> ([f64; 3], [f64; 3], [f64; 3]) {
    match symbol {
        "Cu" => (
            [0.23779860499422903, 1.0066270015586398, 1.240441180172678],
            [3.6264144295661427, 2.5823073079362238, 2.392941300328662],
            [0.9352180977478067, 0.6235100886473987, 0.5382577162627749],
        ),
        "Au" => (
            [0.15557377686501786, 0.42414932790070264, 1.3830881949423406],
            [3.602444957445625, 2.472050472462367, 1.9155000123907862],
            [0.9565222645090055, 0.7915532180129231, 0.4081937270148714],
        ),
        _ => panic!("no measured IOR for {symbol} in these tests"),
    }
}

/// The metals above are the shared table's values (skipped, with a message, where
/// `../shared` is absent).
#[test]
fn the_metals_are_the_shared_table() {
    let Some(path) = shared("data/conductors_nk.json") else {
        return;
    };
    let table = read_json(&path);
    for symbol in ["Cu", "Au"] {
        let values = table["metals"][symbol]["primary"]["values"]
            .as_array()
            .unwrap();
        let at = |nm: f64, key: &str| {
            values
                .iter()
                .find(|v| v["wavelength_nm"].as_f64() == Some(nm))
                .unwrap()[key]
                .as_f64()
                .unwrap()
        };
        let channels = |key: &str| [650.0, 550.0, 450.0].map(|nm| at(nm, key));
        let want = (
            channels("n"),
            channels("k"),
            channels("normal_incidence_reflectance"),
        );
        assert_eq!(metal(symbol), want, "{symbol}");
    }
}

/// A metal's conductor Fresnel as a material file's JSON and as a `--fresnel-known` value.
fn conductor(symbol: &str) -> (serde_json::Value, String) {
    let (eta, k, _) = metal(symbol);
    let known = format!(
        "conductor:{}:{}",
        eta.map(|v| v.to_string()).join(","),
        k.map(|v| v.to_string()).join(",")
    );
    (
        serde_json::json!({"kind": "conductor", "eta": eta, "k": k}),
        known,
    )
}

/// Nine 32x32 flash photos of `heitz` with the metal at `alpha`.
fn heitz_set(dir: &Path, symbol: &str, alpha: f64) -> std::path::PathBuf {
    model_set(dir, "heitz", symbol, alpha)
}

/// Nine 32x32 flash photos of `model` with the metal at `alpha`.
fn model_set(dir: &Path, model: &str, symbol: &str, alpha: f64) -> std::path::PathBuf {
    fresnel_set(dir, model, symbol, conductor(symbol).0, alpha)
}

/// Nine 32x32 flash photos of `model` with the Fresnel `fresnel` (a material file's `fresnel`
/// object, named `name`) at `alpha`.
fn fresnel_set(
    dir: &Path,
    model: &str,
    name: &str,
    fresnel: serde_json::Value,
    alpha: f64,
) -> std::path::PathBuf {
    let material = dir.join(format!("{name}.json"));
    std::fs::write(
        &material,
        serde_json::json!({"model": model, "alpha": [alpha, alpha], "fresnel": fresnel})
            .to_string(),
    )
    .unwrap();
    let capture = dir.join("small.toml");
    std::fs::write(
        &capture,
        std::fs::read_to_string(repo("datasets/sources/copper-flash.capture.toml"))
            .unwrap()
            .replace("resolution = [128, 128]", "resolution = [32, 32]"),
    )
    .unwrap();
    let set = dir.join(format!("{model}-{name}-{alpha}"));
    synth(&material, &capture, &set, &["--seed", "7"]);
    set
}

#[test]
fn heitz_fits_of_heitz_photos_are_unbiased() {
    // The fit renders heitz with its own random streams (seed 0; the photos used seed 7), twice,
    // and scores the pair loss (`bouncefit::loss`): scored on one render, the same fits came out
    // 13% low at alpha 0.5, since that loss also rewards a less noisy, less multiply
    // scattering render. Measured: alpha within 0.8%; F0 within 0.005 but for gold at alpha
    // 0.5, whose red F0 (0.957, nearly white) comes out 0.0087 high without the bounce cap and
    // 0.0104 with it (cap 5: its walks draw other random numbers once one is cut, and the cap
    // drops up to ~5e-4 of the energy, which a higher F0 makes up), hence 0.015.
    let dir = tempfile::tempdir().unwrap();
    for symbol in ["Cu", "Au"] {
        let (_, _, f0_truth) = metal(symbol);
        for alpha in [0.2, 0.5] {
            let set = heitz_set(dir.path(), symbol, alpha);
            let fit = fit_json(&set, &["--models", "heitz"], dir.path());
            let fitted = fit["alpha"][0].as_f64().unwrap();
            assert!(
                ((fitted - alpha) / alpha).abs() < 0.01,
                "{symbol} {alpha}: alpha {fitted}"
            );
            let f0 = triple(&fit["f0"]);
            for c in 0..3 {
                assert!(
                    (f0[c] - f0_truth[c]).abs() < 0.015,
                    "{symbol} {alpha}: F0 {f0:?} vs {f0_truth:?}"
                );
            }
        }
    }
}

#[test]
fn multi_bounce_fits_recover_heitz_photos_that_single_cannot() {
    let dir = tempfile::tempdir().unwrap();
    for symbol in ["Cu", "Au"] {
        let (_, _, f0_truth) = metal(symbol);
        let alpha = 0.5;
        let set = heitz_set(dir.path(), symbol, alpha);
        let multi = fit_json(&set, &["--models", "kulla-conty"], dir.path());
        let single = fit_json(&set, &["--models", "single"], dir.path());
        let alpha_of = |f: &serde_json::Value| f["alpha"][0].as_f64().unwrap();
        let loss_of = |f: &serde_json::Value| f["loss"].as_f64().unwrap();
        // Measured: kulla-conty -1.4% (Cu) and -1.5% (Au); F0 within 0.005.
        let error = (alpha_of(&multi) - alpha) / alpha;
        assert!(error.abs() < 0.03, "{symbol}: alpha {}", alpha_of(&multi));
        let f0 = triple(&multi["f0"]);
        for c in 0..3 {
            assert!(
                (f0[c] - f0_truth[c]).abs() < 0.02,
                "{symbol}: F0 {f0:?} vs {f0_truth:?}"
            );
        }
        // single makes up for the missing energy with a narrower, brighter lobe (measured
        // -13% alpha) and still fits worse (measured loss 1.4x).
        assert!(
            (alpha_of(&single) - alpha) / alpha < -0.05,
            "{symbol}: single alpha {}",
            alpha_of(&single)
        );
        assert!(
            loss_of(&single) > 1.2 * loss_of(&multi),
            "{symbol}: single loss {} vs multi {}",
            loss_of(&single),
            loss_of(&multi)
        );
    }
}

/// The bounce cap (on by default) leaves a fit where it was: photos of `bitterli` rendered
/// without a cap at alpha 0.5, fitted with `bitterli` with the cap (5 reflections there) and
/// with `--no-skip bounce-cap`. Measured: both alpha -1.1%, equal to 1e-13 (walks past 5
/// reflections are rare at this roughness); F0 within 0.01. (At alpha 0.9, cap 8, the two fits
/// differed by 1.9%, both 10-12% low with one sample per pixel: the pair loss's noise, not the
/// cap, dominates there.)
#[test]
fn capped_walks_still_recover_the_roughness() {
    let dir = tempfile::tempdir().unwrap();
    let (_, _, f0_truth) = metal("Cu");
    let alpha = 0.5;
    let set = model_set(dir.path(), "bitterli", "Cu", alpha);
    // Directly on the model's walks: the defect correction renders without a cap.
    let direct = ["--models", "bitterli", "--stochastic-fit", "direct"];
    let capped = fit_json(&set, &direct, dir.path());
    let free = fit_json(
        &set,
        &[&direct[..], &["--no-skip", "bounce-cap"]].concat(),
        dir.path(),
    );
    let cap = capped["render_plan"]["bounce_cap"].as_u64();
    assert!(cap.is_some_and(|k| k >= 2), "{}", capped["render_plan"]);
    assert!(free["render_plan"]["bounce_cap"].is_null());
    let alpha_of = |f: &serde_json::Value| f["alpha"][0].as_f64().unwrap();
    let fitted = alpha_of(&capped);
    assert!(((fitted - alpha) / alpha).abs() < 0.02, "alpha {fitted}");
    assert!(
        ((fitted - alpha_of(&free)) / alpha).abs() < 0.005,
        "capped {fitted} vs free {}",
        alpha_of(&free)
    );
    let f0 = triple(&capped["f0"]);
    for c in 0..3 {
        assert!(
            (f0[c] - f0_truth[c]).abs() < 0.01,
            "F0 {f0:?} vs {f0_truth:?}"
        );
    }
}

/// Issue #16 item 3: the analytic `tabulated` model fits photos of `heitz` where multiple
/// scattering carries much of the light, 32x32, one sample per pixel: at alpha 0.9 white
/// (`--fresnel-known white`) and copper (Schlick F0 fitted), and copper's conductor Fresnel
/// known at alpha 1.5, where the Fresnel weighting of the long walks decides. Measured: white
/// 0.9037 (+0.4%), copper 0.9216 (+2.4%, F0 and alpha trading along the flash set's valley;
/// 0.8901 with the old weights), known copper 1.5033 (+0.2%; 1.4226, -5.2%, with Kulla &
/// Conty's `F_avg^k` weights that `vertex_fresnel` replaced). On the alpha-0.9 photos
/// `bitterli` fitted directly on its walks gave 0.739 and 0.802 (issue #16's low rough fits,
/// which the defect correction of `corrected_stochastic_fits_of_rough_heitz_photos_are_unbiased`
/// removes), `kulla-conty` 0.811 and 2.63, `single` 0.432 and 0.480.
#[test]
fn tabulated_fits_of_rough_heitz_photos_recover_alpha() {
    let dir = tempfile::tempdir().unwrap();
    let (copper, copper_known) = conductor("Cu");
    for (name, fresnel, extra, alpha, tolerance) in [
        (
            "white",
            serde_json::json!({"kind": "white"}),
            vec!["--fresnel-known", "white"],
            0.9,
            0.03,
        ),
        ("Cu", copper.clone(), vec![], 0.9, 0.03),
        (
            "Cu-known",
            copper,
            vec!["--fresnel-known", copper_known.as_str()],
            1.5,
            0.02,
        ),
    ] {
        let set = fresnel_set(dir.path(), "heitz", name, fresnel, alpha);
        let mut args = vec!["--models", "tabulated"];
        args.extend(extra);
        let fit = fit_json(&set, &args, dir.path());
        let fitted = fit["alpha"][0].as_f64().unwrap();
        eprintln!("{name}: tabulated alpha {fitted}");
        assert!(
            ((fitted - alpha) / alpha).abs() < tolerance,
            "{name}: alpha {fitted} against {alpha}"
        );
    }
}

/// Issue #16 item 2: the stochastic models that claim `heitz`'s value, fitted by their default
/// defect correction on `tabulated` (`bouncefit::fit::point::corrected`) with one sub-sample
/// per pixel, recover the roughness of rough `heitz` photos with the Fresnel known: white at
/// alpha 0.9 and copper at 1.5. Measured (`bitterli`): white 0.9182 (+2.0%; 0.9138-0.9171
/// over the defect's seeds 0-7 from the start before the roughness profile, each reporting
/// 0.12-0.27% of walks' noise), copper 1.5021
/// (+0.14%), settled in 1 round (white 0.9078 before the seeds' streams were made disjoint,
/// on other walks); fitted directly on their own walks at one sub-sample
/// (`--stochastic-fit direct --no-skip sparse-multi`) the white set came out at 0.76-0.95,
/// mean 0.81 over 8 seeds, and with the anchors at 0.55-0.69.
#[test]
fn corrected_stochastic_fits_of_rough_heitz_photos_are_unbiased() {
    let dir = tempfile::tempdir().unwrap();
    let (copper, copper_known) = conductor("Cu");
    for (name, fresnel, known, alpha) in [
        (
            "white",
            serde_json::json!({"kind": "white"}),
            "white".to_string(),
            0.9,
        ),
        ("Cu", copper, copper_known, 1.5),
    ] {
        let set = fresnel_set(dir.path(), "heitz", name, fresnel, alpha);
        for model in ["bitterli", "cui"] {
            let fit = fit_json(
                &set,
                &[
                    "--models",
                    model,
                    "--fresnel-known",
                    &known,
                    "--pixel-samples",
                    "1",
                ],
                dir.path(),
            );
            let fitted = fit["alpha"][0].as_f64().unwrap();
            let correction = &fit["correction"];
            eprintln!("{name} {alpha} {model}: alpha {fitted}, rounds {correction}");
            assert_eq!(fit["model"], model);
            assert_eq!(correction["surrogate"], "tabulated");
            assert!(correction["alpha_rounds"].as_array().unwrap().len() >= 2);
            // The walks' noise is reported, and too small to pass a 2% miss off as noise.
            let noise = correction["alpha_noise"][0]
                .as_f64()
                .expect("the noise is reported");
            assert!(
                noise > 0.0 && 3.0 * noise < 0.02,
                "{name} {model}: noise {noise}"
            );
            // A 2% bound on the bias, plus three of the walks' own standard deviations: the
            // white set sits at +1.9% to +2.0%, and which side of 2% it lands on depends on
            // the paths its walks draw (the surrogate's start moving alpha by 2e-5 moved the
            // corrected alpha from 0.9171 to 0.9182, 1.5 of its reported 0.13%).
            assert!(
                ((fitted - alpha) / alpha).abs() < 0.02 + 3.0 * noise,
                "{name} {model}: alpha {fitted} against {alpha} (walks' noise {noise})"
            );
        }
    }
}

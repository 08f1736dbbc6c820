//! Material maps (issue #17): synthetic spatially varying photo sets made by `synth` from known
//! maps, fitted back with `fit --maps`; maps files' round trip and bad input.

mod common;

use bouncefit::bsdf::Model;
use bouncefit::maps::{AnyMaterial, MaterialMaps};
use common::maps_truth::maps_of_materials;
use common::{png_size, read_json, repo, run_bad, run_ok, strings, synth, triple};
use std::path::{Path, PathBuf};

/// Rough copper (the multi-bounce case: alpha 0.65) and a glossy red paint.
const METAL: ([f64; 3], f64, [f64; 3]) = ([0.955, 0.638, 0.538], 0.65, [0.0; 3]);
const PAINT_ALPHA: f64 = 0.15;
const PAINT_F0: [f64; 3] = [0.04; 3];

/// The truth: a disc and a band of rough copper on paint whose albedo varies across the
/// sample, on a `side` x `side` texel grid.
fn truth_maps(model: Model, side: usize) -> MaterialMaps {
    maps_of_materials(model, side, |u, v| {
        if (u - 0.55).powi(2) + (v - 0.5).powi(2) < 0.28f64.powi(2) || v < 0.15 {
            METAL
        } else {
            (PAINT_F0, PAINT_ALPHA, [0.55, 0.2 + 0.25 * u, 0.12])
        }
    })
}

/// The copper-flash template (9 rectified flash photos of an 8 cm sample) at `side` pixels,
/// and a tenth photo unlike them: camera and a point light on opposite sides, 50 and 45
/// degrees from the normal (photo 9, the held-out one).
fn flash_template(dir: &Path, side: usize) -> PathBuf {
    let text = std::fs::read_to_string(repo("datasets/sources/copper-flash.capture.toml"))
        .unwrap()
        .replace(
            "resolution = [128, 128]",
            &format!("resolution = [{side}, {side}]"),
        )
        + r#"
[[photo]]
image = "09.exr"
camera = { position = [13.0, 4.0, 12.0] }
light = { kind = "point", position = [-10.0, -5.0, 11.0], intensity = [3000.0, 3000.0, 3000.0] }
"#;
    let path = dir.join(format!("flash-{side}.capture.toml"));
    std::fs::write(&path, text).unwrap();
    path
}

/// The truth maps (kulla-conty) at `side` texels rendered into `dir/set` by the flash template
/// at `side` pixels, with 1% noise.
fn truth_set(dir: &Path, side: usize) -> (MaterialMaps, PathBuf) {
    truth_set_of(Model::KullaConty, dir, side, &[])
}

/// [`truth_set`] with the truth's model `model` and more `synth` options `extra`.
fn truth_set_of(model: Model, dir: &Path, side: usize, extra: &[&str]) -> (MaterialMaps, PathBuf) {
    truth_set_from(truth_maps(model, side), dir, side, extra)
}

/// The photo set of the maps `truth` (`side` texels): as [`truth_set_of`].
fn truth_set_from(
    truth: MaterialMaps,
    dir: &Path,
    side: usize,
    extra: &[&str],
) -> (MaterialMaps, PathBuf) {
    let capture = flash_template(dir, side);
    truth_set_captured(truth, dir, &capture, extra)
}

/// The photo set of the maps `truth` taken by the capture template `capture`, into `dir/set`,
/// with 1% noise unless `extra` (more `synth` options) says otherwise.
fn truth_set_captured(
    truth: MaterialMaps,
    dir: &Path,
    capture: &Path,
    extra: &[&str],
) -> (MaterialMaps, PathBuf) {
    let material = dir.join("truth.json");
    truth.save(&material, Default::default()).unwrap();
    let set = dir.join("set");
    let mut options = if extra.contains(&"--noise") {
        vec![]
    } else {
        vec!["--noise", "0.01"]
    };
    options.extend_from_slice(extra);
    synth(&material, capture, &set, &options);
    (truth, set)
}

fn load_maps(path: &Path) -> MaterialMaps {
    match AnyMaterial::load_with_warnings(path).unwrap().0 {
        AnyMaterial::Maps(maps) => maps,
        AnyMaterial::Uniform(_) => panic!("{} holds no maps", path.display()),
    }
}

/// RMS over texels and channels of `a - b`.
fn rms(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    let sum: f64 = a
        .iter()
        .zip(b)
        .flat_map(|(x, y)| (0..3).map(move |c| (x[c] - y[c]).powi(2)))
        .sum();
    (sum / (3 * a.len()) as f64).sqrt()
}

/// The errors of fitted maps `got` against `truth`: roughness RMSE (over texels and both
/// axes), diffuse albedo RMS and F0 RMS over texels (and channels).
fn map_errors(got: &MaterialMaps, truth: &MaterialMaps) -> [f64; 3] {
    let (a, b) = (
        got.roughness.as_ref().unwrap(),
        truth.roughness.as_ref().unwrap(),
    );
    let alpha_rmse = (a
        .iter()
        .zip(b)
        .flat_map(|(x, y)| [(x[0] - y[0]).powi(2), (x[1] - y[1]).powi(2)])
        .sum::<f64>()
        / (2 * a.len()) as f64)
        .sqrt();
    [
        alpha_rmse,
        rms(
            got.diffuse.as_ref().unwrap(),
            truth.diffuse.as_ref().unwrap(),
        ),
        rms(
            got.specular.as_ref().unwrap(),
            truth.specular.as_ref().unwrap(),
        ),
    ]
}

/// `bouncefit fit SET --maps ...` into `out/NAME.json`; the fit file.
fn fit_maps(set: &Path, out: &Path, name: &str, extra: &[&str]) -> serde_json::Value {
    let path = out.join(format!("{name}.json"));
    let mut args = vec![
        "fit",
        set.to_str().unwrap(),
        "--maps",
        "-o",
        path.to_str().unwrap(),
        "--quiet",
    ];
    args.extend_from_slice(extra);
    run_ok(&args);
    read_json(&path)
}

/// Issue #17's synthetic truth: two basis materials, one rough metal (alpha 0.65) rendered with
/// the multi-bounce `kulla-conty`, 9 flash photos, 1% noise, fitted back with the same model;
/// the bounds are the issue's (roughness RMSE 0.03, albedo and F0 0.02 RMS). Measured at
/// 128^2: alpha RMSE 0.007, albedo 0.002, F0 0.003; held-out error 0.017 against 0.138 for
/// `single` maps.
#[test]
fn maps_fits_recover_known_maps_and_single_bounce_predicts_worse() {
    // 128 x 128 keeps the suite fast; `scripts/maps-synthetic.sh` runs the same at 256.
    let side = std::env::var("BOUNCEFIT_MAPS_SIDE")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(128);
    let dir = tempfile::tempdir().unwrap();
    let (truth, set) = truth_set(dir.path(), side);
    let fit = fit_maps(
        &set,
        dir.path(),
        "kulla-conty",
        &["--models", "kulla-conty", "--holdout-photo", "9"],
    );
    let got = load_maps(&dir.path().join("kulla-conty.json"));
    let [alpha_rmse, diffuse_rms, f0_rms] = map_errors(&got, &truth);
    let held_out = fit["holdout"]["relative_error"].as_f64().unwrap();
    eprintln!(
        "kulla-conty maps: alpha RMSE {alpha_rmse:.4}, diffuse RMS {diffuse_rms:.4}, F0 RMS \
         {f0_rms:.4}, held-out relative error {held_out:.4}, bases {}, {:.1} s",
        fit["maps_fit"]["bases"].as_array().unwrap().len(),
        fit["maps_fit"]["seconds"]
    );
    assert!(alpha_rmse <= 0.03, "roughness map RMSE {alpha_rmse}");
    assert!(diffuse_rms <= 0.02, "albedo map RMS {diffuse_rms}");
    assert!(f0_rms <= 0.02, "F0 map RMS {f0_rms}");
    // The roughness floor chosen by the validation photo leaves the truly sharp paint (alpha
    // 0.15) as sharp as it is.
    let floor = fit["maps_fit"]["roughness_floor"].as_f64();
    assert!(floor.is_none_or(|f| f <= 0.15), "roughness floor {floor:?}");
    // The file's top-level material describes the material, not one texel: each component is
    // the texels' median, here the majority's (truth's median alpha), whatever texel 0 is.
    let median = |maps: &MaterialMaps, value: &dyn Fn(&MaterialMaps, usize) -> f64| {
        let n = maps.grid.width * maps.grid.height;
        let mut v: Vec<f64> = (0..n).map(|t| value(maps, t)).collect();
        v.sort_by(f64::total_cmp);
        v[n / 2]
    };
    let top_alpha = fit["alpha"][0].as_f64().unwrap();
    let fitted_median = median(&got, &|m, t| m.texel(t).alpha[0]);
    let truth_median = median(&truth, &|m, t| m.texel(t).alpha[0]);
    // (The map is read back from a float EXR.)
    assert!(
        (top_alpha / fitted_median - 1.0).abs() < 1e-6,
        "{top_alpha} vs {fitted_median}"
    );
    assert!(
        (top_alpha - truth_median).abs() < 0.03,
        "{top_alpha} vs {truth_median}"
    );
    let top_f0 = fit["fresnel"]["f0"][0].as_f64().unwrap();
    let truth_f0 = median(&truth, &|m, t| m.texel(t).fresnel.f0()[0]);
    assert!(
        (top_f0 - truth_f0).abs() < 0.02,
        "F0 {top_f0} vs {truth_f0}"
    );

    // The same photos fitted with the single-bounce model: the rough copper's missing multiple
    // scattering cannot be made up per texel, and the held-out photo shows it.
    let single = fit_maps(
        &set,
        dir.path(),
        "single",
        &["--models", "single", "--holdout-photo", "9"],
    );
    let single_held_out = single["holdout"]["relative_error"].as_f64().unwrap();
    eprintln!("single maps: held-out relative error {single_held_out:.4}");
    assert!(
        single_held_out > 1.5 * held_out,
        "single {single_held_out} vs kulla-conty {held_out}"
    );
}

/// Photos each exposed by their own gain (a phone's auto-exposure, 0.85-1.15) that the set does
/// not record: `--photo-gains` finds every training photo's gain (relative to their geometric
/// mean, the gauge the albedos take) within 1%, and the maps fit the photos better for it
/// (measured at 48^2, 1% noise: training error 0.0917 without, 0.0088 with).
#[test]
fn photo_gains_recover_each_photos_unrecorded_exposure() {
    let dir = tempfile::tempdir().unwrap();
    let side = 48;
    let exposures = [1.0, 0.87, 1.12, 0.95, 1.15, 0.85, 1.05, 0.9, 1.08, 1.0];
    let mut photo = 0;
    let template: String = std::fs::read_to_string(flash_template(dir.path(), side))
        .unwrap()
        .lines()
        .map(|line| {
            let mut line = format!("{line}\n");
            if line.starts_with("light = ") {
                line += &format!("exposure = {}\n", exposures[photo]);
                photo += 1;
            }
            line
        })
        .collect();
    assert_eq!(photo, 10);
    let capture = dir.path().join("auto-exposed.capture.toml");
    std::fs::write(&capture, template).unwrap();
    let (_, set) = truth_set_captured(
        truth_maps(Model::KullaConty, side),
        dir.path(),
        &capture,
        &[],
    );
    // The set as a phone writes it: every photo at the nominal exposure.
    let manifest = set.join("capture.toml");
    let nominal: String = std::fs::read_to_string(&manifest)
        .unwrap()
        .lines()
        .map(|line| match line.starts_with("exposure = ") {
            true => "exposure = 1.0\n".to_string(),
            false => format!("{line}\n"),
        })
        .collect();
    std::fs::write(&manifest, nominal).unwrap();
    let args = ["--models", "kulla-conty", "--holdout-photo", "9"];
    let plain = fit_maps(&set, dir.path(), "plain", &args);
    let calibrated = fit_maps(
        &set,
        dir.path(),
        "gains",
        &[&args[..], &["--photo-gains"]].concat(),
    );
    let training = &exposures[..9];
    let mean = (training.iter().map(|e: &f64| e.ln()).sum::<f64>() / 9.0).exp();
    let gains = calibrated["photo_gains"].as_array().unwrap();
    for (i, entry) in gains.iter().enumerate() {
        let want = if i == 9 { 1.0 } else { exposures[i] / mean };
        let got = triple(&entry["gain"]);
        assert!(
            got.iter().all(|g| (g / want - 1.0).abs() < 0.01),
            "photo {i}: gain {got:?} vs {want}"
        );
    }
    let error = |fit: &serde_json::Value| fit["maps_fit"]["train_error"].as_f64().unwrap();
    eprintln!(
        "training error {:.4} without photo gains, {:.4} with",
        error(&plain),
        error(&calibrated)
    );
    assert!(error(&calibrated) < 0.5 * error(&plain));
}

/// Maps fits of noisy photos keep the bases' roughness: the truth rendered at 64^2 with 5%
/// noise, fitted on its 9 flash photos (the oblique tenth held out). The precision-weighted
/// mean of the texels' estimates, which the bases were before their pooled refit, puts the
/// copper at 0.637 at 5% noise and 0.606 at 10% (docs/maps.md, "Noisy photos"); the pooled
/// maximum-likelihood bases come out at 0.649-0.651 and 0.149-0.150 on noise seeds 0-3. At
/// 10% noise the copper's texels are as well fitted as dielectrics, and in 2 of those 4 seeds
/// the copper is reported as one (1 of 4 before the metal F0 prior): that limit is stated in
/// docs/maps.md, not tested.
#[test]
fn noisy_photos_leave_the_bases_roughness_unbiased() {
    let dir = tempfile::tempdir().unwrap();
    let (_, set) = truth_set_of(Model::KullaConty, dir.path(), 64, &["--noise", "0.05"]);
    let options = ["--models", "kulla-conty", "--holdout-photo", "9"];
    let fit = fit_maps(&set, dir.path(), "noisy", &options);
    let bases = fit["maps_fit"]["bases"].as_array().unwrap();
    let alpha_of = |kind: &str, truth: f64| {
        bases
            .iter()
            .filter(|b| b["kind"] == kind)
            .map(|b| b["alpha"].as_f64().unwrap())
            .min_by(|a, b| (a - truth).abs().total_cmp(&(b - truth).abs()))
            .unwrap_or_else(|| panic!("no {kind} basis in {bases:?}"))
    };
    let (metal, paint) = (
        alpha_of("metal", METAL.1),
        alpha_of("dielectric", PAINT_ALPHA),
    );
    eprintln!("5% noise: metal basis alpha {metal:.4}, paint {paint:.4}");
    assert!(
        (metal / METAL.1 - 1.0).abs() < 0.01,
        "metal basis alpha {metal}"
    );
    assert!(
        (paint / PAINT_ALPHA - 1.0).abs() < 0.03,
        "paint basis alpha {paint}"
    );
}

/// Brushed copper: the truth's metal rougher along y (alpha 0.4 by 0.9), the paint isotropic,
/// 9 flash photos at 64^2 with 1% noise. `--anisotropic` fits `alpha_x` and `alpha_y` per
/// texel and gets both axes of both bases back; the isotropic fit of the same photos cannot
/// reproduce them. Measured: copper basis [0.3999, 0.8999], paint [0.1501, 0.1501]; per-texel
/// roughness RMSE 0.019 over both axes (albedo 0.002, F0 0.005); training error 0.0084
/// against 0.062 isotropic.
#[test]
fn anisotropic_maps_recover_the_roughness_along_each_axis() {
    const BRUSHED: [f64; 2] = [0.4, 0.9];
    let side = 64;
    let dir = tempfile::tempdir().unwrap();
    let mut truth = truth_maps(Model::KullaConty, side);
    for alpha in truth.roughness.as_mut().unwrap() {
        if *alpha == [METAL.1; 2] {
            *alpha = BRUSHED;
        }
    }
    let (truth, set) = truth_set_from(truth, dir.path(), side, &[]);
    let options = ["--models", "kulla-conty", "--holdout-photo", "9"];
    let isotropic = fit_maps(&set, dir.path(), "isotropic", &options);
    let mut anisotropic_options = options.to_vec();
    anisotropic_options.push("--anisotropic");
    let fit = fit_maps(&set, dir.path(), "anisotropic", &anisotropic_options);
    let bases = fit["maps_fit"]["bases"].as_array().unwrap();
    let axes_of = |kind: &str| -> [f64; 2] {
        let basis = bases
            .iter()
            .find(|b| b["kind"] == kind)
            .unwrap_or_else(|| panic!("no {kind} basis in {bases:?}"));
        serde_json::from_value(basis["alpha_xy"].clone()).unwrap()
    };
    let (metal, paint) = (axes_of("metal"), axes_of("dielectric"));
    let got = load_maps(&dir.path().join("anisotropic.json"));
    let [alpha_rmse, albedo_rms, f0_rms] = map_errors(&got, &truth);
    let train = |f: &serde_json::Value| f["maps_fit"]["train_error"].as_f64().unwrap();
    eprintln!(
        "anisotropic maps: metal basis {metal:?}, paint {paint:?}; roughness RMSE {alpha_rmse:.4}, \
         albedo {albedo_rms:.4}, F0 {f0_rms:.4}; training error {:.4} against {:.4} isotropic; \
         held-out {:.4} against {:.4}",
        train(&fit),
        train(&isotropic),
        fit["holdout"]["relative_error"].as_f64().unwrap(),
        isotropic["holdout"]["relative_error"].as_f64().unwrap()
    );
    for axis in 0..2 {
        assert!(
            (metal[axis] / BRUSHED[axis] - 1.0).abs() < 0.03,
            "metal {metal:?}"
        );
        assert!(
            (paint[axis] / PAINT_ALPHA - 1.0).abs() < 0.05,
            "paint {paint:?}"
        );
    }
    assert!(got.is_anisotropic());
    assert!(alpha_rmse <= 0.03 && albedo_rms <= 0.02 && f0_rms <= 0.02);
    assert!(
        train(&fit) < 0.5 * train(&isotropic),
        "the isotropic fit cannot reproduce the brushed metal"
    );
}

/// Unit normals tilted by slope `SLOPE` (14 degrees) toward +x and -x in alternating bands
/// of `BAND` texels across the sample: a corrugated surface.
fn corrugated(mut maps: MaterialMaps) -> MaterialMaps {
    const SLOPE: f64 = 0.25;
    const BAND: usize = 4;
    let side = maps.grid.width;
    maps.normal = Some(
        (0..maps.grid.len())
            .map(|t| {
                let p = if (t % side) / BAND % 2 == 0 {
                    SLOPE
                } else {
                    -SLOPE
                };
                let norm = (1.0 + p * p).sqrt();
                [p / norm, 0.0, 1.0 / norm]
            })
            .collect(),
    );
    maps
}

/// `--normals=auto` fits maps with and without a normal per texel on the photos other than the
/// validation photo and keeps normals only where they predict it better by more than 2%: on
/// the flat truth it keeps none; on the same truth corrugated (normals tilted 14 degrees in
/// bands of 4 texels) it keeps them, and they come back. Measured at 32^2: flat, validation
/// errors 0.0187 without normals and 0.0248 with; corrugated, 0.154 without and 0.0204 with,
/// median angular error of the fitted normals 0.58 degrees.
#[test]
fn normals_auto_keeps_normals_only_where_the_sample_has_them() {
    let side = 32;
    let options = [
        "--models",
        "kulla-conty",
        "--normals=auto",
        "--holdout-photo",
        "9",
    ];
    let flat_dir = tempfile::tempdir().unwrap();
    let (_, flat_set) = truth_set(flat_dir.path(), side);
    let flat = fit_maps(&flat_set, flat_dir.path(), "flat", &options);
    let trial = &flat["maps_fit"]["normals_trial"];
    eprintln!("flat: normals trial {trial}");
    assert_eq!(flat["maps_fit"]["normals"], false, "flat truth: {trial}");

    let dir = tempfile::tempdir().unwrap();
    let truth = corrugated(truth_maps(Model::KullaConty, side));
    let (truth, set) = truth_set_from(truth, dir.path(), side, &[]);
    let fit = fit_maps(&set, dir.path(), "corrugated", &options);
    let trial = &fit["maps_fit"]["normals_trial"];
    assert_eq!(
        fit["maps_fit"]["normals"], true,
        "corrugated truth: {trial}"
    );
    let got = load_maps(&dir.path().join("corrugated.json"));
    let (got, truth) = (got.normal.unwrap(), truth.normal.unwrap());
    let mut angles: Vec<f64> = got
        .iter()
        .zip(&truth)
        .map(|(a, b)| {
            let cos = (0..3).map(|c| a[c] * b[c]).sum::<f64>();
            cos.clamp(-1.0, 1.0).acos().to_degrees()
        })
        .collect();
    angles.sort_by(f64::total_cmp);
    let median = angles[angles.len() / 2];
    eprintln!("corrugated: normals trial {trial}, median normal error {median:.2} degrees");
    assert!(median < 4.0, "median angular error {median} degrees");
}

/// Heitz's lobe per texel (issue #17 item 2, through issue #16's `tabulated`): the truth maps
/// rendered by `heitz` itself, its random walk at every sub-sample (1024 walks per pixel, 1%
/// noise), fitted back with `tabulated`. The rough copper's roughness comes back unbiased: its
/// basis and the median over its texels within 2% of the truth. Measured at 32^2: basis 0.6469
/// and median 0.6510 against 0.65 (`kulla-conty` maps of the same photos: basis 0.6354, -2.3%;
/// with 256 walks per pixel, `tabulated`'s basis 0.6423). The per-texel bounds of the test above
/// are not asserted here: at 32^2 the texels astride the disc's edge dominate them even for
/// `tabulated` photos fitted with `tabulated` (alpha RMSE 0.013, albedo RMS 0.020, F0 0.022),
/// and on `heitz`'s photos they are larger still (alpha RMSE 0.050 at 256 walks per pixel,
/// 0.043 at 1024).
#[test]
fn tabulated_maps_recover_the_roughness_of_photos_rendered_by_heitzs_walk() {
    let side = 32;
    let dir = tempfile::tempdir().unwrap();
    let (truth, set) = truth_set_of(Model::Heitz, dir.path(), side, &["--pixel-samples", "1024"]);
    let fit = fit_maps(
        &set,
        dir.path(),
        "tabulated",
        &["--models", "tabulated", "--holdout-photo", "9"],
    );
    let got = load_maps(&dir.path().join("tabulated.json"));
    let basis = fit["maps_fit"]["bases"]
        .as_array()
        .unwrap()
        .iter()
        .map(|b| b["alpha"].as_f64().unwrap())
        .fold(0.0, f64::max);
    let (fitted, true_alpha) = (
        got.roughness.as_ref().unwrap(),
        truth.roughness.as_ref().unwrap(),
    );
    let mut copper: Vec<f64> = (0..fitted.len())
        .filter(|&t| true_alpha[t] == [METAL.1; 2])
        .map(|t| fitted[t][0])
        .collect();
    copper.sort_by(f64::total_cmp);
    let median = copper[copper.len() / 2];
    eprintln!(
        "tabulated maps of heitz photos: copper basis alpha {basis:.4}, median over {} copper \
         texels {median:.4}, held-out relative error {:.4}",
        copper.len(),
        fit["holdout"]["relative_error"].as_f64().unwrap()
    );
    for (what, alpha) in [("basis", basis), ("median texel", median)] {
        assert!(
            (alpha / METAL.1 - 1.0).abs() < 0.02,
            "copper {what} alpha {alpha} against {}",
            METAL.1
        );
    }
}

/// One basis for two materials (`--bases 1`): the basis sets the roughness prior, but each
/// texel stays the kind its own photos show. Before, every texel took its basis's kind, so with
/// one basis the copper became a dielectric (F0 pulled to 0.04, its colour moved into the
/// albedo) or, on the real bath tile, the grout a metal. Measured at 32^2: paint albedo RMS
/// 0.0027, copper F0 RMS 0.021, copper albedo 0.020 (with each texel of its basis's kind:
/// copper F0 0.26, copper albedo 0.28).
#[test]
fn one_basis_keeps_each_texels_kind() {
    let dir = tempfile::tempdir().unwrap();
    let (truth, set) = truth_set(dir.path(), 32);
    fit_maps(
        &set,
        dir.path(),
        "one-basis",
        &["--models", "kulla-conty", "--bases", "1"],
    );
    let got = load_maps(&dir.path().join("one-basis.json"));
    let metal: Vec<bool> = truth
        .specular
        .as_ref()
        .unwrap()
        .iter()
        .map(|f0| f0[0] > 0.5)
        .collect();
    let part = |maps: &MaterialMaps, of_metal: bool, specular: bool| -> Vec<[f64; 3]> {
        let values = if specular {
            &maps.specular
        } else {
            &maps.diffuse
        };
        values
            .as_ref()
            .unwrap()
            .iter()
            .zip(&metal)
            .filter(|(_, &m)| m == of_metal)
            .map(|(v, _)| *v)
            .collect()
    };
    let paint_albedo = rms(&part(&got, false, false), &part(&truth, false, false));
    let copper_f0 = rms(&part(&got, true, true), &part(&truth, true, true));
    let copper_albedo = rms(&part(&got, true, false), &part(&truth, true, false));
    eprintln!(
        "one basis: paint albedo RMS {paint_albedo:.4}, copper F0 RMS {copper_f0:.4}, copper \
         albedo RMS {copper_albedo:.4}"
    );
    assert!(paint_albedo <= 0.03, "paint albedo RMS {paint_albedo}");
    assert!(copper_f0 <= 0.03, "copper F0 RMS {copper_f0}");
    assert!(copper_albedo <= 0.03, "copper albedo RMS {copper_albedo}");
}

/// The bundled `datasets/two-materials` (rough copper on a red paint, 128^2 photos) at texel
/// grids coarser than its photos: both materials are found, and no basis without texels is
/// reported. Before, `single` maps kept one basis at 32^2 (the copper basis gained 1.8% of
/// the validation photo's per-pixel error, under the 2% margin, because that error was mostly
/// the detail within each 4 x 4 pixel texel), and at 48^2 reported three bases, one of them a
/// metal with no texel. The validation error is now taken at the texels' resolution and
/// empty bases are dropped (docs/maps.md, "The number of bases").
#[test]
fn coarse_texel_grids_find_both_materials_of_the_bundled_set() {
    let dir = tempfile::tempdir().unwrap();
    let set = repo("datasets/two-materials");
    for (model, texels) in [
        ("single", "32x32"),
        ("single", "48x48"),
        ("kulla-conty", "32x32"),
    ] {
        let name = format!("{model}-{texels}");
        let fit = fit_maps(
            &set,
            dir.path(),
            &name,
            &["--models", model, "--texels", texels],
        );
        let bases = fit["maps_fit"]["bases"].as_array().unwrap();
        let summary: Vec<(f64, f64)> = bases
            .iter()
            .map(|b| (b["alpha"].as_f64().unwrap(), b["share"].as_f64().unwrap()))
            .collect();
        eprintln!("{name}: bases (alpha, share) {summary:?}");
        assert_eq!(bases.len(), 2, "{name}: bases {summary:?}");
        assert!(
            summary.iter().all(|&(_, share)| share > 0.0),
            "{name}: {summary:?}"
        );
        // The copper is the rougher basis, on about 37% of the texels.
        let (copper, share) = summary
            .iter()
            .copied()
            .max_by(|a, b| a.0.total_cmp(&b.0))
            .unwrap();
        assert!((0.3..0.45).contains(&share), "{name}: copper share {share}");
        if model == "kulla-conty" {
            assert!(
                (copper / METAL.1 - 1.0).abs() < 0.03,
                "{name}: copper alpha {copper}"
            );
        } else {
            // `single` makes up the copper's missing multiple scattering with a narrower lobe.
            assert!(copper > 0.3, "{name}: copper alpha {copper}");
        }
    }
}

/// A truth of three materials (docs/maps.md, "The number of bases"): a gold ellipse (metal,
/// alpha 0.4, F0 (`red`, 0.78, 0.34), 21% of the texels) and a stripe of grey ceramic
/// (dielectric, alpha 0.35, albedo 0.6, 13%) on a blue paint (dielectric, alpha 0.15, albedo
/// (0.08, 0.18, 0.45)), on a `side` x `side` texel grid.
fn three_material_truth(side: usize, red: f64) -> MaterialMaps {
    let gold = ([red, 0.78, 0.34], 0.4, [0.0; 3]);
    let ceramic = ([0.04; 3], 0.35, [0.6; 3]);
    let paint = ([0.04; 3], PAINT_ALPHA, [0.08, 0.18, 0.45]);
    maps_of_materials(Model::KullaConty, side, |u, v| {
        if ((u - 0.38) / 0.30).powi(2) + ((v - 0.5) / 0.223).powi(2) < 1.0 {
            gold
        } else if (0.78..0.91).contains(&u) {
            ceramic
        } else {
            paint
        }
    })
}

/// The capture of [`three_material_truth`]: an 8 cm sample, rectified photos of `side` pixels,
/// 6 flash photos from around the normal and 4 lit by a point light 14 cm off axis on each
/// side, 10 cm up (the last, lit from -y, is the validation photo).
fn side_lit_template(dir: &Path, side: usize) -> PathBuf {
    let cameras = [
        [0.0, 0.0, 18.0],
        [3.0, 3.2, 17.2],
        [-2.6, -2.1, 17.6],
        [-2.1, 2.4, 18.6],
        [2.2, -2.0, 17.0],
        [0.5, -3.0, 18.2],
    ];
    let lights = [
        [14.0, 0.0, 10.0],
        [-14.0, 0.0, 10.0],
        [0.0, 14.0, 10.0],
        [0.0, -14.0, 10.0],
    ];
    let path = dir.join(format!("side-lit-{side}.capture.toml"));
    let sample = Sample { size: 8.0, side };
    write_template(&path, sample, (&cameras, 1500.0), (&lights, 3000.0));
    path
}

/// A square sample `size` cm wide seen by rectified photos of `side` pixels.
#[derive(Clone, Copy)]
struct Sample {
    size: f64,
    side: usize,
}

/// Writes a capture template to `path`: a flash photo from each of `flashes`' camera positions
/// (the first is the manifest's camera) at their intensity, then a photo from that first
/// camera lit by each of `points`' point lights at theirs.
fn write_template(
    path: &Path,
    sample: Sample,
    flashes: (&[[f64; 3]], f64),
    points: (&[[f64; 3]], f64),
) {
    let (Sample { size, side }, (cameras, flash), (lights, point)) = (sample, flashes, points);
    let mut text = format!(
        "name = \"synthetic\"\nunits = \"cm\"\n[sample]\nwidth = {size:?}\nheight = {size:?}\n\
         [camera]\nmodel = \"rectified\"\nposition = {:?}\nresolution = [{side}, {side}]\n",
        cameras[0]
    );
    for (i, c) in cameras.iter().enumerate() {
        text += &format!(
            "[[photo]]\nimage = \"{i:02}.exr\"\ncamera = {{ position = {c:?} }}\n\
             light = {{ kind = \"flash\", intensity = [{flash:?}, {flash:?}, {flash:?}] }}\n"
        );
    }
    for (i, l) in lights.iter().enumerate() {
        text += &format!(
            "[[photo]]\nimage = \"{:02}.exr\"\nlight = {{ kind = \"point\", position = {l:?}, \
             intensity = [{point:?}, {point:?}, {point:?}] }}\n",
            cameras.len() + i
        );
    }
    std::fs::write(path, text).unwrap();
}

/// Issue #43: `fit --maps` finds the three materials of [`three_material_truth`], each of its
/// kind and with its alpha within 3%, at a texel grid coarser than the photos (texels astride
/// the gold's edge mix two materials) and at one texel a pixel (every texel's own photos pin
/// it down, so no number of bases predicts the validation photo better than another), with
/// the gold's red F0 below 1 and saturated. Before, the fits kept four bases at 32^2 (the
/// fourth on the edge's mixed texels) and one at 64^2 (docs/maps.md, "The number of bases").
#[test]
fn maps_fits_find_three_materials_at_coarse_and_fine_texel_grids() {
    let side = 64;
    for red in [0.95, 1.0] {
        let dir = tempfile::tempdir().unwrap();
        let capture = side_lit_template(dir.path(), side);
        let (_, set) =
            truth_set_captured(three_material_truth(side, red), dir.path(), &capture, &[]);
        for texels in ["32x32", "64x64"] {
            let name = format!("red-{red}-{texels}");
            let fit = fit_maps(
                &set,
                dir.path(),
                &name,
                &["--models", "kulla-conty", "--texels", texels],
            );
            assert_bases(
                &fit,
                &name,
                &[("dielectric", 0.15), ("dielectric", 0.35), ("metal", 0.4)],
            );
        }
    }
}

/// Asserts that `fit` reports the bases `truth` (kind, alpha; in increasing alpha), each alpha
/// within 3%.
fn assert_bases(fit: &serde_json::Value, name: &str, truth: &[(&str, f64)]) {
    let mut bases: Vec<(String, f64, f64)> = fit["maps_fit"]["bases"]
        .as_array()
        .unwrap()
        .iter()
        .map(|b| {
            let kind = b["kind"].as_str().unwrap().to_string();
            (
                kind,
                b["alpha"].as_f64().unwrap(),
                b["share"].as_f64().unwrap(),
            )
        })
        .collect();
    bases.sort_by(|a, b| a.1.total_cmp(&b.1));
    eprintln!("{name}: bases (kind, alpha, share) {bases:?}");
    assert_eq!(bases.len(), truth.len(), "{name}: bases {bases:?}");
    for ((kind, alpha, _), &(truth_kind, truth_alpha)) in bases.iter().zip(truth) {
        assert_eq!(kind, truth_kind, "{name}: bases {bases:?}");
        assert!(
            (alpha / truth_alpha - 1.0).abs() < 0.03,
            "{name}: alpha {alpha} for {truth_alpha}"
        );
    }
}

/// A truth unlike the synthetic ones the maps fit was built on: a rough copper square (alpha
/// 0.6) in one corner and a band of dark rubber (a dielectric of albedo 0.05, alpha 0.5)
/// across a glossy white ceramic (alpha 0.1), on a 10 cm sample, `side` texels.
fn copper_rubber_ceramic_truth(side: usize) -> MaterialMaps {
    let copper = ([0.95, 0.64, 0.54], 0.6, [0.0; 3]);
    let rubber = ([0.04; 3], 0.5, [0.05; 3]);
    let ceramic = ([0.04; 3], 0.1, [0.8, 0.78, 0.72]);
    maps_of_materials(Model::KullaConty, side, |u, v| {
        if v >= 0.55 && u < 0.5 {
            copper
        } else if (0.146..0.333).contains(&v) {
            rubber
        } else {
            ceramic
        }
    })
}

/// The capture of [`copper_rubber_ceramic_truth`]: rectified photos of `side` pixels from 25
/// cm, 5 flash photos from cameras up to 5 cm off axis and 5 lit by point lights 8-25 cm up
/// and 10-18 cm off axis.
fn flash_and_points_template(dir: &Path, side: usize) -> PathBuf {
    let cameras = [
        [0.0, 0.0, 25.0],
        [4.0, -1.0, 24.0],
        [-3.0, 3.5, 24.5],
        [1.5, 4.0, 25.5],
        [-4.0, -3.0, 23.5],
    ];
    let lights = [
        [10.0, 10.0, 20.0],
        [-12.0, 6.0, 15.0],
        [6.0, -12.0, 8.0],
        [-8.0, -9.0, 25.0],
        [18.0, -2.0, 12.0],
    ];
    let path = dir.join(format!("flash-and-points-{side}.capture.toml"));
    let sample = Sample { size: 10.0, side };
    write_template(&path, sample, (&cameras, 2500.0), (&lights, 5000.0));
    path
}

/// Issue #43: at one texel a pixel (the default grid), the dark rubber band of
/// [`copper_rubber_ceramic_truth`] is a basis of its own, a dielectric, and the three bases'
/// alphas are within 3%. Before, with a metal's F0 free, the band's texels fitted as a grey
/// metal of F0 0.13 as well as what they are and went to the copper's basis (two bases), and
/// the rubber's pooled alpha came out 3-7% low where it was found (docs/maps.md).
#[test]
fn a_dark_dielectric_is_not_taken_for_a_metal_at_one_texel_a_pixel() {
    let side = 64;
    let dir = tempfile::tempdir().unwrap();
    let capture = flash_and_points_template(dir.path(), side);
    let (_, set) = truth_set_captured(copper_rubber_ceramic_truth(side), dir.path(), &capture, &[]);
    let fit = fit_maps(&set, dir.path(), "fit", &["--models", "kulla-conty"]);
    assert_bases(
        &fit,
        "copper, rubber, ceramic",
        &[("dielectric", 0.1), ("dielectric", 0.5), ("metal", 0.6)],
    );
}

/// Issue #45: coarse to fine. The bases chosen on a grid of half the resolution (photos halved
/// too) and every texel refined from it to the full grid find the same three bases as the fit
/// that chooses them on the full grid, with maps as close to the truth and a held-out photo
/// predicted as well. (From 64^2 to 32^2 the rubber is lost at 32^2, where its texels, one
/// pixel each, fit as a grey metal as well as a dielectric: the bases can be chosen only on a
/// grid that keeps every material; docs/maps.md.)
#[test]
fn coarse_to_fine_maps_match_the_fit_on_the_full_grid() {
    let side = 128;
    let dir = tempfile::tempdir().unwrap();
    let capture = flash_and_points_template(dir.path(), side);
    let (truth, set) =
        truth_set_captured(copper_rubber_ceramic_truth(side), dir.path(), &capture, &[]);
    let mut results = Vec::new();
    for (name, coarsest, bases_grid) in [("full", "off", 128), ("coarse-to-fine", "64", 64)] {
        let fit = fit_maps(
            &set,
            dir.path(),
            name,
            &[
                "--models",
                "kulla-conty",
                "--holdout-photo",
                "4",
                "--coarse-to-fine",
                coarsest,
            ],
        );
        assert_bases(
            &fit,
            name,
            &[("dielectric", 0.1), ("dielectric", 0.5), ("metal", 0.6)],
        );
        assert_eq!(fit["maps_fit"]["bases_grid"]["width"], bases_grid, "{name}");
        let got = load_maps(&dir.path().join(format!("{name}.json")));
        let [alpha_rmse, diffuse_rms, f0_rms] = map_errors(&got, &truth);
        let held_out = fit["holdout"]["relative_error"].as_f64().unwrap();
        eprintln!(
            "{name}: alpha RMSE {alpha_rmse:.4}, diffuse RMS {diffuse_rms:.4}, F0 RMS \
             {f0_rms:.4}, held-out relative error {held_out:.4}"
        );
        results.push((alpha_rmse, diffuse_rms, f0_rms, held_out));
    }
    let (full, refined) = (results[0], results[1]);
    let bounds = [
        ("alpha RMSE", 0.01),
        ("albedo RMS", 0.01),
        ("F0 RMS", 0.01),
        ("held out", 0.005),
    ];
    let pairs = [
        (full.0, refined.0),
        (full.1, refined.1),
        (full.2, refined.2),
        (full.3, refined.3),
    ];
    for ((what, margin), (full, refined)) in bounds.into_iter().zip(pairs) {
        assert!(refined <= full + margin, "{what}: {refined} against {full}");
    }
}

/// Writes the bundled maps source, `datasets/sources/two-materials.material.json` and its
/// `two-materials.material.maps/` (the truth of `datasets/two-materials`, made by `datasets/make.sh`):
/// the truth of the recovery test at 128 x 128. Run with `--ignored` after changing
/// [`truth_maps`].
#[test]
#[ignore]
fn regenerate_bundled_maps_source() {
    truth_maps(Model::KullaConty, 128)
        .save(
            &repo("datasets/sources/two-materials.material.json"),
            Default::default(),
        )
        .unwrap();
}

/// A maps material file with the given `maps` object, in `dir`.
fn maps_file(dir: &Path, name: &str, maps: serde_json::Value) -> PathBuf {
    let path = dir.join(name);
    let text = serde_json::json!({"model": "single", "alpha": 0.3, "fresnel": {"kind": "white"},
                                  "maps": maps});
    std::fs::write(&path, text.to_string()).unwrap();
    path
}

#[test]
fn maps_files_round_trip_and_bad_maps_are_refused_by_file_and_field() {
    let dir = tempfile::tempdir().unwrap();
    let truth = truth_maps(Model::Single, 8);
    let written = dir.path().join("good.json");
    truth.save(&written, Default::default()).unwrap();
    let back = load_maps(&written);
    assert_eq!(back.grid, truth.grid);
    let close = |a: &[[f64; 3]], b: &[[f64; 3]]| rms(a, b) < 1e-4;
    assert!(close(
        back.diffuse.as_ref().unwrap(),
        truth.diffuse.as_ref().unwrap()
    ));
    assert!(close(
        back.specular.as_ref().unwrap(),
        truth.specular.as_ref().unwrap()
    ));
    let (a, b) = (back.roughness.unwrap(), truth.roughness.clone().unwrap());
    let kept = |a: &[[f64; 2]], b: &[[f64; 2]]| {
        a.iter()
            .zip(b)
            .all(|(x, y)| (0..2).all(|i| (x[i] - y[i]).abs() < 1e-6 * y[i]))
    };
    assert!(kept(&a, &b), "EXR keeps alpha");
    // Anisotropic texels: alpha_x in red, alpha_y in green, both kept.
    let stretched = MaterialMaps {
        roughness: Some(b.iter().map(|&[a, _]| [a, 3.0 * a]).collect()),
        ..truth.clone()
    };
    let anisotropic = dir.path().join("anisotropic.json");
    stretched.save(&anisotropic, Default::default()).unwrap();
    let back = load_maps(&anisotropic);
    assert!(back.is_anisotropic() && !truth.is_anisotropic());
    assert!(kept(
        &back.roughness.unwrap(),
        stretched.roughness.as_ref().unwrap()
    ));

    let maps = dir.path().join("good.maps");
    let template = flash_template(dir.path(), 8);
    let out = dir.path().join("out");
    let render = |material: &Path| {
        run_bad(&[
            "render",
            "--capture",
            template.to_str().unwrap(),
            "--material",
            material.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
        ])
    };
    // Maps of two sizes.
    let small = dir.path().join("small");
    truth_maps(Model::Single, 4)
        .save(&small.join("m.json"), Default::default())
        .unwrap();
    let mixed = maps_file(
        dir.path(),
        "mixed.json",
        serde_json::json!({"diffuse": maps.join("diffuse.png"), "roughness": small.join("m.maps/roughness.exr")}),
    );
    let stderr = render(&mixed);
    assert!(
        stderr.contains("roughness.exr: resolution") && stderr.contains("4x4"),
        "{stderr}"
    );
    // A missing map file, an unknown map, a map that is not a path.
    let missing = maps_file(
        dir.path(),
        "missing.json",
        serde_json::json!({"diffuse": "nowhere.png"}),
    );
    assert!(render(&missing).contains("nowhere.png"));
    let unknown = maps_file(
        dir.path(),
        "unknown.json",
        serde_json::json!({"albedo": "x.png"}),
    );
    assert!(render(&unknown).contains("maps.albedo: unknown map"));
    let number = maps_file(dir.path(), "number.json", serde_json::json!({"normal": 3}));
    assert!(render(&number).contains("maps.normal: expected the image file's path"));
    // A roughness map of 8x8 texels, 0.3 but for texel `t` (column t % 8, row t / 8), rendered:
    // stderr.
    let bad_texel = |name: &str, t: usize, texel: [f32; 3]| {
        let mut texels = vec![[0.3f32; 3]; 64];
        texels[t] = texel;
        let image = format!("{name}.exr");
        bouncefit::capture::image_io::write_exr(&dir.path().join(&image), &texels, 8, 8).unwrap();
        let file = maps_file(
            dir.path(),
            &format!("{name}.json"),
            serde_json::json!({ "roughness": image }),
        );
        render(&file)
    };
    let stderr = bad_texel("nan", 9, [f32::NAN; 3]);
    assert!(
        stderr.contains("nan.exr: texel (1, 1) of map `roughness`"),
        "{stderr}"
    );
    // A texel whose roughness along y (green) is zero.
    let stderr = bad_texel("flat", 10, [0.3, 0.0, 0.3]);
    assert!(
        stderr.contains("flat.exr: texel (2, 1) of map `roughness`")
            && stderr.contains("alpha_y 0"),
        "{stderr}"
    );
    // An 8x4 texel grid on the template's square sample: texels of aspect 0.5.
    bouncefit::capture::image_io::write_exr(&dir.path().join("wide.exr"), &[[0.3f32; 3]; 32], 8, 4)
        .unwrap();
    let wide = maps_file(
        dir.path(),
        "wide.json",
        serde_json::json!({"roughness": "wide.exr"}),
    );
    assert!(render(&wide).contains("maps resolution"));
    assert!(!out.exists(), "nothing is written on bad input");
}

#[test]
fn maps_fits_refuse_stochastic_models_options_they_would_ignore_and_a_missing_holdout_photo() {
    let set = repo("datasets/copper-flash");
    let out = tempfile::tempdir().unwrap();
    let fit = out.path().join("f.json");
    let args = |extra: &[&'static str]| {
        let mut a = vec![
            "fit",
            set.to_str().unwrap(),
            "--maps",
            "-o",
            fit.to_str().unwrap(),
        ];
        a.extend_from_slice(extra);
        run_bad(&a)
    };
    assert!(args(&["--models", "bitterli"]).contains("bitterli is stochastic"));
    assert!(args(&["--holdout-photo", "9"]).contains("--holdout-photo: photo 9 does not exist"));
    // Options a maps fit has no use for are refused, not ignored.
    assert!(args(&["--fresnel", "conductor"]).contains("--fresnel: a maps fit takes Schlick F0"));
    assert!(args(&["--loss", "log-l1"]).contains("--loss: a maps fit minimises"));
    assert!(args(&["--mcmc"]).contains("--mcmc: a maps fit reports maximum a posteriori maps"));
    assert!(!fit.exists() && !out.path().join("f.maps").exists());
}

/// `compare --maps` (issue #17 item 3) on the synthetic truth at 32 x 32 with the side-lit
/// photo 9 held out: every field of the report, images of the right sizes, and the physics of
/// the difference. Measured (32^2 and 64^2 texels): on the rough copper single's roughness is
/// about 0.25 below kulla-conty's (0.40 against the true 0.65), on the paint they agree within
/// 0.001; single also takes the copper for a dielectric with a diffuse albedo.
#[test]
fn compare_maps_reports_each_model_and_what_multiple_bounces_change() {
    let side = 32;
    let dir = tempfile::tempdir().unwrap();
    let (truth, set) = truth_set(dir.path(), side);
    let out = dir.path().join("report");
    run_ok(&[
        "compare",
        set.to_str().unwrap(),
        "--maps",
        "--models",
        "single,kulla-conty",
        "--holdout-photo",
        "9",
        "-o",
        out.to_str().unwrap(),
        "--quiet",
    ]);
    let report = read_json(&out.join("report.json"));
    assert_eq!(report["kind"], "maps");
    assert_eq!(report["texels"], serde_json::json!([side, side]));
    assert_eq!(report["holdout_photo"], 9);
    let photos = strings(&report["photos"]);
    assert_eq!(photos.len(), 10);
    assert_eq!(
        report["pixels_used"].as_u64().unwrap(),
        10 * (side * side) as u64
    );
    assert!(report["residual_scale"].as_f64().unwrap() > 0.0);

    // Per model: the held-out error and its baseline, the fit file with its maps, the
    // re-render and residual of every photo (the held-out one included) at the photo's size.
    let models = report["models"].as_array().unwrap();
    assert_eq!(models.len(), 2);
    let held_out = |model: &str| {
        let row = models.iter().find(|r| r["model"] == model).unwrap();
        assert_eq!(row["holdout"]["photo"], 9);
        assert!(row["train_error"].as_f64().unwrap() > 0.0);
        assert!(row["seconds"].as_f64().unwrap() > 0.0);
        assert!(!row["maps_fit"]["bases"].as_array().unwrap().is_empty());
        let fit = load_maps(&out.join(row["fit_file"].as_str().unwrap()));
        assert_eq!(fit.grid, truth.grid);
        assert_eq!(fit.base.model.name(), model);
        for stem in &photos {
            for kind in ["target", "fit", "residual"] {
                let image = out.join(model).join(format!("{stem}_{kind}.png"));
                assert_eq!(png_size(&image), (side as u32, side as u32), "{kind}");
            }
        }
        let baseline = row["holdout"]["mean_photo_error"].as_f64().unwrap();
        (row["holdout"]["relative_error"].as_f64().unwrap(), baseline)
    };
    let (single, baseline) = held_out("single");
    let (kulla, _) = held_out("kulla-conty");
    eprintln!("held-out photo: single {single:.4}, kulla-conty {kulla:.4}, mean of the others {baseline:.4}");
    assert!(kulla < single, "kulla-conty {kulla} vs single {single}");
    assert!(kulla < baseline);

    // The maps side by side: two rows (models) of three cells (no normals), 4 pixels apart,
    // each texel an 8 x 8 square (32 texels make 256 pixels), roughness on a colour map whose
    // bar is beside it.
    let maps = &report["maps_image"];
    assert_eq!(maps["rows"], serde_json::json!(["single", "kulla-conty"]));
    assert_eq!(
        maps["columns"],
        serde_json::json!(["diffuse", "specular", "roughness"])
    );
    assert_eq!(maps["texel_pixels"], 8);
    let cells = 8 * side as u32;
    assert_eq!(
        png_size(&out.join("maps.png")),
        (3 * cells + 2 * 4, 2 * cells + 4)
    );
    assert!(out
        .join(maps["roughness_colour_bar"].as_str().unwrap())
        .is_file());

    // The per-texel sds beside them, laid out alike: roughness, F0 and albedo per model, each
    // column with its colour bar and a positive median sd per model.
    let sds = &report["uncertainty_image"];
    assert_eq!(sds["rows"], maps["rows"]);
    assert_eq!(
        sds["columns"],
        serde_json::json!(["roughness", "specular", "diffuse"])
    );
    assert_eq!(
        png_size(&out.join(sds["path"].as_str().unwrap())),
        (3 * cells + 2 * 4, 2 * cells + 4)
    );
    for c in 0..3 {
        assert!(sds["scales"][c].as_f64().unwrap() > 0.0);
        assert!(out.join(sds["colour_bars"][c].as_str().unwrap()).is_file());
        for row in 0..2 {
            assert!(sds["medians"][c][row].as_f64().unwrap() > 0.0, "{c} {row}");
        }
    }

    // kulla-conty minus single.
    let differences = report["differences"].as_array().unwrap();
    assert_eq!(differences.len(), 1);
    let d = &differences[0];
    assert_eq!(
        (&d["model"], &d["minus"]),
        (&"kulla-conty".into(), &"single".into())
    );
    for quantity in ["alpha", "diffuse", "f0"] {
        for stat in ["mean", "mean_abs", "p05", "p50", "p95", "min", "max"] {
            assert!(
                d[quantity][stat].as_f64().unwrap().is_finite(),
                "{quantity}.{stat}"
            );
        }
    }
    assert_eq!(d["alpha_change_threshold"], 0.02);
    for what in ["alpha", "diffuse"] {
        let image = out.join(d["images"][what].as_str().unwrap());
        assert_eq!(png_size(&image), (cells, cells));
        assert!(d["images"][format!("{what}_scale")].as_f64().unwrap() > 0.0);
        assert!(out
            .join(d["images"][format!("{what}_colour_bar")].as_str().unwrap())
            .is_file());
    }
    let region = |kind: &str| {
        d["regions"]
            .as_array()
            .unwrap()
            .iter()
            .find(|r| r["kind"] == kind)
            .unwrap_or_else(|| panic!("no {kind} region in {}", d["regions"]))
    };
    let (metal, paint) = (region("metal"), region("dielectric"));
    eprintln!(
        "kulla-conty minus single: copper {}, paint {}",
        metal["alpha"], paint["alpha"]
    );
    let number = |r: &serde_json::Value, path: [&str; 2]| r[path[0]][path[1]].as_f64().unwrap();
    // Single scattering loses rough copper's multiple-bounce energy and makes it up with a
    // narrower lobe: its roughness is lower there, by far more than the change threshold,
    // on nearly every copper texel; on the glossy paint the models agree.
    assert!(number(metal, ["alpha", "mean"]) > 0.1, "{metal}");
    assert!(number(metal, ["alpha", "p05"]) > 0.02, "{metal}");
    assert!(metal["alpha_changed_fraction"].as_f64().unwrap() > 0.9);
    assert!(metal["alpha_single"].as_f64().unwrap() < metal["alpha_model"].as_f64().unwrap() - 0.1);
    assert!((metal["alpha_model"].as_f64().unwrap() - METAL.1).abs() < 0.05);
    assert!(number(paint, ["alpha", "mean"]).abs() < 0.01, "{paint}");
    assert!(paint["alpha_changed_fraction"].as_f64().unwrap() < 0.1);
    let share = |r: &serde_json::Value| r["share"].as_f64().unwrap();
    let fraction = d["alpha_changed_fraction"].as_f64().unwrap();
    assert!(
        (fraction - share(metal)).abs() < 0.1,
        "changed {fraction} vs copper share"
    );

    // The pages: the verdicts name the held-out winner and the difference; the HTML embeds
    // the three figures and every photo's images.
    let verdicts = report["verdicts"].to_string();
    assert!(verdicts.contains("kulla-conty predicts best"), "{verdicts}");
    assert!(verdicts.contains("kulla-conty minus single"), "{verdicts}");
    // Under new light, single's glTF export is its fit: every texel with a diffuse albedo is a
    // glTF dielectric with the same F0 (single fits the copper with F0 and a diffuse, which a
    // glTF metal would drop: -0.27 when it did). kulla-conty's export is darker by the rough
    // copper's multiple bounces alone. Measured: single 0.0000, kulla-conty -0.14.
    let relit = |model: &str| {
        let row = report["relit"]["rows"]
            .as_array()
            .unwrap()
            .iter()
            .find(|r| r["model"] == model)
            .unwrap();
        for image in ["sphere", "sample", "gltf_sphere", "gltf_difference"] {
            assert!(out.join(row[image].as_str().unwrap()).is_file(), "{image}");
        }
        assert!(row["lobe"].is_null());
        row["gltf_mean_difference"].as_f64().unwrap()
    };
    let (single_loss, kulla_loss) = (relit("single"), relit("kulla-conty"));
    eprintln!(
        "glTF export minus fit, relit: single {single_loss:+.4}, kulla-conty {kulla_loss:+.4}"
    );
    assert!(single_loss.abs() < 1e-3, "{single_loss}");
    assert!((-0.3..-0.05).contains(&kulla_loss), "{kulla_loss}");
    // The figures: maps, roughness bar, the sds with three bars, two difference images with
    // their bars; the relit images (four per model) and their bar; every photo's images.
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert_eq!(
        html.matches("src=\"data:image/png;base64,").count(),
        2 + 4 + 4 + (2 * 4 + 1) + photos.len() * (1 + 2 * 2)
    );
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(
        md.contains("## Multi-bounce minus single")
            && md.contains("![Maps: rows single, kulla-conty")
    );
}

#[test]
fn compare_maps_bad_input_exits_2_and_writes_nothing() {
    let set = repo("datasets/two-materials");
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("report");
    let run = |extra: &[&str]| {
        let mut args = vec![
            "compare",
            set.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
            "--quiet",
        ];
        args.extend_from_slice(extra);
        run_bad(&args)
    };
    let maps = |extra: &[&'static str]| {
        let mut a = vec!["--maps"];
        a.extend_from_slice(extra);
        a
    };
    // The stochastic model is refused before any fit (single's comes first).
    assert!(run(&maps(&["--models", "single,bitterli"])).contains("bitterli is stochastic"));
    assert!(run(&maps(&["--models", "single", "--holdout-photo", "9"]))
        .contains("--holdout-photo: photo 9 does not exist"));
    assert!(run(&maps(&["--models", "single", "--holdout", "3"])).contains("--holdout-photo N"));
    assert!(run(&maps(&["--models", "single", "--mcmc"])).contains("--mcmc"));
    assert!(run(&maps(&["--models", "single,single"])).contains("listed twice"));
    // Maps options without --maps are a usage error.
    assert!(run(&["--models", "single", "--holdout-photo", "2"]).contains("--maps"));
    assert!(run(&maps(&["--models", "single", "--texels", "0x8"])).contains("1 to 8192"));
    assert_eq!(
        std::fs::read_dir(dir.path()).unwrap().count(),
        0,
        "nothing written"
    );
}

/// The shares of a maps fit's texels whose truth lies within 2 of its posterior standard
/// deviations (docs/maps.md, "Uncertainty"), each in the coordinate the posterior is Gaussian
/// in: roughness as `ln alpha` (the sd `roughness_sd.exr` holds), F0 and the albedo per channel
/// as `logit` (their sd maps hold the sd in F0 and albedo units, `sigmoid'` times that of the
/// logit). `fit` is the fit file `path`'s JSON. Returns `(share, count)` for roughness, F0 and
/// the dielectrics' albedo (a metal's is 0, where the logit is not finite).
fn shares_within_two_sd(
    path: &Path,
    fit: &serde_json::Value,
    truth: &MaterialMaps,
) -> [(f64, usize); 3] {
    use bouncefit::capture::image_io::{load_image, ColorEncoding};
    let got = load_maps(path);
    let sd = |name: &str| {
        let file = fit["uncertainty"][name]["file"].as_str().unwrap();
        let image = load_image(&path.parent().unwrap().join(file), ColorEncoding::Linear).unwrap();
        assert_eq!(
            (image.width, image.height),
            (truth.grid.width, truth.grid.height)
        );
        image.rgb
    };
    let logit = |p: f64| (p / (1.0 - p)).ln();
    let within = |pairs: &mut dyn Iterator<Item = bool>| {
        let (mut inside, mut count) = (0, 0);
        for ok in pairs {
            inside += usize::from(ok);
            count += 1;
        }
        (inside as f64 / count as f64, count)
    };
    let (alpha_sd, f0_sd, albedo_sd) = (sd("roughness_sd"), sd("specular_sd"), sd("diffuse_sd"));
    let (alpha, f0, albedo) = (
        got.roughness.as_ref().unwrap(),
        got.specular.as_ref().unwrap(),
        got.diffuse.as_ref().unwrap(),
    );
    let (true_alpha, true_f0, true_albedo) = (
        truth.roughness.as_ref().unwrap(),
        truth.specular.as_ref().unwrap(),
        truth.diffuse.as_ref().unwrap(),
    );
    let texels = 0..truth.grid.len();
    // Per channel: the fitted and true values of a bounded map, and its sd in logit units.
    let logit_within =
        |t: usize, c: usize, got: &[[f64; 3]], truth: &[[f64; 3]], sd: &[[f32; 3]]| {
            let p = got[t][c];
            let sd_logit = f64::from(sd[t][c]) / (p * (1.0 - p));
            (logit(p) - logit(truth[t][c])).abs() <= 2.0 * sd_logit
        };
    [
        within(&mut texels.clone().map(|t| {
            (alpha[t][0].ln() - true_alpha[t][0].ln()).abs() <= 2.0 * f64::from(alpha_sd[t][0])
        })),
        within(
            &mut texels
                .clone()
                .flat_map(|t| (0..3).map(move |c| (t, c)))
                .map(|(t, c)| logit_within(t, c, f0, true_f0, &f0_sd)),
        ),
        within(
            &mut texels
                .filter(|&t| true_albedo[t] != [0.0; 3])
                .flat_map(|t| (0..3).map(move |c| (t, c)))
                .map(|(t, c)| logit_within(t, c, albedo, true_albedo, &albedo_sd)),
        ),
    ]
}

/// Issue #47: the per-texel standard deviations of `fit --maps` are calibrated. On two truths
/// with other materials, captures and noise levels than the recovery test's (each fit at 32^2
/// texels, one a pixel, `kulla-conty`), the truth lies within 2 sd of the fitted roughness and
/// F0 for 95% of the texels, within `3 sqrt(0.95 x 0.05 / n)` for the `n` texels (the channels
/// of a texel's F0 are not independent, so `n` counts texels) plus a model error of 0.02: the
/// truths' materials are uniform, so texels whose photos say little of them sit at their
/// basis's centre, where the prior (sd 0.25 in `ln alpha`) says they could be anywhere near it,
/// and are covered more often than 95%. Measured: roughness 96.8% and 98.0%, F0 96.1% and
/// 96.6% (albedo 89.5% and 97.8%, not asserted: docs/maps.md, "Uncertainty"). With the one
/// noise level of stage 2 instead of the noise level function, the same fits gave 93.4% and
/// 90.6% for roughness; with the Gauss-Newton matrices left in units of the noise variance
/// (no `sigma^2`), the first truth's roughness and F0 came out 99.9% and 100% covered and this
/// test failed.
#[test]
fn texel_standard_deviations_cover_the_truth_as_often_as_they_say() {
    let side = 32;
    let dir = tempfile::tempdir().unwrap();
    let cases: [(&str, MaterialMaps, PathBuf, &str); 2] = [
        (
            "copper, rubber, ceramic",
            copper_rubber_ceramic_truth(side),
            flash_and_points_template(dir.path(), side),
            "0.02",
        ),
        (
            "gold, ceramic, paint",
            three_material_truth(side, 0.95),
            side_lit_template(dir.path(), side),
            "0.01",
        ),
    ];
    let texels = side * side;
    let band = 3.0 * (0.95 * 0.05 / texels as f64).sqrt() + 0.02;
    for (i, (name, truth, capture, noise)) in cases.into_iter().enumerate() {
        let case_dir = dir.path().join(i.to_string());
        std::fs::create_dir(&case_dir).unwrap();
        let (truth, set) = truth_set_captured(truth, &case_dir, &capture, &["--noise", noise]);
        let fit = fit_maps(&set, &case_dir, "fit", &["--models", "kulla-conty"]);
        let [roughness, f0, albedo] =
            shares_within_two_sd(&case_dir.join("fit.json"), &fit, &truth);
        eprintln!(
            "{name}, {noise} noise: within 2 sd (share, count): roughness {roughness:?}, F0 \
             {f0:?}, albedo {albedo:?}"
        );
        for (what, (share, _)) in [("roughness", roughness), ("F0", f0)] {
            assert!(
                (share - 0.95).abs() <= band,
                "{name}: {what} within 2 sd for {share} of the texels, expected 0.95 +- {band}"
            );
        }
    }
}

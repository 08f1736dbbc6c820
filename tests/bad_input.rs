//! Bad input for every command (issue #6 item 4): each case must exit with status 2, name the
//! problem (file and field where there is one) on stderr, not panic, and leave the output's
//! folder exactly as it was: no output, no partial output, no temporary file, an existing
//! output untouched. Warnings (unknown keys) and excluded pixels (NaN, Inf, negative) are not
//! errors: those cases run to the end and report what they ignored.
//!
//! The cases are tables; a failure names the case. Fixtures are made in a temporary folder:
//! a small synthetic photo set (9 rectified 16x16 photos of copper, from `bouncefit synth`)
//! and variants of it with one thing broken.

mod common;
use bouncefit::capture::image_io::{load_image, write_exr};
use bouncefit::capture::ColorEncoding;
use common::*;
use std::path::{Path, PathBuf};

/// The photo set every fixture starts from: the bundled copper-flash template (9 rectified
/// flash photos) at 16x16 pixels.
fn capture_template() -> String {
    let text = std::fs::read_to_string(repo("datasets/sources/copper-flash.capture.toml")).unwrap();
    replaced(&text, "resolution = [128, 128]", "resolution = [16, 16]")
}

/// A pinhole camera for the geometry cases (replaces the rectified `[camera]` of the template).
const PINHOLE: &str = r#"[camera]
model = "pinhole"
position = [0.0, 0.0, 30.0]
look_at = [0.0, 0.0, 0.0]
up = [0.0, 1.0, 0.0]
fov_y_deg = 30.0
resolution = [16, 16]
"#;

const MATERIAL: &str = r#"{"model": "single", "alpha": 0.3,
 "fresnel": {"kind": "conductor", "eta": [0.2378, 1.0066, 1.2404], "k": [3.6264, 2.5823, 2.3929]}}"#;

/// Pixels of the fixture set: 9 photos of 16x16.
const PIXELS: usize = 9 * 16 * 16;

struct Fixture {
    dir: tempfile::TempDir,
}

impl Fixture {
    /// Writes the template manifest and material and synthesises the photo set `set/`.
    fn new() -> Fixture {
        let fixture = Fixture {
            dir: tempfile::tempdir().unwrap(),
        };
        std::fs::write(fixture.path("template.toml"), capture_template()).unwrap();
        std::fs::write(fixture.path("material.json"), MATERIAL).unwrap();
        synth(
            &fixture.path("material.json"),
            &fixture.path("template.toml"),
            &fixture.path("set"),
            &[],
        );
        fixture
    }

    fn path(&self, name: &str) -> PathBuf {
        self.dir.path().join(name)
    }

    fn arg(&self, name: &str) -> String {
        self.path(name).to_str().unwrap().to_string()
    }

    /// A copy of the photo set named `name`, changed by `edit` (given the copy's folder).
    fn set_variant(&self, name: &str, edit: impl FnOnce(&Path)) -> String {
        let folder = self.path(name);
        std::fs::create_dir(&folder).unwrap();
        for entry in std::fs::read_dir(self.path("set")).unwrap() {
            let entry = entry.unwrap();
            std::fs::copy(entry.path(), folder.join(entry.file_name())).unwrap();
        }
        edit(&folder);
        folder.to_str().unwrap().to_string()
    }

    /// The set with its manifest's text changed by `edit`.
    fn manifest_variant(&self, name: &str, edit: impl FnOnce(String) -> String) -> String {
        self.set_variant(name, |folder| {
            let path = folder.join("capture.toml");
            let text = std::fs::read_to_string(&path).unwrap();
            std::fs::write(&path, edit(text)).unwrap();
        })
    }

    /// A file `name` holding `text`.
    fn file(&self, name: &str, text: &str) -> String {
        std::fs::write(self.path(name), text).unwrap();
        self.arg(name)
    }

    /// A material file: [`MATERIAL`] with `from` replaced by `to`.
    fn material_variant(&self, name: &str, from: &str, to: &str) -> String {
        self.file(name, &replaced(MATERIAL, from, to))
    }
}

/// `text` with the first `from` replaced by `to`; `from` must occur.
fn replaced(text: &str, from: &str, to: &str) -> String {
    assert!(text.contains(from), "fixture edit: `{from}` not in\n{text}");
    text.replacen(from, to, 1)
}

/// The 9 photos `00.EXTENSION` ... `08.EXTENSION` of a set in `folder`.
fn photos(folder: &Path, extension: &str) -> Vec<PathBuf> {
    (0..9)
        .map(|i| folder.join(format!("{i:02}.{extension}")))
        .collect()
}

/// Rewrites the EXR at `path` with `change` applied to its pixels.
fn edit_exr(path: &Path, change: impl FnOnce(&mut [[f32; 3]])) {
    let mut image = load_image(path, ColorEncoding::Linear).unwrap();
    change(&mut image.rgb);
    write_exr(path, &image.rgb, image.width, image.height).unwrap();
}

/// What the output's folder holds before the command runs.
#[derive(Clone, Copy)]
enum Before {
    /// Nothing.
    Empty,
    /// The output's parent is a regular file (`OUT` becomes `blocker/<output>`).
    ParentIsFile,
    /// The output exists already: a file, or a folder holding a file.
    Exists,
}

/// One bad-input case: `args` with `OUT` standing for the output path `output` (a name in a
/// fresh folder), and the texts stderr must contain.
struct Case {
    name: &'static str,
    args: Vec<String>,
    output: &'static str,
    before: Before,
    expect: Vec<String>,
}

fn case(name: &'static str, args: &[&str], expect: &[&str]) -> Case {
    Case {
        name,
        args: args.iter().map(|a| a.to_string()).collect(),
        output: "result",
        before: Before::Empty,
        expect: expect.iter().map(|e| e.to_string()).collect(),
    }
}

impl Case {
    fn output(mut self, output: &'static str, before: Before) -> Case {
        (self.output, self.before) = (output, before);
        self
    }
}

/// Every file and folder under `folder` with its content (folders: empty), sorted.
fn snapshot(folder: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut all = Vec::new();
    for entry in std::fs::read_dir(folder).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            all.push((path.clone(), Vec::new()));
            all.extend(snapshot(&path));
        } else {
            all.push((path.clone(), std::fs::read(&path).unwrap()));
        }
    }
    all.sort();
    all
}

/// Runs every case in its own folder under `root` and checks the contract; fails listing every
/// broken case.
fn check(root: &Path, cases: Vec<Case>) {
    let mut failures = Vec::new();
    for case in cases {
        let folder = root.join(format!("out-{}", case.name));
        std::fs::create_dir_all(&folder).unwrap();
        let output = match case.before {
            Before::Empty => folder.join(case.output),
            Before::ParentIsFile => {
                std::fs::write(folder.join("blocker"), "a file, not a folder").unwrap();
                folder.join("blocker").join(case.output)
            }
            Before::Exists => {
                let existing = folder.join(case.output);
                if case.output.contains('.') {
                    std::fs::write(&existing, "the old output").unwrap();
                } else {
                    std::fs::create_dir(&existing).unwrap();
                    std::fs::write(existing.join("old.txt"), "the old output").unwrap();
                }
                existing
            }
        };
        let out = output.to_str().unwrap();
        let args: Vec<String> = case.args.iter().map(|a| a.replace("OUT", out)).collect();
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let before = snapshot(&folder);
        let (stderr, mut problems) = run_bad_problems(&args);
        for needle in &case.expect {
            let needle = needle.replace("OUT", out);
            if !stderr.contains(&needle) {
                problems.push(format!("stderr should name `{needle}`:\n{stderr}"));
            }
        }
        if snapshot(&folder) != before {
            problems.push("the output folder changed (partial output or temporary files)".into());
        }
        failures.extend(problems.iter().map(|p| format!("case {}: {p}", case.name)));
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn bad_photo_sets_are_refused_by_every_command_that_reads_them() {
    let fx = Fixture::new();
    let material = fx.arg("material.json");
    let with_pinhole = |text: String, from: &str, to: &str| {
        let camera_start = text.find("[camera]").unwrap();
        let camera_end = text[camera_start..].find("[[photo]]").unwrap() + camera_start;
        let text = format!(
            "{}{}{}",
            &text[..camera_start],
            PINHOLE,
            &text[camera_end..]
        );
        // The second photo's own rectified camera is dropped: it inherits the pinhole.
        let text = text.replace("[photo.camera]\nmodel = \"rectified\"", "[photo.camera]");
        replaced(&text, from, to)
    };
    let edit =
        |name: &str, from: &str, to: &str| fx.manifest_variant(name, |t| replaced(&t, from, to));
    let malformed = edit(
        "malformed",
        "name = \"copper-flash\"",
        "name = \"copper-flash",
    );
    let no_sample = edit("no-sample", "[sample]\nwidth = 8.0\nheight = 8.0\n", "");
    let no_image = edit("no-image", "image = \"00.exr\"\n", "");
    let wrong_type = edit("wrong-type", "width = 8.0", "width = \"wide\"");
    let no_photo = fx.manifest_variant("no-photo", |t| {
        t[..t.find("[[photo]]").unwrap()].to_string()
    });
    let intensity = "intensity = [1500.0, 1500.0, 1500.0]";
    let zero_light = edit("zero-light", intensity, "intensity = [0.0, 0.0, 0.0]");
    let negative_light = edit(
        "negative-light",
        intensity,
        "intensity = [1500.0, -1.0, 1500.0]",
    );
    let camera_below = edit(
        "camera-below",
        "position = [0.0, 0.0, 18.0]",
        "position = [0.0, 0.0, -18.0]",
    );
    let light_below = edit(
        "light-below",
        "kind = \"flash\"",
        "kind = \"point\"\nposition = [1.0, 1.0, -0.5]",
    );
    let look_at_camera = fx.manifest_variant("look-at-camera", |t| {
        with_pinhole(t, "look_at = [0.0, 0.0, 0.0]", "look_at = [0.0, 0.0, 30.0]")
    });
    let up_along_view = fx.manifest_variant("up-along-view", |t| {
        with_pinhole(t, "up = [0.0, 1.0, 0.0]", "up = [0.0, 0.0, 1.0]")
    });
    let image_is_folder = fx.set_variant("image-is-folder", |f| {
        std::fs::remove_file(f.join("00.exr")).unwrap();
        std::fs::create_dir(f.join("00.exr")).unwrap();
    });
    let image_missing = fx.set_variant("image-missing", |f| {
        std::fs::remove_file(f.join("01.exr")).unwrap();
    });
    let truncated_exr = fx.set_variant("truncated-exr", |f| {
        let bytes = std::fs::read(f.join("00.exr")).unwrap();
        std::fs::write(f.join("00.exr"), &bytes[..bytes.len() / 3]).unwrap();
    });
    let text_exr = fx.set_variant("text-exr", |f| {
        std::fs::write(f.join("01.exr"), "this is not an image\n").unwrap();
    });
    let truncated_png = edit("truncated-png", "00.exr", "00.png");
    let bytes = std::fs::read(fx.path("set/00.png")).unwrap();
    std::fs::write(
        Path::new(&truncated_png).join("00.png"),
        &bytes[..bytes.len() / 2],
    )
    .unwrap();
    let wrong_size = edit(
        "wrong-size",
        "resolution = [16, 16]",
        "resolution = [16, 12]",
    );
    let all_nan = fx.set_variant("all-nan", |f| {
        photos(f, "exr")
            .iter()
            .for_each(|p| edit_exr(p, |rgb| rgb.fill([f32::NAN; 3])));
    });
    let all_black = fx.set_variant("all-black", |f| {
        photos(f, "exr")
            .iter()
            .for_each(|p| edit_exr(p, |rgb| rgb.fill([0.0; 3])));
    });
    let all_saturated = fx.manifest_variant("all-saturated", |t| t.replace(".exr", ".png"));
    for photo in photos(Path::new(&all_saturated), "png") {
        let white = image::RgbImage::from_pixel(16, 16, image::Rgb([255, 255, 255]));
        white.save(photo).unwrap();
    }
    let mask_size = edit(
        "mask-size",
        "image = \"00.exr\"",
        "image = \"00.exr\"\nmask = \"mask.png\"",
    );
    image::GrayImage::from_pixel(8, 8, image::Luma([255]))
        .save(Path::new(&mask_size).join("mask.png"))
        .unwrap();
    let no_manifest = fx.set_variant("no-manifest", |f| {
        std::fs::remove_file(f.join("capture.toml")).unwrap();
    });

    let fit = |set: &str| -> Vec<String> {
        ["fit", set, "-o", "OUT", "--quiet"]
            .map(String::from)
            .to_vec()
    };
    let fit_case = |name: &'static str, set: &str, expect: &[&str]| {
        let mut c = case(name, &[], expect).output("fit.json", Before::Empty);
        c.args = fit(set);
        c
    };
    let render_case = |name: &'static str, set: &str, expect: &[&str]| {
        let args = [
            "render",
            "--capture",
            set,
            "--material",
            &material,
            "-o",
            "OUT",
        ];
        case(name, &args, expect)
    };
    let synth_case = |name: &'static str, set: &str, expect: &[&str]| {
        let manifest = format!("{set}/capture.toml");
        let args = [
            "synth",
            "--capture",
            &manifest,
            "--material",
            &material,
            "-o",
            "OUT",
        ];
        case(name, &args, expect)
    };
    let compare_case = |name: &'static str, set: &str, expect: &[&str]| {
        let args = ["compare", set, "--models", "single", "-o", "OUT", "--quiet"];
        case(name, &args, expect)
    };
    let manifest = "capture.toml";
    check(
        fx.dir.path(),
        vec![
            fit_case("malformed-toml", &malformed, &[manifest, "line 1"]),
            render_case(
                "missing-sample",
                &no_sample,
                &[manifest, "sample: missing", "[sample]"],
            ),
            synth_case(
                "missing-image",
                &no_image,
                &[manifest, "photo[0].image: missing"],
            ),
            fit_case(
                "wrong-type",
                &wrong_type,
                &[manifest, "sample.width", "expected f64"],
            ),
            compare_case(
                "no-photo",
                &no_photo,
                &[manifest, "photo: missing", "[[photo]]"],
            ),
            synth_case(
                "zero-light",
                &zero_light,
                &[manifest, "photo[0].light.intensity", "zero"],
            ),
            render_case(
                "negative-light",
                &negative_light,
                &[manifest, "photo[0].light.intensity", "non-negative"],
            ),
            fit_case(
                "camera-below",
                &camera_below,
                &[manifest, "camera.position", "above the sample plane"],
            ),
            synth_case(
                "light-below",
                &light_below,
                &[
                    manifest,
                    "photo[0].light.position",
                    "above the sample plane",
                ],
            ),
            render_case(
                "look-at-camera",
                &look_at_camera,
                &[manifest, "camera.look_at", "equals the camera position"],
            ),
            synth_case(
                "up-along-view",
                &up_along_view,
                &[manifest, "camera.up", "parallel"],
            ),
            fit_case(
                "image-is-folder",
                &image_is_folder,
                &["00.exr", "is a folder; expected an image file"],
            ),
            compare_case(
                "image-missing",
                &image_missing,
                &["01.exr", "expected an image file"],
            ),
            fit_case(
                "truncated-exr",
                &truncated_exr,
                &["00.exr", "EXR data", "expected a complete OpenEXR file"],
            ),
            fit_case("text-file-named-exr", &text_exr, &["01.exr", "EXR data"]),
            fit_case(
                "truncated-png",
                &truncated_png,
                &["00.png", "image data", "expected a complete PNG"],
            ),
            fit_case(
                "resolution-mismatch",
                &wrong_size,
                &["00.exr", "resolution", "16x16", "16x12"],
            ),
            fit_case(
                "all-nan",
                &all_nan,
                &[
                    "all-nan",
                    "every pixel is excluded",
                    &format!("{} non-finite", PIXELS),
                ],
            ),
            compare_case(
                "all-black",
                &all_black,
                &["all-black", "every usable pixel is black"],
            ),
            fit_case(
                "all-saturated",
                &all_saturated,
                &[
                    "all-saturated",
                    &format!("{} saturated", PIXELS),
                    "lower exposure",
                ],
            ),
            fit_case("mask-size", &mask_size, &["mask.png", "8x8", "16x16"]),
            fit_case(
                "no-manifest",
                &no_manifest,
                &["no-manifest", "expected a capture.toml"],
            ),
        ],
    );
}

#[test]
fn bad_materials_and_options_are_refused() {
    let fx = Fixture::new();
    let set = fx.arg("set");
    let capture = fx.arg("template.toml");
    let malformed = fx.file("malformed.json", r#"{"model": "single", "alpha": 0.3,"#);
    let huge = fx.material_variant("huge.json", "\"alpha\": 0.3", "\"alpha\": 1e999");
    let no_alpha = fx.material_variant("no-alpha.json", "\"alpha\": 0.3,", "");
    let alpha_text = fx.material_variant("alpha-text.json", "0.3", "\"rough\"");
    let alpha_zero = fx.material_variant("alpha-zero.json", "0.3", "[0.3, 0.0]");
    let eta_zero = fx.material_variant("eta-zero.json", "0.2378", "0.0");
    let f0_above_one = fx.file(
        "f0.json",
        r#"{"model": "single", "alpha": 0.3, "fresnel": {"kind": "schlick", "f0": [1.2, 0.5, 0.5]}}"#,
    );
    let diffuse_above_one = fx.material_variant(
        "diffuse.json",
        "\"alpha\": 0.3,",
        "\"alpha\": 0.3, \"diffuse\": [0.2, 1.5, 0.2],",
    );
    let unknown_model = fx.material_variant("model.json", "\"single\"", "\"triple\"");
    let not_object = fx.file("list.json", "[1, 2, 3]");
    // A good brdf command with the options of `changed` (flag, value pairs) replaced.
    let brdf = |changed: &[&str]| -> Vec<String> {
        let mut args = vec!["brdf"];
        for (flag, value) in [
            ("--model", "single"),
            ("--alpha", "0.3"),
            ("--fresnel", "white"),
            ("--wi", "0,0,1"),
            ("--wo", "0.2,0,1"),
        ] {
            let given = changed.chunks(2).find(|pair| pair[0] == flag);
            args.extend([flag, given.map_or(value, |pair| pair[1])]);
        }
        args.iter().map(|a| a.to_string()).collect()
    };
    let brdf_case = |name: &'static str, extra: &[&str], expect: &[&str]| {
        let mut c = case(name, &[], expect);
        c.args = brdf(extra);
        c
    };
    let export = |name: &'static str, input: &str, expect: &[&str]| {
        case(
            name,
            &["export", input, "--format", "gltf", "-o", "OUT"],
            expect,
        )
        .output("m.gltf", Before::Empty)
    };
    let synth = |name: &'static str, input: &str, expect: &[&str]| {
        case(
            name,
            &[
                "synth",
                "--material",
                input,
                "--capture",
                &capture,
                "-o",
                "OUT",
            ],
            expect,
        )
    };
    let render = |name: &'static str, input: &str, expect: &[&str]| {
        case(
            name,
            &[
                "render",
                "--material",
                input,
                "--capture",
                &set,
                "-o",
                "OUT",
            ],
            expect,
        )
    };
    let lobe = [
        "lobe",
        "--model",
        "single",
        "--alpha",
        "0.3",
        "-o",
        "OUT",
        "--size",
        "8",
        "--samples",
        "64",
    ];
    let lobe_case = |name: &'static str, extra: &[&str], expect: &[&str]| {
        let mut args = lobe.to_vec();
        args.extend_from_slice(extra);
        case(name, &args, expect).output("lobe.png", Before::Empty)
    };
    check(
        fx.dir.path(),
        vec![
            synth(
                "malformed-json",
                &malformed,
                &[
                    "malformed.json",
                    "line 1",
                    "EOF",
                    "expected a JSON material file",
                ],
            ),
            export(
                "number-out-of-range",
                &huge,
                &["huge.json", "line 1", "number out of range"],
            ),
            render(
                "missing-alpha",
                &no_alpha,
                &[
                    "no-alpha.json",
                    "alpha: missing",
                    "expected a number or [alpha_x, alpha_y]",
                ],
            ),
            export(
                "alpha-wrong-type",
                &alpha_text,
                &[
                    "alpha-text.json",
                    "alpha:",
                    "expected a number or [alpha_x, alpha_y]",
                ],
            ),
            synth(
                "alpha-zero",
                &alpha_zero,
                &["alpha-zero.json", "alpha", "> 0"],
            ),
            render(
                "eta-zero",
                &eta_zero,
                &["eta-zero.json", "fresnel", "eta must be > 0"],
            ),
            export(
                "f0-above-one",
                &f0_above_one,
                &["f0.json", "fresnel", "[0, 1]"],
            ),
            synth(
                "diffuse-above-one",
                &diffuse_above_one,
                &["diffuse.json", "diffuse", "[0, 1]"],
            ),
            export(
                "unknown-model-in-file",
                &unknown_model,
                &["model.json", "model:", "unknown variant `triple`"],
            ),
            export(
                "material-not-an-object",
                &not_object,
                &["list.json", "expected a JSON object"],
            ),
            export("material-is-a-folder", &set, &["set"]),
            case(
                "unknown-export-format",
                &[
                    "export",
                    &fx.arg("material.json"),
                    "--format",
                    "pbrt",
                    "-o",
                    "OUT",
                ],
                &["--format", "pbrt"],
            ),
            case(
                "unknown-model-option",
                &["fit", &set, "--models", "single,triple", "-o", "OUT"],
                &["triple", "known: single"],
            ),
            case(
                "repeated-model",
                &["compare", &set, "--models", "single,single", "-o", "OUT"],
                &["--models", "listed twice"],
            ),
            case(
                "holdout-too-large",
                &[
                    "compare",
                    &set,
                    "--models",
                    "single",
                    "--holdout",
                    "10",
                    "-o",
                    "OUT",
                ],
                &["holdout"],
            ),
            case(
                "pixel-samples-not-square",
                &["fit", &set, "--pixel-samples", "3", "-o", "OUT"],
                &["pixel_samples", "perfect square"],
            ),
            case(
                "pixel-samples-not-a-number",
                &[
                    "render",
                    "--capture",
                    &set,
                    "--material",
                    &fx.arg("material.json"),
                    "--pixel-samples",
                    "four",
                    "-o",
                    "OUT",
                ],
                &["--pixel-samples", "four"],
            ),
            case(
                "starts-zero",
                &["fit", &set, "--starts", "0", "-o", "OUT"],
                &["--starts"],
            ),
            case(
                "negative-noise",
                &[
                    "synth",
                    "--capture",
                    &capture,
                    "--material",
                    &fx.arg("material.json"),
                    "--noise",
                    "-0.1",
                    "-o",
                    "OUT",
                ],
                &["--noise"],
            ),
            brdf_case("alpha-option-zero", &["--alpha", "0"], &["--alpha"]),
            brdf_case(
                "fresnel-eta-zero",
                &["--fresnel", "conductor:0,1,1:1,1,1"],
                &["--fresnel", "eta must be > 0"],
            ),
            brdf_case("direction-syntax", &["--wi", "1,2"], &["--wi", "X,Y,Z"]),
            brdf_case(
                "direction-below",
                &["--wo", "0,0.5,-1"],
                &["--wo", "z <= 0"],
            ),
            case(
                "theta-out-of-range",
                &[
                    "albedo",
                    "--model",
                    "single",
                    "--alpha",
                    "0.3",
                    "--theta-i",
                    "90",
                ],
                &["--theta-i"],
            ),
            lobe_case(
                "lobe-negative-theta",
                &["--theta-i", "-5"],
                &["--theta-i", "outside [0, 90)"],
            ),
            case(
                "albedo-unknown-model",
                &[
                    "albedo",
                    "--model",
                    "triple",
                    "--alpha",
                    "0.3",
                    "--theta-i",
                    "10",
                ],
                &["triple"],
            ),
            lobe_case(
                "lobe-table-alpha",
                &["--table-alphas", "0.3,-1"],
                &["--table-alphas", "-1"],
            ),
            lobe_case("lobe-size", &["--size", "0"], &["--size"]),
        ],
    );
}

#[test]
fn outputs_are_never_partial_and_never_replaced_without_force() {
    let fx = Fixture::new();
    let set = fx.arg("set");
    let capture = fx.arg("template.toml");
    let material = fx.arg("material.json");
    let fit = ["fit", &set, "-o", "OUT", "--quiet", "--max-iters", "5"];
    let synth = [
        "synth",
        "--capture",
        &capture,
        "--material",
        &material,
        "-o",
        "OUT",
    ];
    let render = [
        "render",
        "--capture",
        &set,
        "--material",
        &material,
        "-o",
        "OUT",
    ];
    let export = ["export", &material, "--format", "mitsuba", "-o", "OUT"];
    let compare = [
        "compare",
        &set,
        "--models",
        "single",
        "-o",
        "OUT",
        "--quiet",
        "--max-iters",
        "5",
    ];
    let lobe = [
        "lobe",
        "--model",
        "single",
        "--alpha",
        "0.3",
        "-o",
        "OUT",
        "--size",
        "8",
        "--table-alphas",
        "0.3",
        "--samples",
        "64",
    ];
    let blocked = "is a file, not a folder";
    let exists = "pass --force to replace it";
    check(
        fx.dir.path(),
        vec![
            case("fit-parent-is-file", &fit, &["blocker", blocked])
                .output("fit.json", Before::ParentIsFile),
            case("synth-parent-is-file", &synth, &["blocker", blocked])
                .output("set", Before::ParentIsFile),
            case("render-parent-is-file", &render, &["blocker", blocked])
                .output("render", Before::ParentIsFile),
            case("export-parent-is-file", &export, &["blocker", blocked])
                .output("m.xml", Before::ParentIsFile),
            case("compare-parent-is-file", &compare, &["blocker", blocked])
                .output("report", Before::ParentIsFile),
            case("lobe-parent-is-file", &lobe, &["blocker", blocked])
                .output("lobe.png", Before::ParentIsFile),
            case("fit-exists", &fit, &["OUT", exists]).output("fit.json", Before::Exists),
            case("synth-exists", &synth, &["OUT", exists]).output("set", Before::Exists),
            case("render-exists", &render, &["OUT", exists]).output("render", Before::Exists),
            case("export-exists", &export, &["OUT", exists]).output("m.xml", Before::Exists),
            case("compare-exists", &compare, &["OUT", exists]).output("report", Before::Exists),
            case("lobe-exists", &lobe, &["OUT", exists]).output("lobe.png", Before::Exists),
            case("export-to-a-folder", &export, &["OUT", "is a folder"])
                .output("folder", Before::Exists),
        ],
    );
    // The same commands with --force replace the old output by a complete new one and leave
    // nothing else beside it.
    let replaced_by = |args: &[&str], output: &str, produced: &str| {
        let folder = fx.path(&format!("force-{output}"));
        std::fs::create_dir(&folder).unwrap();
        let target = folder.join(output);
        if output.contains('.') {
            std::fs::write(&target, "the old output").unwrap();
        } else {
            std::fs::create_dir(&target).unwrap();
            std::fs::write(target.join("old.txt"), "the old output").unwrap();
        }
        let out = target.to_str().unwrap();
        let mut args: Vec<&str> = args
            .iter()
            .map(|a| if *a == "OUT" { out } else { a })
            .collect();
        args.push("--force");
        run_ok(&args);
        let produced = target.join(produced);
        let check = if output.contains('.') {
            &target
        } else {
            &produced
        };
        assert!(check.is_file(), "{args:?}: {} missing", check.display());
        assert_ne!(std::fs::read(check).unwrap(), b"the old output", "{args:?}");
        assert!(
            !target.join("old.txt").exists(),
            "{args:?}: old folder content kept"
        );
        let mut names = folder_entries(&folder);
        names.retain(|n| n != "fit.residuals");
        assert_eq!(names, vec![output.to_string()], "{args:?}: stray files");
    };
    replaced_by(&fit, "fit.json", "");
    replaced_by(&synth, "set", "capture.toml");
    replaced_by(&render, "render", "00.exr");
    replaced_by(&export, "m.xml", "");
    replaced_by(&compare, "report", "report.json");
    replaced_by(&lobe, "lobe.png", "");
}

#[test]
fn unknown_keys_warn_and_the_command_goes_on() {
    let fx = Fixture::new();
    let set = fx.manifest_variant("extra-keys", |t| {
        let t = replaced(&t, "units = \"cm\"", "units = \"cm\"\nauthor = \"me\"");
        replaced(
            &t,
            "image = \"00.exr\"",
            "image = \"00.exr\"\nshutter = 0.01",
        )
    });
    let fit_path = fx.path("fit.json");
    let (code, _, stderr) = run(&[
        "fit",
        &set,
        "-o",
        fit_path.to_str().unwrap(),
        "--quiet",
        "--max-iters",
        "5",
    ]);
    assert_eq!(code, Some(0), "{stderr}");
    for key in ["author", "photo[0].shutter"] {
        let warned = stderr.lines().any(|line| {
            line.starts_with("warning: ")
                && line.ends_with(&format!(": {key}: unknown key, ignored"))
        });
        assert!(warned, "{key}: {stderr}");
    }
    assert!(fit_path.is_file());
    // A material file with a misspelt key: warned, and the material is used without it.
    let material = fx.material_variant(
        "misspelt.json",
        "\"alpha\": 0.3,",
        "\"alpha\": 0.3, \"difuse\": [0.5, 0.5, 0.5],",
    );
    let exported = fx.path("exported.json");
    let (code, _, stderr) = run(&[
        "export",
        &material,
        "--format",
        "json",
        "-o",
        exported.to_str().unwrap(),
    ]);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(
        stderr.contains("misspelt.json: difuse: unknown key, ignored"),
        "{stderr}"
    );
    assert_eq!(triple(&read_json(&exported)["diffuse"]), [0.0; 3]);
    // A fit file's own fields are not unknown keys.
    let (code, _, stderr) = run(&[
        "export",
        fit_path.to_str().unwrap(),
        "--format",
        "json",
        "-o",
        fx.path("from-fit.json").to_str().unwrap(),
    ]);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(!stderr.contains("warning"), "{stderr}");
}

#[test]
fn non_finite_and_negative_pixels_are_excluded_and_counted() {
    let fx = Fixture::new();
    // Photo 0: 5 NaN and 3 infinite pixels; photo 1: 7 pixels with a negative channel.
    let set = fx.set_variant("holes", |f| {
        edit_exr(&f.join("00.exr"), |rgb| {
            for p in 0..5 {
                rgb[p * 11][1] = f32::NAN;
            }
            for p in 0..3 {
                rgb[100 + p][0] = f32::INFINITY;
            }
        });
        edit_exr(&f.join("01.exr"), |rgb| {
            for p in 0..7 {
                rgb[30 + 13 * p][2] = -0.25;
            }
        });
    });
    let out = fx.path("fit");
    let fit = fit_json(Path::new(&set), &["--max-iters", "20"], &out);
    let excluded = &fit["excluded"];
    assert_eq!(excluded["non_finite"], 8, "{excluded}");
    assert_eq!(excluded["negative"], 7, "{excluded}");
    assert_eq!(fit["pixels_used"], PIXELS - 15);
    assert!(fit["loss"].as_f64().unwrap().is_finite());
    // The same set on stderr, without --quiet's silence for warnings.
    let (code, _, stderr) = run(&[
        "fit",
        &set,
        "-o",
        fx.path("again.json").to_str().unwrap(),
        "--quiet",
        "--max-iters",
        "5",
    ]);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(
        stderr.contains("8 non-finite and 7 negative pixels excluded"),
        "{stderr}"
    );
}

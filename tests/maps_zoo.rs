//! The maps zoo (issue #43 item 5): random maps truths of two to four materials, laid out in
//! random shapes and photographed by random flash and side-lit captures, each synthesised and
//! fitted back by `fit --maps` at a coarse texel grid and at one texel a pixel. The fit must
//! report as many bases as the truth has materials, each of the truth's kind (metal or
//! dielectric) with its alpha within 3%.
//!
//! Case `id` is generated from `id` alone, so one case is reproduced with
//! `MAPS_ZOO_SEED=<id> MAPS_ZOO_CASES=1`. Environment:
//! - `MAPS_ZOO_SEED` (default 0): the id of the first case; cases are `SEED, SEED + 1, ...`;
//! - `MAPS_ZOO_CASES` (default 4): how many cases;
//! - `MAPS_ZOO_SIDE` (default 48): the photos' side in pixels (the script uses 128; one case in
//!   six then doubles it);
//! - `MAPS_ZOO_TABLE`: also write the table as Markdown to this file;
//! - `MAPS_ZOO_KEEP`: keep every case's folder (truth, manifests, photos, fit files) here.
//!
//! Per case:
//! - materials: a rough metal (alpha 0.3-1.2; a measured conductor's F0 or a Schlick F0 of
//!   0.5-0.98 per channel), a dielectric (Schlick F0 0.04, alpha 0.04-0.6, albedo 0.03-0.8 per
//!   channel), and zero to two more of either kind; two materials of one kind differ in alpha by
//!   at least 1.6x (closer, they are one basis whose texels differ in colour);
//! - layout: one material is the background, each other one a disc, a rectangle or a band
//!   across the sample, at least a fifth of the sample wide and 6% of its area; dielectrics'
//!   albedo sometimes varies across the sample by up to +-30%;
//! - capture: a rectified camera 18-32 cm above an 8-12 cm sample; 3-6 flash photos from
//!   cameras up to a quarter of the distance off axis, and 3-6 photos under point lights
//!   (8-25 cm up, 8-20 cm off axis) or directional lights 30-70 degrees from the normal,
//!   sometimes shuffled (the validation photo, the last, is then any of them); 6-12 photos;
//! - truth model `single`, `kulla-conty` or `tabulated`, fitted back with the same model;
//! - `synth` noise 0.5-2%, 1 or 4 sub-samples per pixel;
//! - fits: `--texels` 16, 24 or 32 (coarser than the photos), and the default grid.
//!
//! The bar is every fit at every grid. The test asserts less, what holds today, so
//! that it guards what works: at least [`DEFAULT_GRID_SHARE`] of the fits at the default grid
//! find every material. The coarse grids' fits are reported, not asserted (docs/maps-zoo.md
//! and docs/maps.md, "The maps zoo", give the misses and their mechanisms).

mod common;
use bouncefit::bsdf::Model;
use common::maps_truth::{maps_of_materials, TexelMaterial};
use common::zoo::*;
use common::*;
use std::f64::consts::PI;
use std::fmt::Write as _;
use std::time::Instant;

/// Relative alpha error of a basis that counts as off the truth.
const ALPHA_TOLERANCE: f64 = 0.03;

/// Two materials of one kind closer in alpha than this ratio would be one basis.
const DISTINCT_ALPHA_RATIO: f64 = 1.6;

/// Each material covers at least this share of the sample.
const LEAST_SHARE: f64 = 0.06;

/// The least share of the fits at the default grid (one texel a pixel) that must find every
/// material. Measured on cases 0-23 at 48^2: 20 of 24 (83%); 17 of 24 before a blend had to
/// lie on edges and a basis had to pay for itself in its texels' photos.
const DEFAULT_GRID_SHARE: f64 = 0.75;

#[derive(Clone, Copy, PartialEq, Debug)]
enum Kind {
    Metal,
    Dielectric,
}

impl Kind {
    fn label(self) -> &'static str {
        match self {
            Kind::Metal => "metal",
            Kind::Dielectric => "dielectric",
        }
    }
}

#[derive(Clone, Copy)]
struct Truth {
    kind: Kind,
    alpha: f64,
    f0: V3,
    albedo: V3,
    /// Relative change of the albedo from the sample's left edge to its right.
    gradient: f64,
}

impl Truth {
    fn at(&self, u: f64) -> TexelMaterial {
        let scale = 1.0 + self.gradient * (u - 0.5);
        (self.f0, self.alpha, self.albedo.map(|a| a * scale))
    }

    fn label(&self) -> String {
        match self.kind {
            Kind::Metal => format!(
                "metal {:.3} F0 {:.2},{:.2},{:.2}",
                self.alpha, self.f0[0], self.f0[1], self.f0[2]
            ),
            Kind::Dielectric => format!(
                "dielectric {:.3} albedo {:.2},{:.2},{:.2}",
                self.alpha, self.albedo[0], self.albedo[1], self.albedo[2]
            ),
        }
    }
}

/// Where a material lies, in the sample's `(u, v)` in [0, 1]^2.
#[derive(Clone, Copy)]
enum Shape {
    Disc {
        centre: [f64; 2],
        radius: f64,
    },
    Rectangle {
        centre: [f64; 2],
        half: [f64; 2],
    },
    /// A band across the sample along u (`along_u`) or v, centred at `at`.
    Band {
        along_u: bool,
        at: f64,
        half: f64,
    },
}

impl Shape {
    fn random(rng: &mut Rng) -> Shape {
        match rng.int(0, 2) {
            0 => Shape::Disc {
                centre: [rng.range(0.25, 0.75), rng.range(0.25, 0.75)],
                radius: rng.range(0.12, 0.28),
            },
            1 => Shape::Rectangle {
                centre: [rng.range(0.2, 0.8), rng.range(0.2, 0.8)],
                half: [rng.range(0.1, 0.25), rng.range(0.1, 0.25)],
            },
            _ => Shape::Band {
                along_u: rng.chance(0.5),
                at: rng.range(0.15, 0.85),
                half: rng.range(0.1, 0.16),
            },
        }
    }

    fn contains(&self, u: f64, v: f64) -> bool {
        match *self {
            Shape::Disc { centre, radius } => {
                (u - centre[0]).powi(2) + (v - centre[1]).powi(2) < radius * radius
            }
            Shape::Rectangle { centre, half } => {
                (u - centre[0]).abs() < half[0] && (v - centre[1]).abs() < half[1]
            }
            Shape::Band { along_u, at, half } => (if along_u { v } else { u } - at).abs() < half,
        }
    }

    fn label(&self) -> &'static str {
        match self {
            Shape::Disc { .. } => "disc",
            Shape::Rectangle { .. } => "rectangle",
            Shape::Band { .. } => "band",
        }
    }
}

struct Photo {
    /// The camera moved for this photo (flash photos), or the manifest's camera.
    camera: Option<V3>,
    light: Light,
}

struct Case {
    id: u64,
    materials: Vec<Truth>,
    /// `shapes[i]` is where `materials[i + 1]` lies; `materials[0]` is the background. A later
    /// shape covers an earlier one.
    shapes: Vec<Shape>,
    size: f64,
    camera: V3,
    photos: Vec<Photo>,
    shuffled: bool,
    side: usize,
    model: Model,
    noise: f64,
    pixel_samples: usize,
    coarse: usize,
    synth_seed: u64,
}

impl Case {
    /// Case `id`, drawn from a stream seeded by `id` alone; photos of `side` pixels.
    fn generate(id: u64, side: usize) -> Case {
        let mut rng = Rng::new(id ^ 0x6d61_7073);
        let metal = |rng: &mut Rng, alpha: f64| {
            let f0 = if rng.chance(0.5) {
                let (_, eta, k) = CONDUCTORS[rng.int(0, CONDUCTORS.len() - 1)];
                [0, 1, 2].map(|c| {
                    ((eta[c] - 1.0).powi(2) + k[c] * k[c]) / ((eta[c] + 1.0).powi(2) + k[c] * k[c])
                })
            } else {
                [0; 3].map(|_| rng.range(0.5, 0.98))
            };
            Truth {
                kind: Kind::Metal,
                alpha,
                f0,
                albedo: [0.0; 3],
                gradient: 0.0,
            }
        };
        let dielectric = |rng: &mut Rng, alpha: f64| Truth {
            kind: Kind::Dielectric,
            alpha,
            f0: [0.04; 3],
            albedo: [0; 3].map(|_| rng.range(0.03, 0.8)),
            gradient: if rng.chance(0.4) {
                rng.range(-0.6, 0.6)
            } else {
                0.0
            },
        };
        let (rough, glossy) = (rng.log_range(0.3, 1.2), rng.log_range(0.04, 0.6));
        let mut materials = vec![metal(&mut rng, rough), dielectric(&mut rng, glossy)];
        let count = rng.int(2, 4);
        while materials.len() < count {
            let kind = if rng.chance(0.5) {
                Kind::Metal
            } else {
                Kind::Dielectric
            };
            let alpha = rng.log_range(0.03, 1.2);
            let distinct = materials.iter().all(|m| {
                m.kind != kind || (alpha / m.alpha).ln().abs() >= DISTINCT_ALPHA_RATIO.ln()
            });
            if distinct {
                materials.push(match kind {
                    Kind::Metal => metal(&mut rng, alpha),
                    Kind::Dielectric => dielectric(&mut rng, alpha),
                });
            }
        }
        // Any of them may be the background.
        let background = rng.int(0, materials.len() - 1);
        materials.swap(0, background);
        let shapes = loop {
            let shapes: Vec<Shape> = (1..materials.len())
                .map(|_| Shape::random(&mut rng))
                .collect();
            let shares = shares(&shapes, materials.len());
            if shares.iter().all(|&s| s >= LEAST_SHARE) {
                break shapes;
            }
        };

        let size = rng.range(8.0, 12.0);
        let distance = rng.range(18.0, 32.0);
        let flash_intensity = distance * distance * rng.range(0.6, 1.4);
        let flashes = rng.int(3, 6);
        let lit = rng.int(3, 6);
        let camera = [
            rng.range(-0.1, 0.1) * distance,
            rng.range(-0.1, 0.1) * distance,
            distance,
        ];
        let mut photos: Vec<Photo> = (0..flashes)
            .map(|i| {
                let offset = if i == 0 {
                    [camera[0], camera[1]]
                } else {
                    let (r, a) = (rng.range(0.0, 0.25) * distance, rng.range(0.0, 2.0 * PI));
                    [r * a.cos(), r * a.sin()]
                };
                Photo {
                    camera: Some([offset[0], offset[1], distance * rng.range(0.95, 1.05)]),
                    light: Light::Flash {
                        intensity: flash_intensity,
                    },
                }
            })
            .collect();
        for _ in 0..lit {
            let azimuth = rng.range(0.0, 2.0 * PI);
            let light = if rng.chance(0.75) {
                let (r, h) = (rng.range(8.0, 20.0), rng.range(8.0, 25.0));
                Light::Point {
                    position: [r * azimuth.cos(), r * azimuth.sin(), h],
                    intensity: (r * r + h * h) * rng.range(0.6, 1.4),
                }
            } else {
                Light::Directional {
                    direction: spherical(rng.range(30.0, 70.0), azimuth, 1.0),
                    irradiance: rng.range(0.6, 1.4),
                }
            };
            photos.push(Photo {
                camera: None,
                light,
            });
        }
        let shuffled = rng.chance(0.3);
        if shuffled {
            for i in (1..photos.len()).rev() {
                photos.swap(i, rng.int(0, i));
            }
        }
        let model = match rng.int(0, 2) {
            0 => Model::Single,
            1 => Model::KullaConty,
            _ => Model::Tabulated,
        };
        let noise = rng.range(0.005, 0.02);
        let pixel_samples = if rng.chance(0.3) { 1 } else { 4 };
        let coarse = [16, 24, 32][rng.int(0, 2)];
        let side = if side >= 128 && rng.chance(1.0 / 6.0) {
            2 * side
        } else {
            side
        };
        Case {
            id,
            materials,
            shapes,
            size,
            camera,
            photos,
            shuffled,
            side,
            model,
            noise,
            pixel_samples,
            coarse,
            synth_seed: rng.next_u64() >> 16,
        }
    }

    /// The index of the material at `(u, v)`.
    fn material_at(&self, u: f64, v: f64) -> usize {
        material_at(&self.shapes, u, v)
    }

    fn truth_maps(&self) -> bouncefit::maps::MaterialMaps {
        maps_of_materials(self.model, self.side, |u, v| {
            self.materials[self.material_at(u, v)].at(u)
        })
    }

    fn capture_toml(&self) -> String {
        let mut t = String::new();
        writeln!(t, "# maps zoo case {}", self.id).unwrap();
        writeln!(
            t,
            "name = \"maps-zoo-{}\"\nunits = \"cm\"\n[sample]\nwidth = {:.4}\nheight = {:.4}\n\
             [camera]\nmodel = \"rectified\"\nposition = {}\nresolution = [{}, {}]\n",
            self.id,
            self.size,
            self.size,
            toml_v3(self.camera),
            self.side,
            self.side
        )
        .unwrap();
        for (i, photo) in self.photos.iter().enumerate() {
            writeln!(t, "[[photo]]\nimage = \"{i:02}.exr\"").unwrap();
            if let Some(camera) = photo.camera {
                writeln!(t, "camera = {{ position = {} }}", toml_v3(camera)).unwrap();
            }
            writeln!(t, "light = {}\n", photo.light.toml()).unwrap();
        }
        t
    }

    fn materials_label(&self) -> String {
        let shares = shares(&self.shapes, self.materials.len());
        self.materials
            .iter()
            .enumerate()
            .map(|(i, m)| {
                let shape = if i == 0 {
                    "background"
                } else {
                    self.shapes[i - 1].label()
                };
                format!("{} ({shape}, {:.0}%)", m.label(), 100.0 * shares[i])
            })
            .collect::<Vec<_>>()
            .join("; ")
    }

    fn capture_label(&self) -> String {
        let count = |f: fn(&Light) -> bool| self.photos.iter().filter(|p| f(&p.light)).count();
        format!(
            "{:.0} cm at {:.0} cm, {}px, flash {}, point {}, directional {}{}",
            self.size,
            self.camera[2],
            self.side,
            count(|l| matches!(l, Light::Flash { .. })),
            count(|l| matches!(l, Light::Point { .. })),
            count(|l| matches!(l, Light::Directional { .. })),
            if self.shuffled { ", shuffled" } else { "" }
        )
    }
}

fn material_at(shapes: &[Shape], u: f64, v: f64) -> usize {
    shapes
        .iter()
        .rposition(|s| s.contains(u, v))
        .map_or(0, |i| i + 1)
}

/// Each material's share of the sample, on a 64 x 64 grid.
fn shares(shapes: &[Shape], materials: usize) -> Vec<f64> {
    let mut counts = vec![0usize; materials];
    for t in 0..64 * 64 {
        let (u, v) = (
            ((t % 64) as f64 + 0.5) / 64.0,
            ((t / 64) as f64 + 0.5) / 64.0,
        );
        counts[material_at(shapes, u, v)] += 1;
    }
    counts.iter().map(|&c| c as f64 / 4096.0).collect()
}

/// A basis a fit reported.
struct Basis {
    kind: String,
    alpha: f64,
    share: f64,
}

/// The bases of a maps fit file, in increasing alpha.
fn bases(fit: &serde_json::Value) -> Vec<Basis> {
    let mut bases: Vec<Basis> = fit["maps_fit"]["bases"]
        .as_array()
        .unwrap()
        .iter()
        .map(|b| Basis {
            kind: b["kind"].as_str().unwrap().to_string(),
            alpha: b["alpha"].as_f64().unwrap(),
            share: b["share"].as_f64().unwrap(),
        })
        .collect();
    bases.sort_by(|a, b| a.alpha.total_cmp(&b.alpha));
    bases
}

/// Why the reported `bases` are not the truth's `materials` (`None`: they are): each material
/// needs a basis of its kind with its alpha within [`ALPHA_TOLERANCE`], and no basis is left.
fn mismatch(materials: &[Truth], bases: &[Basis]) -> Option<String> {
    let mut unmatched: Vec<&Basis> = bases.iter().collect();
    let mut problems = Vec::new();
    let mut truth: Vec<&Truth> = materials.iter().collect();
    truth.sort_by(|a, b| a.alpha.total_cmp(&b.alpha));
    for m in truth {
        let best = unmatched
            .iter()
            .enumerate()
            .filter(|(_, b)| b.kind == m.kind.label())
            .min_by(|a, b| {
                let d = |x: &Basis| (x.alpha / m.alpha).ln().abs();
                d(a.1).total_cmp(&d(b.1))
            })
            .map(|(i, b)| (i, b.alpha));
        match best {
            Some((i, alpha)) if (alpha / m.alpha - 1.0).abs() <= ALPHA_TOLERANCE => {
                unmatched.remove(i);
            }
            Some((_, alpha)) => problems.push(format!(
                "{} {:.3} fitted at {alpha:.3}",
                m.kind.label(),
                m.alpha
            )),
            None => problems.push(format!("{} {:.3} lost", m.kind.label(), m.alpha)),
        }
    }
    if problems.is_empty() && !unmatched.is_empty() {
        problems.extend(
            unmatched
                .iter()
                .map(|b| format!("extra {} {:.3}", b.kind, b.alpha)),
        );
    }
    (!problems.is_empty()).then(|| problems.join(", "))
}

/// One fit of a case: its texel grid, the bases it reported and what is wrong with them.
struct FitRow {
    texels: Option<usize>,
    outcome: Result<(Vec<Basis>, Option<String>), String>,
}

impl FitRow {
    fn miss(&self) -> bool {
        !matches!(self.outcome, Ok((_, None)))
    }

    fn grid(&self, side: usize) -> String {
        let n = self.texels.unwrap_or(side);
        format!("{n}^2")
    }

    fn bases_label(&self) -> String {
        match &self.outcome {
            Ok((bases, _)) => bases
                .iter()
                .map(|b| format!("{} {:.3} ({:.0}%)", b.kind, b.alpha, 100.0 * b.share))
                .collect::<Vec<_>>()
                .join(", "),
            Err(e) => format!("error: {e}"),
        }
    }

    fn verdict(&self) -> String {
        match &self.outcome {
            Ok((_, None)) => "-".into(),
            Ok((_, Some(why))) => format!("MISS: {why}"),
            Err(_) => "MISS: error".into(),
        }
    }
}

struct Row {
    case: Case,
    fits: Vec<FitRow>,
    seconds: f64,
}

fn run_case(case: Case) -> Row {
    let started = Instant::now();
    let dir = tempfile::tempdir().unwrap();
    let _keep = KeepOnDrop(dir.path().to_path_buf(), case.id, "MAPS_ZOO_KEEP");
    let material = dir.path().join("truth.json");
    let capture = dir.path().join("capture.toml");
    let set = dir.path().join("set");
    let model = serde_json::to_value(case.model).unwrap();
    let model = model.as_str().unwrap().to_string();
    let synthesised = (|| {
        case.truth_maps()
            .save(&material, Default::default())
            .map_err(|e| e.to_string())?;
        std::fs::write(&capture, case.capture_toml()).unwrap();
        let files = (material.as_path(), capture.as_path(), set.as_path());
        synth_case(files, case.noise, case.pixel_samples, case.synth_seed)
    })();
    let fits = [Some(case.coarse), None]
        .into_iter()
        .map(|texels| {
            let outcome = synthesised.clone().and_then(|()| {
                let out = dir
                    .path()
                    .join(texels.map_or("default".into(), |n| n.to_string()));
                std::fs::create_dir_all(&out).unwrap();
                let grid = texels.map(|n| format!("{n}x{n}"));
                let mut args = vec!["--maps", "--models", &model];
                if let Some(grid) = &grid {
                    args.extend(["--texels", grid]);
                }
                let fit = try_fit_json(&set, &args, &out)?;
                let bases = bases(&fit);
                let why = mismatch(&case.materials, &bases);
                Ok((bases, why))
            });
            FitRow { texels, outcome }
        })
        .collect();
    Row {
        case,
        fits,
        seconds: started.elapsed().as_secs_f64(),
    }
}

const HEADER: [&str; 9] = [
    "case",
    "truth (kind alpha, shape, share)",
    "capture",
    "model",
    "synth",
    "texels",
    "fitted bases (kind alpha, share)",
    "verdict",
    "s",
];

impl Row {
    fn lines(&self) -> Vec<Vec<String>> {
        let c = &self.case;
        let model = serde_json::to_value(c.model).unwrap();
        self.fits
            .iter()
            .map(|fit| {
                vec![
                    c.id.to_string(),
                    c.materials_label(),
                    c.capture_label(),
                    model.as_str().unwrap().to_string(),
                    format!("{:.1}% {}spp", 100.0 * c.noise, c.pixel_samples),
                    fit.grid(c.side),
                    fit.bases_label(),
                    fit.verdict(),
                    format!("{:.1}", self.seconds),
                ]
            })
            .collect()
    }
}

fn markdown(rows: &[Row], seed: u64, side: usize, misses: usize, seconds: f64) -> String {
    let fits: usize = rows.iter().map(|r| r.fits.len()).sum();
    let found = |default: bool| {
        let of: Vec<&FitRow> = rows
            .iter()
            .flat_map(|r| &r.fits)
            .filter(|f| f.texels.is_none() == default)
            .collect();
        format!(
            "{} of {}",
            of.iter().filter(|f| !f.miss()).count(),
            of.len()
        )
    };
    let mut t = String::new();
    writeln!(t, "# The maps zoo\n").unwrap();
    writeln!(
        t,
        "`MAPS_ZOO_SEED={seed} MAPS_ZOO_CASES={} MAPS_ZOO_SIDE={side} cargo test --release \
         --test maps_zoo -- --nocapture` (tests/maps_zoo.rs, scripts/maps-zoo.sh): random maps \
         truths of two to four materials fitted back by `fit --maps` at a coarse texel grid and \
         at one texel a pixel. A fit misses unless it reports one basis per material, of its \
         kind, with its alpha within {:.0}%. Case `id` is reproduced alone by \
         `MAPS_ZOO_SEED=id MAPS_ZOO_CASES=1`.\n",
        rows.len(),
        100.0 * ALPHA_TOLERANCE
    )
    .unwrap();
    writeln!(
        t,
        "{} cases, {fits} fits, {misses} missed, {seconds:.0} s. Every material found: {} fits \
         at the default grid, {} at the coarse grid.\n",
        rows.len(),
        found(true),
        found(false)
    )
    .unwrap();
    writeln!(t, "| {} |", HEADER.join(" | ")).unwrap();
    writeln!(t, "|{}", " --- |".repeat(HEADER.len())).unwrap();
    for row in rows {
        for line in row.lines() {
            writeln!(t, "| {} |", line.join(" | ")).unwrap();
        }
    }
    t
}

#[test]
fn maps_fits_find_every_material_of_random_truths() {
    let seed = env_number("MAPS_ZOO_SEED", 0);
    let cases = env_number("MAPS_ZOO_CASES", 8);
    let side = env_number("MAPS_ZOO_SIDE", 48) as usize;
    let started = Instant::now();
    println!("{}", HEADER.join("\t"));
    let rows: Vec<Row> = (0..cases)
        .map(|i| {
            let row = run_case(Case::generate(seed + i, side));
            for line in row.lines() {
                println!("{}", line.join("\t"));
            }
            row
        })
        .collect();
    let seconds = started.elapsed().as_secs_f64();
    let misses = rows
        .iter()
        .flat_map(|r| &r.fits)
        .filter(|f| f.miss())
        .count();
    let default_fits: Vec<&FitRow> = rows
        .iter()
        .flat_map(|r| &r.fits)
        .filter(|f| f.texels.is_none())
        .collect();
    let found = default_fits.iter().filter(|f| !f.miss()).count();
    let table = markdown(&rows, seed, side, misses, seconds);
    if let Ok(path) = std::env::var("MAPS_ZOO_TABLE") {
        std::fs::write(&path, &table).unwrap_or_else(|e| panic!("MAPS_ZOO_TABLE={path}: {e}"));
    }
    println!(
        "maps zoo: {} cases from seed {seed}, {misses} fits missed, {seconds:.1} s",
        rows.len()
    );
    assert!(
        found as f64 >= DEFAULT_GRID_SHARE * default_fits.len() as f64,
        "{found} of {} fits at the default grid found every material (at least {:.0}% must):\n{table}",
        default_fits.len(),
        100.0 * DEFAULT_GRID_SHARE
    );
}

//! Fuzzing the parsers (issue #6 item 5): arbitrary bytes, and valid inputs with random
//! mutations, fed straight to the library's loaders. Every loader must return `Ok` or `Err`;
//! a panic (or an abort) fails the test. proptest shrinks a failure to a minimal input and
//! prints it: fix the root cause and keep the input as a unit test of the loader (as
//! `image_io`'s test of an EXR header claiming too many pixels, found here).
//!
//! | property | seeds | loader |
//! | --- | --- | --- |
//! | [`arbitrary_bytes`] | none | every loader below |
//! | [`mutated_manifests`] | `datasets/sources/*.capture.toml`, `datasets/*/capture.toml` | `Capture::open`, then `ShadingRecords::build` for small sets |
//! | [`mutated_materials`] | `fits/*.json`, `datasets/*/material.json`, test fit files | `Material::load_with_warnings`, then every export format |
//! | [`mutated_materialgan_folders`] | a valid 2-photo folder (txt and JSON calibration) | `materialgan::import` via `Capture::open` |
//! | [`mutated_images`] | 8- and 16-bit PNG, JPEG, EXR of every compression, scan lines and tiles | `load_image`, `load_mask` |
//!
//! Mutations are byte-level (flips, truncation, insertion, removal) and, for the text formats,
//! token-level: a number replaced by a hostile one (`nan`, `1e999`, `-0`, `2^64`, ...), a line
//! deleted or duplicated, so that mutated files get past the syntax check into the field checks.

use bouncefit::capture::image_io::{load_image, load_mask, write_exr};
use bouncefit::capture::{Capture, ColorEncoding};
use bouncefit::export::{gltf, json, materialx, mitsuba, Conversion};
use bouncefit::material::Material;
use bouncefit::shading::ShadingRecords;
use proptest::prelude::*;
use proptest::test_runner::TestRunner;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

fn repo(path: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(path)
}

/// Numbers that have broken parsers and geometry code before: zero and signed zero,
/// negatives, overflow to infinity, subnormals, the names of non-finite values, integers past
/// `u32` and `u64`, and non-numbers where a number belongs.
const HOSTILE_NUMBERS: [&str; 20] = [
    "0",
    "-0",
    "-1",
    "-1e-300",
    "1e999",
    "-1e999",
    "1e-320",
    "1e308",
    "nan",
    "inf",
    "-inf",
    "NaN",
    "4294967296",
    "18446744073709551616",
    "99999999",
    "65536",
    "0.5",
    "\"x\"",
    "[]",
    "true",
];

#[derive(Clone, Debug)]
enum Mutation {
    /// XOR the byte at `at` (modulo the length) with `bits`.
    Flip {
        at: usize,
        bits: u8,
    },
    /// Keep the first `at` bytes (modulo the length + 1).
    Truncate {
        at: usize,
    },
    Insert {
        at: usize,
        bytes: Vec<u8>,
    },
    Remove {
        at: usize,
        len: usize,
    },
    /// Replace the `which`-th number of the text (modulo their count) by a hostile one.
    Number {
        which: usize,
        hostile: usize,
    },
    DeleteLine {
        which: usize,
    },
    DuplicateLine {
        which: usize,
    },
}

fn byte_mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        (any::<usize>(), 1..=255u8).prop_map(|(at, bits)| Mutation::Flip { at, bits }),
        any::<usize>().prop_map(|at| Mutation::Truncate { at }),
        (any::<usize>(), prop::collection::vec(any::<u8>(), 1..8))
            .prop_map(|(at, bytes)| Mutation::Insert { at, bytes }),
        (any::<usize>(), 1..64usize).prop_map(|(at, len)| Mutation::Remove { at, len }),
    ]
}

fn text_mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        1 => byte_mutation(),
        3 => (any::<usize>(), 0..HOSTILE_NUMBERS.len())
            .prop_map(|(which, hostile)| Mutation::Number { which, hostile }),
        1 => any::<usize>().prop_map(|which| Mutation::DeleteLine { which }),
        1 => any::<usize>().prop_map(|which| Mutation::DuplicateLine { which }),
    ]
}

/// Byte ranges of the numbers in `text`: an optional minus, then digits, dots, exponents.
fn number_spans(text: &[u8]) -> Vec<(usize, usize)> {
    let mut spans = Vec::new();
    let mut i = 0;
    while i < text.len() {
        let starts = text[i].is_ascii_digit()
            || (text[i] == b'-' && text.get(i + 1).is_some_and(u8::is_ascii_digit));
        let inside_word = i > 0 && (text[i - 1].is_ascii_alphanumeric() || text[i - 1] == b'_');
        if starts && !inside_word {
            let start = i;
            i += 1;
            while i < text.len()
                && (text[i].is_ascii_digit()
                    || matches!(text[i], b'.' | b'e' | b'E')
                    || (matches!(text[i], b'+' | b'-') && matches!(text[i - 1], b'e' | b'E')))
            {
                i += 1;
            }
            spans.push((start, i));
        } else {
            i += 1;
        }
    }
    spans
}

/// Byte ranges of the lines of `bytes`, newline included.
fn line_spans(bytes: &[u8]) -> Vec<(usize, usize)> {
    let mut spans = Vec::new();
    let mut start = 0;
    for (i, b) in bytes.iter().enumerate() {
        if *b == b'\n' {
            spans.push((start, i + 1));
            start = i + 1;
        }
    }
    if start < bytes.len() {
        spans.push((start, bytes.len()));
    }
    spans
}

fn mutate(mut bytes: Vec<u8>, mutations: &[Mutation]) -> Vec<u8> {
    for mutation in mutations {
        let len = bytes.len();
        match mutation {
            Mutation::Flip { at, bits } if len > 0 => bytes[at % len] ^= bits,
            Mutation::Flip { .. } => {}
            Mutation::Truncate { at } => bytes.truncate(at % (len + 1)),
            Mutation::Insert { at, bytes: new } => {
                let at = at % (len + 1);
                bytes.splice(at..at, new.iter().copied());
            }
            Mutation::Remove { at, len: n } => {
                let at = at % (len + 1);
                bytes.drain(at..(at + n).min(len));
            }
            Mutation::Number { which, hostile } => {
                let spans = number_spans(&bytes);
                if !spans.is_empty() {
                    let (start, end) = spans[which % spans.len()];
                    bytes.splice(start..end, HOSTILE_NUMBERS[*hostile].bytes());
                }
            }
            Mutation::DeleteLine { which } | Mutation::DuplicateLine { which } => {
                let spans = line_spans(&bytes);
                if !spans.is_empty() {
                    let (start, end) = spans[which % spans.len()];
                    if matches!(mutation, Mutation::DeleteLine { .. }) {
                        bytes.drain(start..end);
                    } else {
                        let line = bytes[start..end].to_vec();
                        bytes.splice(end..end, line);
                    }
                }
            }
        }
    }
    bytes
}

fn read_all(paths: &[&str]) -> Vec<Vec<u8>> {
    paths
        .iter()
        .map(|p| std::fs::read(repo(p)).unwrap_or_else(|e| panic!("{p}: {e}")))
        .collect()
}

/// Opening the capture and, when it is small, building its shading records (which exercises
/// the camera and light geometry on whatever values got through the checks).
fn open_capture(path: &Path) {
    if let Ok(capture) = Capture::open(path) {
        let pixels: usize = capture
            .photos
            .iter()
            .map(|p| p.camera.resolution().iter().product::<usize>())
            .fold(0, usize::saturating_add);
        if pixels <= 4096 {
            let _ = ShadingRecords::build(&capture, 1, false);
        }
    }
}

/// Loading the material and, when valid, converting it to every export format.
fn load_material(path: &Path) {
    if let Ok((material, _)) = Material::load_with_warnings(path) {
        let conversion = Conversion::new(&material);
        json::document(&conversion);
        gltf::document(&conversion);
        materialx::document(&conversion);
        mitsuba::document(&conversion, &mitsuba::Scene::default_flash("fuzz"));
    }
}

fn load_images(path: &Path) {
    for encoding in [
        ColorEncoding::Srgb,
        ColorEncoding::Linear,
        ColorEncoding::Gamma(2.2),
    ] {
        let _ = load_image(path, encoding);
    }
    let _ = load_mask(path, 4, 3);
}

/// The calibration files (name, content) of a MaterialGAN folder of two photos, as text
/// (`json` false) or as `parameters.json`.
fn materialgan_calibration(json: bool) -> Vec<(&'static str, Vec<u8>)> {
    if json {
        vec![(
            "parameters.json",
            br#"{"camera_pos": [[0.0, 0.0, 18.0], [1.0, 2.0, 17.0]],
 "light_pos": [0.0, 0.0, 18.0], "light_pow": [1500.0, 1500.0, 1500.0],
 "im_size": 8.0, "idx": [0, 1]}"#
                .to_vec(),
        )]
    } else {
        vec![
            ("camera_pos.txt", b"0,0,18\n1,2,17\n".to_vec()),
            ("light_pos.txt", b"0 0 18\n".to_vec()),
            ("light_power.txt", b"1500,1500,1500\n".to_vec()),
            ("image_size.txt", b"8\n".to_vec()),
        ]
    }
}

/// An RGB EXR of 16x16 pixels with `compression`, in scan lines or 8x8 tiles.
fn exr_seed(compression: exr::prelude::Compression, tiles: bool) -> Vec<u8> {
    use exr::prelude::*;
    let channels = SpecificChannels::rgb(|Vec2(x, y)| (x as f32 * 0.1, y as f32, 0.5f32));
    let blocks = if tiles {
        Blocks::Tiles(Vec2(8, 8))
    } else {
        Blocks::ScanLines
    };
    let encoding = Encoding {
        compression,
        blocks,
        line_order: LineOrder::Increasing,
    };
    let layer = Layer::new((16, 16), LayerAttributes::default(), encoding, channels);
    let mut bytes = Vec::new();
    Image::from_layer(layer)
        .write()
        .to_buffered(std::io::Cursor::new(&mut bytes))
        .unwrap();
    bytes
}

/// Small valid images, `(file name, bytes)`: an 8-bit PNG first (the MaterialGAN photos), a
/// 16-bit PNG with alpha, a JPEG, our own EXR writer's output, and EXRs with every lossless
/// and lossy compression of OpenEXR the `exr` crate writes, in scan lines and tiles.
fn image_seeds() -> &'static [(String, Vec<u8>)] {
    static SEEDS: OnceLock<Vec<(String, Vec<u8>)>> = OnceLock::new();
    SEEDS.get_or_init(|| {
        use exr::prelude::Compression;
        let dir = tempfile::tempdir().unwrap();
        let file = |name: &str| dir.path().join(name);
        image::RgbImage::from_fn(4, 3, |x, y| image::Rgb([x as u8 * 60, y as u8 * 80, 255]))
            .save(file("a.png"))
            .unwrap();
        image::ImageBuffer::<image::Rgba<u16>, _>::from_fn(4, 3, |x, y| {
            image::Rgba([x as u16 * 9000, y as u16 * 20000, 65535, 1])
        })
        .save(file("b.png"))
        .unwrap();
        image::RgbImage::from_fn(4, 3, |x, _| image::Rgb([x as u8 * 60, 10, 200]))
            .save(file("c.jpg"))
            .unwrap();
        let rgb: Vec<[f32; 3]> = (0..12).map(|i| [i as f32 * 0.1, 0.5, 2.0]).collect();
        write_exr(&file("d.exr"), &rgb, 4, 3).unwrap();
        let mut seeds: Vec<(String, Vec<u8>)> = ["a.png", "b.png", "c.jpg", "d.exr"]
            .iter()
            .map(|name| (name.to_string(), std::fs::read(file(name)).unwrap()))
            .collect();
        let compressions = [
            Compression::Uncompressed,
            Compression::RLE,
            Compression::ZIP1,
            Compression::ZIP16,
            Compression::PIZ,
            Compression::PXR24,
            Compression::B44,
            Compression::B44A,
        ];
        for (i, compression) in compressions.into_iter().enumerate() {
            for tiles in [false, true] {
                let name = format!("e{i}{}.exr", if tiles { "t" } else { "s" });
                seeds.push((name, exr_seed(compression, tiles)));
            }
        }
        seeds
    })
}

/// A scratch folder for one property's cases (each case overwrites the files of the one before:
/// creating and removing a folder per case would cost more than the parsing), in memory
/// (`/dev/shm`) where there is one: on a busy disk each small write can take milliseconds.
fn scratch_folder() -> tempfile::TempDir {
    let memory = Path::new("/dev/shm");
    if memory.is_dir() {
        tempfile::tempdir_in(memory).unwrap()
    } else {
        tempfile::tempdir().unwrap()
    }
}

/// Runs `property` on `cases` values of `strategy` (times `BOUNCEFIT_FUZZ_SCALE`, default 1,
/// for longer runs: `BOUNCEFIT_FUZZ_SCALE=100 cargo test --release --test fuzz_parsers`) in a
/// scratch folder removed afterwards. A panic fails the test with the shrunk, minimal input.
fn fuzz<S: Strategy>(cases: u32, strategy: S, property: impl Fn(&Path, S::Value)) {
    let scale = std::env::var("BOUNCEFIT_FUZZ_SCALE")
        .ok()
        .and_then(|s| s.parse::<u32>().ok())
        .unwrap_or(1);
    let config = ProptestConfig {
        cases: cases.saturating_mul(scale),
        failure_persistence: None,
        ..ProptestConfig::default()
    };
    let scratch = scratch_folder();
    let result = TestRunner::new(config).run(&strategy, |value| {
        property(scratch.path(), value);
        Ok(())
    });
    if let Err(failure) = result {
        panic!("{failure}");
    }
}

/// Arbitrary bytes under every name a loader looks for.
#[test]
fn arbitrary_bytes() {
    let bytes = prop::collection::vec(any::<u8>(), 0..512);
    fuzz(4000, bytes, |dir, bytes| {
        for name in ["capture.toml", "m.json", "x.exr", "x.png", "x.jpg"] {
            std::fs::write(dir.join(name), &bytes).unwrap();
        }
        open_capture(&dir.join("capture.toml"));
        load_material(&dir.join("m.json"));
        for name in ["x.exr", "x.png", "x.jpg"] {
            load_images(&dir.join(name));
        }
        for file in ["camera_pos.txt", "parameters.json"] {
            let folder = dir.join(format!("arbitrary-{file}"));
            std::fs::create_dir_all(&folder).unwrap();
            std::fs::write(folder.join(file), &bytes).unwrap();
            open_capture(&folder);
        }
    });
}

#[test]
fn mutated_manifests() {
    let seeds = read_all(&[
        "datasets/sources/copper-flash.capture.toml",
        "datasets/sources/aluminium-pinhole.capture.toml",
        "datasets/copper-flash/capture.toml",
        "datasets/aluminium-pinhole/capture.toml",
    ]);
    let cases = (0..seeds.len(), prop::collection::vec(text_mutation(), 1..6));
    fuzz(4000, cases, |dir, (seed, mutations)| {
        let path = dir.join("capture.toml");
        std::fs::write(&path, mutate(seeds[seed].clone(), &mutations)).unwrap();
        open_capture(&path);
    });
}

#[test]
fn mutated_materialgan_folders() {
    let cases = (
        any::<bool>(),
        any::<usize>(),
        prop::collection::vec(text_mutation(), 1..4),
    );
    fuzz(4000, cases, |dir, (json, file, mutations)| {
        let dir = dir.join(if json { "json" } else { "txt" });
        std::fs::create_dir_all(&dir).unwrap();
        let calibration = materialgan_calibration(json);
        let target = file % calibration.len();
        for (i, (name, bytes)) in calibration.into_iter().enumerate() {
            let bytes = if i == target {
                mutate(bytes, &mutations)
            } else {
                bytes
            };
            std::fs::write(dir.join(name), bytes).unwrap();
        }
        for photo in ["00.png", "01.png"] {
            std::fs::write(dir.join(photo), &image_seeds()[0].1).unwrap();
        }
        open_capture(&dir);
    });
}

#[test]
fn mutated_images() {
    let cases = (
        0..image_seeds().len(),
        prop::collection::vec(byte_mutation(), 1..4),
    );
    fuzz(4000, cases, |dir, (seed, mutations)| {
        let (name, bytes) = &image_seeds()[seed];
        let path = dir.join(name);
        std::fs::write(&path, mutate(bytes.clone(), &mutations)).unwrap();
        load_images(&path);
    });
}

/// Fewer cases: a valid material goes on through every export format (about 2 ms).
#[test]
fn mutated_materials() {
    let seeds = read_all(&[
        "fits/copper-flash.json",
        "fits/aluminium-pinhole.json",
        "datasets/copper-flash/material.json",
        "datasets/sources/aluminium-a05.material.json",
        "tests/data/export/copper-flash-conductor.fit.json",
        "tests/data/export/copper-flash-kulla-conty.fit.json",
    ]);
    let cases = (0..seeds.len(), prop::collection::vec(text_mutation(), 1..6));
    fuzz(1500, cases, |dir, (seed, mutations)| {
        let path = dir.join("m.json");
        std::fs::write(&path, mutate(seeds[seed].clone(), &mutations)).unwrap();
        load_material(&path);
    });
}

#[test]
fn mutations_reach_numbers_and_lines() {
    let text = b"a = 1.5e-3\nb = [-2, x3]\n";
    let spans: Vec<&[u8]> = number_spans(text)
        .into_iter()
        .map(|(s, e)| &text[s..e])
        .collect();
    assert_eq!(spans, vec![&b"1.5e-3"[..], b"-2"]);
    let nan = mutate(
        text.to_vec(),
        &[Mutation::Number {
            which: 1,
            hostile: 8,
        }],
    );
    assert_eq!(nan, b"a = 1.5e-3\nb = [nan, x3]\n");
    let doubled = mutate(text.to_vec(), &[Mutation::DuplicateLine { which: 0 }]);
    assert_eq!(doubled, b"a = 1.5e-3\na = 1.5e-3\nb = [-2, x3]\n");
    let deleted = mutate(text.to_vec(), &[Mutation::DeleteLine { which: 3 }]);
    assert_eq!(deleted, b"a = 1.5e-3\n");
}

//! libFuzzer target for every loader of user files. The first input byte picks the loader, the
//! rest is the file's content; any panic or abort is a finding. The proptest counterpart that
//! runs with `cargo test` is `tests/fuzz_parsers.rs`.
#![no_main]

use bouncefit::capture::image_io::load_image;
use bouncefit::capture::{Capture, ColorEncoding};
use bouncefit::material::Material;
use libfuzzer_sys::fuzz_target;
use std::path::PathBuf;
use std::sync::OnceLock;

/// File names that select each loader (the extension decides the image decoder).
const NAMES: [&str; 5] = ["capture.toml", "material.json", "x.exr", "x.png", "x.jpg"];

/// This process's scratch folder, in memory where `/dev/shm` exists.
fn scratch() -> &'static PathBuf {
    static FOLDER: OnceLock<PathBuf> = OnceLock::new();
    FOLDER.get_or_init(|| {
        let base = if std::path::Path::new("/dev/shm").is_dir() {
            PathBuf::from("/dev/shm")
        } else {
            std::env::temp_dir()
        };
        let folder = base.join(format!("bouncefit-fuzz-{}", std::process::id()));
        std::fs::create_dir_all(&folder).unwrap();
        folder
    })
}

fuzz_target!(|data: &[u8]| {
    let Some((&which, content)) = data.split_first() else {
        return;
    };
    let path = scratch().join(NAMES[usize::from(which) % NAMES.len()]);
    std::fs::write(&path, content).unwrap();
    match usize::from(which) % NAMES.len() {
        0 => drop(Capture::open(&path)),
        1 => drop(Material::load_with_warnings(&path)),
        _ => drop(load_image(&path, ColorEncoding::Srgb)),
    }
});

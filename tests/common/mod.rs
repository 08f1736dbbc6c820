//! Helpers shared by the integration tests: run the binary, read JSON, compare with truth.
#![allow(dead_code)]

pub mod maps_truth;
pub mod zoo;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

pub fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_bouncefit"))
}

pub fn repo(path: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(path)
}

/// `../shared/<path>`, beside the project (data with no licence to commit, read in place), or
/// `None` with a message saying the test skipped where it is absent.
pub fn shared(path: &str) -> Option<PathBuf> {
    let full = repo(&format!("../shared/{path}"));
    if full.exists() {
        return Some(full);
    }
    eprintln!(
        "skipped: no {} (it lives in ../shared, beside the project)",
        full.display()
    );
    None
}

/// Run the binary, assert success, return stdout.
pub fn run_ok(args: &[&str]) -> String {
    let out = bin().args(args).output().expect("binary runs");
    assert!(
        out.status.success(),
        "bouncefit {args:?} failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

/// Run the binary; returns the exit code, stdout and stderr.
pub fn run(args: &[&str]) -> (Option<i32>, String, String) {
    let out: Output = bin().args(args).output().expect("binary runs");
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// Run the binary expecting the bad-input exit status 2 without a panic; returns stderr.
pub fn run_bad(args: &[&str]) -> String {
    let (stderr, problems) = run_bad_problems(args);
    assert!(problems.is_empty(), "{}", problems.join("\n"));
    stderr
}

/// Runs a command that should fail on bad input; returns stderr and what is wrong with the
/// failure (not exit status 2, a panic), so that a table of cases can report every broken one.
pub fn run_bad_problems(args: &[&str]) -> (String, Vec<String>) {
    let (code, _, stderr) = run(args);
    let mut problems = Vec::new();
    if code != Some(2) {
        problems.push(format!(
            "bouncefit {args:?} should exit 2, got {code:?}, stderr:\n{stderr}"
        ));
    }
    if stderr.contains("panicked") {
        problems.push(format!("panic on bad input: {stderr}"));
    }
    (stderr, problems)
}

/// Names of the entries of `folder`, sorted.
pub fn folder_entries(folder: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(folder)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

/// The PNG's width and height.
pub fn png_size(path: &Path) -> (u32, u32) {
    image::image_dimensions(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

pub fn read_json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// A JSON array of strings.
pub fn strings(v: &serde_json::Value) -> Vec<&str> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|p| p.as_str().unwrap())
        .collect()
}

pub fn triple(v: &serde_json::Value) -> [f64; 3] {
    [0, 1, 2].map(|i| v[i].as_f64().unwrap())
}

/// F0 of a material file's Fresnel.
pub fn material_f0(material: &serde_json::Value) -> [f64; 3] {
    let fresnel = &material["fresnel"];
    match fresnel["kind"].as_str().unwrap() {
        "conductor" => {
            let (eta, k) = (triple(&fresnel["eta"]), triple(&fresnel["k"]));
            [0, 1, 2].map(|c| {
                ((eta[c] - 1.0).powi(2) + k[c] * k[c]) / ((eta[c] + 1.0).powi(2) + k[c] * k[c])
            })
        }
        "schlick" => triple(&fresnel["f0"]),
        other => panic!("no F0 for {other}"),
    }
}

/// `bouncefit fit SET -o OUT/fit.json --quiet --force EXTRA...`: the fit file, or what the
/// command printed when it failed.
pub fn try_fit_json(set: &Path, extra: &[&str], out: &Path) -> Result<serde_json::Value, String> {
    let fit_path = out.join("fit.json");
    let mut args = vec![
        "fit",
        set.to_str().unwrap(),
        "-o",
        fit_path.to_str().unwrap(),
        "--quiet",
        "--force",
    ];
    args.extend_from_slice(extra);
    let (code, _, stderr) = run(&args);
    if code != Some(0) {
        return Err(format!("fit {extra:?} exited {code:?}: {}", stderr.trim()));
    }
    Ok(read_json(&fit_path))
}

/// `bouncefit fit SET -o OUT/fit.json --quiet --force EXTRA...`; returns the fit file.
pub fn fit_json(set: &Path, extra: &[&str], out: &Path) -> serde_json::Value {
    try_fit_json(set, extra, out).unwrap_or_else(|e| panic!("{e}"))
}

/// `bouncefit synth --material M --capture C -o OUT EXTRA...`, or what the command printed
/// when it failed.
pub fn try_synth(
    material: &Path,
    capture: &Path,
    out: &Path,
    extra: &[&str],
) -> Result<(), String> {
    let mut args = vec![
        "synth",
        "--material",
        material.to_str().unwrap(),
        "--capture",
        capture.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    let (code, _, stderr) = run(&args);
    if code != Some(0) {
        return Err(format!("synth exited {code:?}: {}", stderr.trim()));
    }
    Ok(())
}

/// `bouncefit synth --material M --capture C -o OUT EXTRA...`.
pub fn synth(material: &Path, capture: &Path, out: &Path, extra: &[&str]) {
    try_synth(material, capture, out, extra).unwrap_or_else(|e| panic!("{e}"))
}

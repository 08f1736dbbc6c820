//! Reading a command's input files: the photo set and the material, with their warnings
//! (unknown keys and the like, which are not errors) printed on stderr as `warning: ...`.

use crate::capture::Capture;
use crate::error::{Error, Result};
use crate::maps::AnyMaterial;
use crate::material::Material;
use std::path::Path;

/// [`Capture::open`], printing the capture's warnings.
pub fn open_capture(path: &Path) -> Result<Capture> {
    let capture = Capture::open(path)?;
    print_warnings(&capture.warnings);
    Ok(capture)
}

/// A uniform material file, printing its warnings; a maps material is refused (the command
/// has no per-texel path).
pub fn load_material(path: &Path) -> Result<Material> {
    match load_any_material(path)? {
        AnyMaterial::Uniform(material) => Ok(material),
        AnyMaterial::Maps(_) => Err(Error::invalid(
            path,
            "maps",
            "this command takes a uniform material; maps materials are read by synth, render \
             and export",
        )),
    }
}

/// A uniform or maps material file ([`AnyMaterial::load_with_warnings`]), printing the
/// warnings.
pub fn load_any_material(path: &Path) -> Result<AnyMaterial> {
    let (material, warnings) = AnyMaterial::load_with_warnings(path)?;
    print_warnings(&warnings);
    Ok(material)
}

fn print_warnings(warnings: &[String]) {
    for warning in warnings {
        print_warning(warning);
    }
}

/// Prints a warning about the inputs (of the library, e.g. [`crate::fit::pipeline::load_records`])
/// on stderr.
pub fn print_warning(warning: &str) {
    eprintln!("warning: {warning}");
}

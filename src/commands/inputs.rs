//! Reading a command's input files: the photo set and the material, with their warnings
//! (unknown keys and the like, which are not errors) printed on stderr as `warning: ...`.

use crate::capture::Capture;
use crate::error::Result;
use crate::material::Material;
use std::path::Path;

/// [`Capture::open`], printing the capture's warnings.
pub fn open_capture(path: &Path) -> Result<Capture> {
    let capture = Capture::open(path)?;
    print_warnings(&capture.warnings);
    Ok(capture)
}

/// [`Material::load_with_warnings`], printing the warnings.
pub fn load_material(path: &Path) -> Result<Material> {
    let (material, warnings) = Material::load_with_warnings(path)?;
    print_warnings(&warnings);
    Ok(material)
}

fn print_warnings(warnings: &[String]) {
    for warning in warnings {
        eprintln!("warning: {warning}");
    }
}

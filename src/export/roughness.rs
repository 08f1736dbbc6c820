//! The roughness parameters of the renderers the exports target, from the fitted `alpha`:
//! glTF's `roughnessFactor` and `KHR_materials_anisotropy`, and MaterialX's standard_surface
//! and open_pbr_surface. Both the single-material documents ([`super::gltf`],
//! [`super::materialx`]) and the texture maps ([`super::maps`]) read them from here; each
//! document's module table states its mapping.

/// Standard Surface clamps its anisotropy to this (`mx_roughness_anisotropy`).
pub const STANDARD_SURFACE_MAX_ANISOTROPY: f64 = 0.98;

/// glTF's roughness range is [0, 1].
pub fn gltf_roughness(alpha: f64) -> f64 {
    alpha.sqrt().min(1.0)
}

/// `(roughness, anisotropyStrength, along_y)` of `alpha` ([`super::gltf`]'s module table):
/// glTF's roughness of the smaller alpha and the strength that stretches it to the larger
/// along the tangent, or along the bitangent (the sample's y) when `along_y`.
pub fn anisotropy(alpha: [f64; 2]) -> (f64, f64, bool) {
    let (high, low, along_y) = super::stretch(alpha);
    let strength = if high > low {
        ((high.min(1.0) - low) / (1.0 - low)).max(0.0).sqrt()
    } else {
        0.0
    };
    (gltf_roughness(low), strength.min(1.0), along_y)
}

/// `[specular_roughness, specular_anisotropy, specular_rotation]` of standard_surface for
/// `alpha` ([`super::materialx`]'s module table; isotropic: anisotropy and rotation 0).
pub fn standard_surface_roughness(alpha: [f64; 2]) -> [f64; 3] {
    let (high, low, along_y) = super::stretch(alpha);
    [
        (high * low).powf(0.25),
        (1.0 - low / high).min(STANDARD_SURFACE_MAX_ANISOTROPY),
        if along_y { 0.25 } else { 0.0 },
    ]
}

/// `[specular_roughness, specular_roughness_anisotropy]` of open_pbr_surface for `alpha`
/// ([`super::materialx`]'s module table), along the tangent, which must follow the larger alpha.
pub fn open_pbr_roughness(alpha: [f64; 2]) -> [f64; 2] {
    let (high, low, _) = super::stretch(alpha);
    [
        ((high * high + low * low) / 2.0).powf(0.25),
        1.0 - low / high,
    ]
}

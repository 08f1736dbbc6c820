//! Per-pixel shading records, computed once per photo set (DESIGN.md "shading").
//!
//! Everything downstream of the capture (render, loss, fit) loops over these records and never
//! over images. Geometry is stored per sub-pixel sample (structure of arrays); targets and
//! weights are stored per pixel. A pixel's prediction is the mean over its `samples_per_pixel`
//! sub-samples of `f(wi, wo) * irradiance`.

/// One photo's place in the record arrays.
#[derive(Clone, Debug)]
pub struct PhotoSpan {
    /// File stem of the photo's image (`000` for `000.exr`), used to name rendered outputs.
    pub stem: String,
    pub width: usize,
    pub height: usize,
    /// Index of this photo's first pixel in the per-pixel arrays (row-major, row 0 at the top).
    pub first_pixel: usize,
}

/// Why a pixel does not enter the loss (weight 0). Counted per photo set for reports.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct ExclusionCounts {
    pub masked: usize,
    pub saturated: usize,
    pub non_finite: usize,
    pub outside_sample: usize,
}

/// Shading records of a whole photo set, structure of arrays.
#[derive(Clone, Debug, Default)]
pub struct ShadingRecords {
    pub photos: Vec<PhotoSpan>,
    /// Stratified sub-pixel samples per pixel (a perfect square: 1, 4, 9, ...).
    pub samples_per_pixel: usize,
    /// Per sub-sample: unit direction toward the light, local frame (z = sample normal).
    pub wi: Vec<[f64; 3]>,
    /// Per sub-sample: unit direction toward the camera, local frame.
    pub wo: Vec<[f64; 3]>,
    /// Per sub-sample: the factor that turns `f` (1/sr) into radiance, exposure included:
    /// `I * wi.z / d^2 * exposure` for a point light. Zero where the sub-sample misses the
    /// sample or the light is below the horizon.
    pub irradiance: Vec<[f64; 3]>,
    /// Per pixel: linear radiance of the photo (zeros when built without images).
    pub target: Vec<[f64; 3]>,
    /// Per pixel: loss weight, 0 for excluded pixels (mask, saturation, non-finite, outside).
    pub weight: Vec<f64>,
    pub excluded: ExclusionCounts,
}

impl ShadingRecords {
    pub fn pixel_count(&self) -> usize {
        self.weight.len()
    }
}

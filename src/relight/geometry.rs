//! What a relit preview shows: the flat sample or a sphere, seen by an orthographic camera
//! looking straight down (along `-z`, image `x` along the world's `+x`, image rows from `+y`
//! down), so every pixel sees its surface point from `wo = +z`.
//!
//! | geometry | surface | texture coordinates |
//! | --- | --- | --- |
//! | `flat` | the sample in the plane `z = 0`, `x` in `[-1, 1]`, `y` in `[-a, a]` with `a` = image height / width; normal `+z` | the image's: `u` from left to right, `v` from the top row down, as the sample's texel grid (docs/maps.md) |
//! | `sphere` | the unit sphere at the origin; the image covers `x, y` in `[-1, 1]`, and the pixel at `(x, y)` inside the unit disc sees `n = (x, y, sqrt(1 - x^2 - y^2))` | the orthographic projection of the maps onto the front hemisphere: `u = (x + 1) / 2`, `v = (1 - y) / 2`, i.e. the flat sample's layout seen from the camera, laid on the sphere |
//!
//! Each point carries its tangent frame: the normal and the tangent `s = normalize(x - (x.n) n)`,
//! the projection of the sample's `+x` (the direction in which `u` grows), so that the maps'
//! anisotropic roughness and shading normals keep their directions ([`ShadingFrame`]). A
//! sphere's frame is singular only at `n = +-x`, on the silhouette, which no pixel centre inside
//! the disc reaches. The unit of length is the sample's half-width, which is the sphere's radius.

use crate::maps::{ShadingFrame, TexelGrid};
use crate::scalar::Vec3;
use glam::DVec3;

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Geometry {
    Flat,
    Sphere,
}

/// The surface point a camera ray sees.
#[derive(Clone, Copy, Debug)]
pub struct SurfacePoint {
    pub position: DVec3,
    /// Tangent frame: world directions into tangent space (`z` the normal) and back.
    pub frame: ShadingFrame<f64>,
    /// Texture coordinates on the material's texel grid.
    pub uv: [f64; 2],
}

/// The camera's view direction, from every surface point toward the camera.
pub const VIEW: Vec3<f64> = Vec3 {
    x: 0.0,
    y: 0.0,
    z: 1.0,
};

impl Geometry {
    /// `[width, height]` of an image `size` pixels wide of a material on `grid`: the flat
    /// sample keeps the grid's proportions, the sphere is square.
    pub fn resolution(self, size: usize, grid: TexelGrid) -> [usize; 2] {
        match self {
            Geometry::Flat => {
                let height = size as f64 * grid.height as f64 / grid.width as f64;
                [size, (height.round() as usize).max(1)]
            }
            Geometry::Sphere => [size, size],
        }
    }

    /// The point seen at the continuous image position `pixel` (`[0, width] x [0, height]`,
    /// row 0 at the top) of an image of `resolution`; `None` where the ray misses (background).
    pub fn point(self, resolution: [usize; 2], pixel: [f64; 2]) -> Option<SurfacePoint> {
        let [width, height] = resolution.map(|n| n as f64);
        let uv = [pixel[0] / width, pixel[1] / height];
        let scale = 2.0 / width;
        let (x, y) = (
            pixel[0] * scale - 1.0,
            (height - pixel[1]) * scale - height / width,
        );
        match self {
            Geometry::Flat => Some(SurfacePoint {
                position: DVec3::new(x, y, 0.0),
                frame: ShadingFrame::new(VIEW),
                uv,
            }),
            Geometry::Sphere => {
                let r2 = x * x + y * y;
                if r2 >= 1.0 {
                    return None;
                }
                let n = Vec3::new(x, y, (1.0 - r2).sqrt());
                Some(SurfacePoint {
                    position: DVec3::from_array(n.re()),
                    frame: ShadingFrame::new(n),
                    uv,
                })
            }
        }
    }
}

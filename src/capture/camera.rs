//! Camera models of the photo-set manifest (DESIGN.md "Photo-set manifest").
//!
//! Pixel coordinates: pixel `(c, r)` (column, row) covers `[c, c+1] x [r, r+1]`, image y
//! points down, row 0 is the top row; pixel centres are at half-integers.
//!
//! - [`Pinhole`]: OpenCV's convention (camera x right, y down, z forward), so
//!   `cv2.projectPoints` with `K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]` and the world-to-camera
//!   rotation whose rows are `right`, `-up`, `forward` gives the same pixels as [`Pinhole::project`].
//! - [`Rectified`]: the image covers exactly the sample rectangle, orthographically; row 0 is
//!   +y and column 0 is -x (the MaterialGAN convention, data/real/README.md).

use glam::DVec3;

use super::Sample;

/// A camera of one photo. Serialises as the manifest's `[camera]` table (`model = ...`).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
#[serde(tag = "model", rename_all = "lowercase")]
pub enum Camera {
    /// Perspective camera (`model = "pinhole"`).
    Pinhole(Pinhole),
    /// The image is the sample rectangle (`model = "rectified"`).
    Rectified(Rectified),
}

/// Perspective pinhole camera with intrinsics in pixels (OpenCV convention, see module docs).
/// A manifest's `fov_y_deg` is converted on reading: `fy = (height/2) / tan(fov_y/2)`, `fx = fy`.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Pinhole {
    /// Centre of projection (world units of the manifest).
    pub position: DVec3,
    /// A point on the optical axis, in front of the camera.
    pub look_at: DVec3,
    /// Any vector not parallel to the viewing direction; the image's "up" is its component
    /// orthogonal to the viewing direction.
    pub up: DVec3,
    /// Horizontal focal length in pixels.
    pub fx: f64,
    /// Vertical focal length in pixels.
    pub fy: f64,
    /// Principal point, x pixel coordinate (default: width / 2).
    pub cx: f64,
    /// Principal point, y pixel coordinate (default: height / 2).
    pub cy: f64,
    /// `[width, height]` in pixels.
    pub resolution: [usize; 2],
}

/// Orthographic camera whose image covers exactly the sample rectangle; `position` is only
/// used as the camera centre for view directions (MaterialGAN data, data/real/README.md).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Rectified {
    /// Camera centre, the origin of every view direction.
    pub position: DVec3,
    /// `[width, height]` in pixels.
    pub resolution: [usize; 2],
}

/// Orthonormal frame of a pinhole camera: `forward = normalize(look_at - position)`,
/// `right = normalize(forward x up_hint)`, `up = right x forward`. OpenCV's camera axes are
/// `right`, `-up`, `forward`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame {
    /// Viewing direction (OpenCV camera +z).
    pub forward: DVec3,
    /// Image right (OpenCV camera +x).
    pub right: DVec3,
    /// Image up (OpenCV camera -y).
    pub up: DVec3,
}

impl Camera {
    /// Camera centre: the origin of view directions `wo`.
    pub fn position(&self) -> DVec3 {
        match self {
            Camera::Pinhole(c) => c.position,
            Camera::Rectified(c) => c.position,
        }
    }

    /// `[width, height]` in pixels.
    pub fn resolution(&self) -> [usize; 2] {
        match self {
            Camera::Pinhole(c) => c.resolution,
            Camera::Rectified(c) => c.resolution,
        }
    }

    /// The same camera with an image of `resolution` pixels: the same view of the scene, each
    /// pixel-unit intrinsic (`fx`, `cx` and `fy`, `cy`) scaled by the ratio of widths and of
    /// heights, so a world point lands at the same fraction of the image.
    pub fn resampled(&self, resolution: [usize; 2]) -> Camera {
        match self {
            Camera::Pinhole(c) => {
                let [sx, sy] = [0, 1].map(|i| resolution[i] as f64 / c.resolution[i] as f64);
                Camera::Pinhole(Pinhole {
                    fx: c.fx * sx,
                    cx: c.cx * sx,
                    fy: c.fy * sy,
                    cy: c.cy * sy,
                    resolution,
                    ..c.clone()
                })
            }
            Camera::Rectified(c) => Camera::Rectified(Rectified {
                resolution,
                ..c.clone()
            }),
        }
    }

    /// The point of the plane z = 0 seen at pixel position `pixel`, or `None` when the pinhole
    /// ray does not reach the plane going downwards. The point may lie outside `sample`
    /// (only the rectified model uses `sample`, to scale pixels to lengths).
    pub fn surface_point(&self, sample: &Sample, pixel: [f64; 2]) -> Option<DVec3> {
        match self {
            Camera::Pinhole(c) => c.surface_point(pixel),
            Camera::Rectified(c) => Some(c.surface_point(sample, pixel)),
        }
    }

    /// Pixel position at which `world` appears (inverse of [`Camera::surface_point`] for
    /// points on the plane), or `None` when it is not in front of a pinhole camera.
    pub fn project(&self, sample: &Sample, world: DVec3) -> Option<[f64; 2]> {
        match self {
            Camera::Pinhole(c) => c.project(world),
            Camera::Rectified(c) => Some(c.project(sample, world)),
        }
    }
}

impl Pinhole {
    /// A pinhole camera from a vertical field of view in degrees, principal point at the image
    /// centre: `fy = (height/2) / tan(fov_y/2)`, `fx = fy`.
    pub fn with_fov(
        position: DVec3,
        look_at: DVec3,
        up: DVec3,
        fov_y_deg: f64,
        resolution: [usize; 2],
    ) -> Pinhole {
        let [width, height] = resolution.map(|n| n as f64);
        let fy = (height / 2.0) / (fov_y_deg.to_radians() / 2.0).tan();
        Pinhole {
            position,
            look_at,
            up,
            fx: fy,
            fy,
            cx: width / 2.0,
            cy: height / 2.0,
            resolution,
        }
    }

    /// The camera frame (see [`Frame`]). Meaningless (NaN) for a degenerate camera, which the
    /// manifest reader rejects ([`Pinhole::degeneracy`]).
    pub fn frame(&self) -> Frame {
        let forward = (self.look_at - self.position).normalize();
        let right = forward.cross(self.up).normalize();
        Frame {
            forward,
            right,
            up: right.cross(forward),
        }
    }

    /// Why the frame is undefined, if it is: `("look_at", ..)` when `look_at == position`,
    /// `("up", ..)` when `up` is zero or parallel to the viewing direction.
    pub fn degeneracy(&self) -> Option<(&'static str, &'static str)> {
        let view = self.look_at - self.position;
        if view.length_squared() == 0.0 {
            return Some((
                "look_at",
                "equals the camera position: the viewing direction is undefined",
            ));
        }
        let normal = view.normalize().cross(self.up).length();
        if normal.is_nan() || normal <= 1e-9 * self.up.length() {
            return Some((
                "up",
                "is zero or parallel to the viewing direction (look_at - position)",
            ));
        }
        None
    }

    /// Unit direction of the ray through pixel position `pixel`:
    /// `normalize(forward + (px-cx)/fx * right - (py-cy)/fy * up)`.
    pub fn ray(&self, pixel: [f64; 2]) -> DVec3 {
        let f = self.frame();
        let x = (pixel[0] - self.cx) / self.fx;
        let y = (pixel[1] - self.cy) / self.fy;
        (f.forward + x * f.right - y * f.up).normalize()
    }

    /// Pixel position of `world`, or `None` when it is not strictly in front of the camera.
    pub fn project(&self, world: DVec3) -> Option<[f64; 2]> {
        let f = self.frame();
        let d = world - self.position;
        let depth = d.dot(f.forward);
        (depth > 0.0).then(|| {
            [
                self.cx + self.fx * d.dot(f.right) / depth,
                self.cy - self.fy * d.dot(f.up) / depth,
            ]
        })
    }

    /// Where the ray through `pixel` meets the plane z = 0, if it goes down towards it.
    pub fn surface_point(&self, pixel: [f64; 2]) -> Option<DVec3> {
        let ray = self.ray(pixel);
        (ray.z < 0.0 && self.position.z > 0.0).then(|| {
            let hit = self.position - (self.position.z / ray.z) * ray;
            DVec3::new(hit.x, hit.y, 0.0)
        })
    }
}

impl Rectified {
    /// `x = (px/W - 0.5) * width`, `y = -(py/H - 0.5) * height`, `z = 0`.
    pub fn surface_point(&self, sample: &Sample, pixel: [f64; 2]) -> DVec3 {
        let [w, h] = self.resolution.map(|n| n as f64);
        DVec3::new(
            (pixel[0] / w - 0.5) * sample.width,
            -(pixel[1] / h - 0.5) * sample.height,
            0.0,
        )
    }

    /// Inverse of [`Rectified::surface_point`] (orthographic along z).
    pub fn project(&self, sample: &Sample, world: DVec3) -> [f64; 2] {
        let [w, h] = self.resolution.map(|n| n as f64);
        [
            (world.x / sample.width + 0.5) * w,
            (0.5 - world.y / sample.height) * h,
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn looking_down(height: f64, fov_y_deg: f64, resolution: [usize; 2]) -> Pinhole {
        Pinhole::with_fov(
            DVec3::new(0.0, 0.0, height),
            DVec3::ZERO,
            DVec3::Y,
            fov_y_deg,
            resolution,
        )
    }

    #[test]
    fn fov_gives_focal_length_and_centred_principal_point() {
        let c = looking_down(30.0, 30.0, [128, 96]);
        assert!((c.fy - 48.0 / 15f64.to_radians().tan()).abs() < 1e-12);
        assert_eq!(c.fx, c.fy);
        assert_eq!((c.cx, c.cy), (64.0, 48.0));
    }

    #[test]
    fn looking_down_image_right_is_plus_x_and_image_down_is_minus_y() {
        // fov 90 deg over 100 px: fy = 50, so a point at lateral distance h maps 50 px away.
        let c = looking_down(10.0, 90.0, [100, 100]);
        assert!((c.fy - 50.0).abs() < 1e-12);
        let p = c.project(DVec3::new(10.0, 0.0, 0.0)).unwrap();
        assert!(
            (p[0] - 100.0).abs() < 1e-9 && (p[1] - 50.0).abs() < 1e-9,
            "{p:?}"
        );
        let p = c.project(DVec3::new(0.0, 5.0, 0.0)).unwrap();
        assert!(
            (p[0] - 50.0).abs() < 1e-9 && (p[1] - 25.0).abs() < 1e-9,
            "{p:?}"
        );
        assert!((c.ray([50.0, 50.0]) - DVec3::NEG_Z).length() < 1e-15);
        // Behind the camera: no projection.
        assert_eq!(c.project(DVec3::new(0.0, 0.0, 20.0)), None);
    }

    #[test]
    fn frame_is_orthonormal_and_opencv_handed() {
        let c = Pinhole::with_fov(
            DVec3::new(3.0, -4.0, 12.0),
            DVec3::new(0.5, 0.2, 0.0),
            DVec3::new(0.1, 1.0, 0.3),
            40.0,
            [64, 48],
        );
        let f = c.frame();
        for v in [f.forward, f.right, f.up] {
            assert!((v.length() - 1.0).abs() < 1e-12);
        }
        assert!(f.forward.dot(f.right).abs() < 1e-12 && f.forward.dot(f.up).abs() < 1e-12);
        assert!(f.right.dot(f.up).abs() < 1e-12);
        // OpenCV: x (right) cross y (down) = z (forward).
        assert!((f.right.cross(-f.up) - f.forward).length() < 1e-12);
        // The up hint keeps its sign: image up leans toward it.
        assert!(f.up.dot(c.up) > 0.0);
    }

    #[test]
    fn degenerate_cameras_are_reported() {
        let mut c = looking_down(10.0, 40.0, [8, 8]);
        assert_eq!(c.degeneracy(), None);
        c.up = DVec3::new(0.0, 0.0, 2.0);
        assert_eq!(c.degeneracy().unwrap().0, "up");
        c.up = DVec3::ZERO;
        assert_eq!(c.degeneracy().unwrap().0, "up");
        c.up = DVec3::Y;
        c.look_at = c.position;
        assert_eq!(c.degeneracy().unwrap().0, "look_at");
    }

    #[test]
    fn rectified_corners_map_to_sample_corners() {
        let sample = Sample {
            width: 6.0,
            height: 4.0,
        };
        let c = Rectified {
            position: DVec3::new(0.0, 0.0, 20.0),
            resolution: [30, 20],
        };
        assert_eq!(
            c.surface_point(&sample, [0.0, 0.0]),
            DVec3::new(-3.0, 2.0, 0.0)
        );
        assert_eq!(
            c.surface_point(&sample, [30.0, 20.0]),
            DVec3::new(3.0, -2.0, 0.0)
        );
        assert_eq!(c.surface_point(&sample, [15.0, 10.0]), DVec3::ZERO);
        // MaterialGAN pixel-centre formula: x = ((c+0.5)/N - 0.5) S, y = -((r+0.5)/N - 0.5) S.
        let p = c.surface_point(&sample, [3.5, 7.5]);
        assert!((p.x - (3.5 / 30.0 - 0.5) * 6.0).abs() < 1e-15);
        assert!((p.y + (7.5 / 20.0 - 0.5) * 4.0).abs() < 1e-15);
    }

    /// A world point keeps its place as a fraction of the image when the image is resampled
    /// (a wrong scale of the principal point or focal length would move it).
    #[test]
    fn resampled_cameras_see_points_at_the_same_image_fraction() {
        let sample = Sample {
            width: 8.0,
            height: 6.0,
        };
        let mut pinhole = Pinhole::with_fov(
            DVec3::new(2.0, -3.0, 15.0),
            DVec3::new(0.5, 0.2, 0.0),
            DVec3::Y,
            35.0,
            [64, 48],
        );
        pinhole.cx += 3.0;
        pinhole.fx *= 1.2;
        let rectified = Rectified {
            position: DVec3::new(0.0, 0.0, 20.0),
            resolution: [64, 48],
        };
        for camera in [Camera::Pinhole(pinhole), Camera::Rectified(rectified)] {
            let larger = camera.resampled([256, 96]);
            assert_eq!(larger.resolution(), [256, 96]);
            assert_eq!(larger.position(), camera.position());
            for world in [DVec3::new(1.0, -2.0, 0.0), DVec3::new(-3.5, 2.5, 0.0)] {
                let (a, b) = (
                    camera.project(&sample, world).unwrap(),
                    larger.project(&sample, world).unwrap(),
                );
                assert!((b[0] - 4.0 * a[0]).abs() < 1e-9, "{a:?} {b:?}");
                assert!((b[1] - 2.0 * a[1]).abs() < 1e-9, "{a:?} {b:?}");
            }
        }
    }

    proptest! {
        #[test]
        fn pinhole_project_inverts_unproject(
            px in -20.0..84.0f64, py in -20.0..68.0f64,
            cam in prop::array::uniform3(-5.0..5.0f64), target in prop::array::uniform3(-3.0..3.0f64),
            fov in 10.0..120.0f64, depth in 0.1..50.0f64,
        ) {
            let mut c = Pinhole::with_fov(DVec3::from_array(cam) + DVec3::new(0.0, 0.0, 10.0),
                DVec3::from_array(target), DVec3::new(0.2, 1.0, 0.1), fov, [64, 48]);
            c.cx += 1.5;
            c.fx *= 1.1;
            prop_assume!(c.degeneracy().is_none());
            let world = c.position + depth * c.ray([px, py]);
            let back = c.project(world).unwrap();
            prop_assert!((back[0] - px).abs() < 1e-8 && (back[1] - py).abs() < 1e-8, "{:?} vs {:?}", back, [px, py]);
            if let Some(hit) = c.surface_point([px, py]).filter(|h| (*h - c.position).length() < 1e3) {
                prop_assert!(hit.z == 0.0);
                let back = c.project(hit).unwrap();
                prop_assert!((back[0] - px).abs() < 1e-6 && (back[1] - py).abs() < 1e-6);
            }
        }

        #[test]
        fn rectified_project_inverts_surface_point(px in -5.0..40.0f64, py in -5.0..30.0f64) {
            let sample = Sample { width: 7.0, height: 3.0 };
            let c = Camera::Rectified(Rectified { position: DVec3::new(1.0, 2.0, 9.0), resolution: [35, 25] });
            let back = c.project(&sample, c.surface_point(&sample, [px, py]).unwrap()).unwrap();
            prop_assert!((back[0] - px).abs() < 1e-10 && (back[1] - py).abs() < 1e-10);
        }
    }
}

//! Plane geometry of a board photo: the homography from the board plane to the image (DLT with
//! Hartley normalisation, Hartley & Zisserman 2003, Alg. 4.2), the focal length shared by the
//! photos of one phone (Zhang 2000, "A flexible new technique for camera calibration", sec.
//! 3.1, with square pixels, no skew and the principal point at the image centre), the camera
//! pose of each photo (Zhang 2000 sec. 3.1, then Levenberg-Marquardt on the reprojection
//! error, Hartley & Zisserman A6.2), and the reprojection error reported per photo.
//!
//! Image coordinates follow src/capture/camera.rs (pixel centres at half-integers); the camera
//! frame is OpenCV's (x right, y down, z forward), so a [`Pose`] is what `cv2.solvePnP` returns.

use nalgebra::{DMatrix, Matrix3, Rotation3, Vector3};

/// One board point and where it was seen.
#[derive(Clone, Copy, Debug)]
pub struct Correspondence {
    pub board: [f64; 2],
    pub image: [f64; 2],
}

/// Camera intrinsics in pixels: square pixels, no skew, and radial distortion `[k1, k2]` of the
/// normalised image point `x_d = x (1 + k1 r^2 + k2 r^4)` (Zhang 2000 sec. 3.3, eq. 11-12;
/// OpenCV's first two coefficients). `[0, 0]` is a pinhole.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Intrinsics {
    pub focal: f64,
    pub cx: f64,
    pub cy: f64,
    pub distortion: [f64; 2],
}

impl Intrinsics {
    /// A pinhole camera (no distortion).
    pub fn pinhole(focal: f64, cx: f64, cy: f64) -> Intrinsics {
        Intrinsics {
            focal,
            cx,
            cy,
            distortion: [0.0; 2],
        }
    }

    /// The pixel of a point at normalised image coordinates `(x, y)` (`X / Z`, `Y / Z` in the
    /// camera frame), distorted.
    pub fn pixel(&self, x: f64, y: f64) -> [f64; 2] {
        let r2 = x * x + y * y;
        let s = 1.0 + r2 * (self.distortion[0] + self.distortion[1] * r2);
        [self.focal * x * s + self.cx, self.focal * y * s + self.cy]
    }

    /// The squared normalised distance from the principal point of pixel position `(x, y)`
    /// (the distorted image's `r^2`).
    pub fn radius2(&self, x: f64, y: f64) -> f64 {
        ((x - self.cx).powi(2) + (y - self.cy).powi(2)) / (self.focal * self.focal)
    }

    fn matrix(&self) -> Matrix3<f64> {
        Matrix3::new(
            self.focal, 0.0, self.cx, 0.0, self.focal, self.cy, 0.0, 0.0, 1.0,
        )
    }
}

/// World (board) to camera: `x_cam = rotation * x_board + translation`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose {
    pub rotation: Rotation3<f64>,
    pub translation: Vector3<f64>,
}

impl Pose {
    /// The camera centre in the board frame.
    pub fn center(&self) -> Vector3<f64> {
        -(self.rotation.inverse() * self.translation)
    }

    /// Image position of board point `(x, y, 0)`; `None` behind the camera.
    pub fn project(&self, k: &Intrinsics, board: [f64; 2]) -> Option<[f64; 2]> {
        let c = self.rotation * Vector3::new(board[0], board[1], 0.0) + self.translation;
        (c.z > 0.0).then(|| k.pixel(c.x / c.z, c.y / c.z))
    }

    /// Root-mean-square distance in pixels between the observed and reprojected points.
    pub fn rms_error(&self, k: &Intrinsics, points: &[Correspondence]) -> f64 {
        let sum: f64 = points
            .iter()
            .map(|p| match self.project(k, p.board) {
                Some(q) => (q[0] - p.image[0]).powi(2) + (q[1] - p.image[1]).powi(2),
                None => f64::INFINITY,
            })
            .sum();
        (sum / points.len().max(1) as f64).sqrt()
    }
}

/// Similarity that moves `points` to their centroid and scales their mean distance to sqrt(2).
fn normaliser(points: impl Iterator<Item = [f64; 2]> + Clone) -> Matrix3<f64> {
    let n = points.clone().count() as f64;
    let (mx, my) = points
        .clone()
        .fold((0.0, 0.0), |(a, b), p| (a + p[0] / n, b + p[1] / n));
    let spread = points
        .map(|p| ((p[0] - mx).powi(2) + (p[1] - my).powi(2)).sqrt())
        .sum::<f64>()
        / n;
    let s = std::f64::consts::SQRT_2 / spread.max(1e-300);
    Matrix3::new(s, 0.0, -s * mx, 0.0, s, -s * my, 0.0, 0.0, 1.0)
}

fn apply(h: &Matrix3<f64>, p: [f64; 2]) -> [f64; 2] {
    let v = h * Vector3::new(p[0], p[1], 1.0);
    [v.x / v.z, v.y / v.z]
}

/// Sum of squared distances in pixels between the observed image points and the board points
/// mapped by the homography `h` (the transfer error, Hartley & Zisserman 2003, eq. 4.6).
pub fn transfer_error(h: &Matrix3<f64>, points: &[Correspondence]) -> f64 {
    points
        .iter()
        .map(|p| {
            let q = apply(h, p.board);
            (q[0] - p.image[0]).powi(2) + (q[1] - p.image[1]).powi(2)
        })
        .sum()
}

/// The homography `H` with `image ~ H (board, 1)` from at least four correspondences (DLT on
/// normalised coordinates); `None` when they are degenerate (collinear, too few).
pub fn homography(points: &[Correspondence]) -> Option<Matrix3<f64>> {
    if points.len() < 4 {
        return None;
    }
    let tb = normaliser(points.iter().map(|p| p.board));
    let ti = normaliser(points.iter().map(|p| p.image));
    let mut a = DMatrix::<f64>::zeros(2 * points.len().max(5), 9);
    for (i, p) in points.iter().enumerate() {
        let [x, y] = apply(&tb, p.board);
        let [u, v] = apply(&ti, p.image);
        let rows = [
            [-x, -y, -1.0, 0.0, 0.0, 0.0, u * x, u * y, u],
            [0.0, 0.0, 0.0, -x, -y, -1.0, v * x, v * y, v],
        ];
        for (r, row) in rows.iter().enumerate() {
            for (c, &value) in row.iter().enumerate() {
                a[(2 * i + r, c)] = value;
            }
        }
    }
    let svd = a.svd(false, true);
    let v_t = svd.v_t?;
    let (smallest, _) = svd
        .singular_values
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(b.1))?;
    // The second smallest singular value must be clearly non-zero: otherwise the points do not
    // fix a unique homography.
    let mut sorted: Vec<f64> = svd.singular_values.iter().copied().collect();
    sorted.sort_by(f64::total_cmp);
    if sorted[1] < 1e-9 * sorted[8] {
        return None;
    }
    let h = v_t.row(smallest);
    let hn = Matrix3::new(h[0], h[1], h[2], h[3], h[4], h[5], h[6], h[7], h[8]);
    let full = ti.try_inverse()? * hn * tb;
    Some(full / full[(2, 2)])
}

/// The focal length (pixels) that makes every homography's first two columns orthogonal and of
/// equal length after `K^-1` (Zhang 2000 eq. 3-4 with `omega = diag(1/f^2, 1/f^2, 1)`), by
/// least squares in `1/f^2` over all photos; `None` when the views do not determine it (all
/// fronto-parallel) or the answer is not a real focal length.
pub fn focal_from_homographies(homographies: &[Matrix3<f64>], cx: f64, cy: f64) -> Option<f64> {
    let shift = Matrix3::new(1.0, 0.0, -cx, 0.0, 1.0, -cy, 0.0, 0.0, 1.0);
    let (mut aa, mut ab) = (0.0, 0.0);
    for h in homographies {
        let h = shift * h;
        let (c1, c2) = (h.column(0).normalize(), h.column(1).normalize());
        // (a1 a2 + b1 b2) u + c1 c2 = 0 and (a1^2 + b1^2 - a2^2 - b2^2) u + c1^2 - c2^2 = 0.
        let rows = [
            (c1.x * c2.x + c1.y * c2.y, c1.z * c2.z),
            (
                c1.x * c1.x + c1.y * c1.y - c2.x * c2.x - c2.y * c2.y,
                c1.z * c1.z - c2.z * c2.z,
            ),
        ];
        for (a, b) in rows {
            aa += a * a;
            ab += a * b;
        }
    }
    let u = -ab / aa;
    (aa > 1e-18 && u.is_finite() && u > 0.0).then(|| 1.0 / u.sqrt())
}

/// The pose of a camera with intrinsics `k` that maps the board plane by `h` (Zhang 2000 sec.
/// 3.1): `[h1 h2 h3] = lambda K [r1 r2 t]`, the rotation made orthonormal by SVD and the board
/// put in front of the camera.
pub fn pose_from_homography(h: &Matrix3<f64>, k: &Intrinsics) -> Option<Pose> {
    let m = k.matrix().try_inverse()? * h;
    let lambda = 1.0 / m.column(0).norm();
    let sign = if m[(2, 2)] * lambda > 0.0 { 1.0 } else { -1.0 };
    let (r1, r2, t) = (
        m.column(0) * lambda * sign,
        m.column(1) * lambda * sign,
        m.column(2) * lambda * sign,
    );
    let r = Matrix3::from_columns(&[r1, r2, r1.cross(&r2)]);
    let svd = r.svd(true, true);
    let mut rotation = svd.u? * svd.v_t?;
    if rotation.determinant() < 0.0 {
        rotation = -rotation;
    }
    Some(Pose {
        rotation: Rotation3::from_matrix_unchecked(rotation),
        translation: t,
    })
}

/// The board geometry's one damped least-squares loop: Levenberg-Marquardt (Hartley &
/// Zisserman A6.2) on `residuals` over the parameters `p`, forward-difference Jacobian with step
/// `steps[j]` for parameter `j`, Marquardt's diagonal scaling; `residuals` returns `None` where
/// the parameters are invalid (a point behind a camera). Returns the parameters at the least
/// sum of squares found.
pub(super) fn levenberg_marquardt(
    mut p: Vec<f64>,
    steps: &[f64],
    residuals: impl Fn(&[f64]) -> Option<Vec<f64>>,
) -> Vec<f64> {
    let n = p.len();
    let Some(mut r) = residuals(&p) else {
        return p;
    };
    let cost = |r: &[f64]| r.iter().map(|v| v * v).sum::<f64>();
    let mut damping = 1e-3;
    for _ in 0..50 {
        let mut jac = DMatrix::<f64>::zeros(r.len(), n);
        for j in 0..n {
            let mut q = p.clone();
            q[j] += steps[j];
            let Some(rq) = residuals(&q) else {
                return p;
            };
            for i in 0..r.len() {
                jac[(i, j)] = (rq[i] - r[i]) / steps[j];
            }
        }
        let jt = jac.transpose();
        let jtj = &jt * &jac;
        let g = &jt * nalgebra::DVector::from_column_slice(&r);
        let mut improved = false;
        while damping < 1e12 {
            let mut a = jtj.clone();
            for d in 0..n {
                a[(d, d)] += damping * jtj[(d, d)].max(1e-12);
            }
            let Some(delta) = a.lu().solve(&(-&g)) else {
                break;
            };
            let q: Vec<f64> = p.iter().zip(delta.iter()).map(|(a, b)| a + b).collect();
            match residuals(&q) {
                Some(rq) if cost(&rq) < cost(&r) => {
                    let gain = cost(&r) - cost(&rq);
                    (p, r) = (q, rq);
                    damping = (damping / 10.0).max(1e-12);
                    improved = gain > 1e-12 * cost(&r).max(1e-300);
                    break;
                }
                _ => damping *= 10.0,
            }
        }
        if !improved {
            break;
        }
    }
    p
}

/// A pose as six parameters (rotation vector, translation) and back.
fn pose_parameters(pose: &Pose) -> [f64; 6] {
    let rv = pose.rotation.scaled_axis();
    let t = pose.translation;
    [rv.x, rv.y, rv.z, t.x, t.y, t.z]
}

fn pose_of(p: &[f64]) -> Pose {
    Pose {
        rotation: Rotation3::new(Vector3::new(p[0], p[1], p[2])),
        translation: Vector3::new(p[3], p[4], p[5]),
    }
}

/// Finite-difference steps of a pose's parameters: radians, and lengths on `scale`.
fn pose_steps(scale: f64) -> [f64; 6] {
    let t = 1e-7 * scale.max(1e-9);
    [1e-7, 1e-7, 1e-7, t, t, t]
}

/// Image residuals (x and y per point) of `points` seen by a camera `k` at `pose`.
fn reprojection(
    pose: &Pose,
    k: &Intrinsics,
    points: &[Correspondence],
    out: &mut Vec<f64>,
) -> Option<()> {
    for c in points {
        let q = pose.project(k, c.board)?;
        out.push(q[0] - c.image[0]);
        out.push(q[1] - c.image[1]);
    }
    Some(())
}

/// Levenberg-Marquardt on the reprojection error over the pose's six parameters (rotation
/// vector and translation); returns the refined pose.
pub fn refine_pose(pose: Pose, k: &Intrinsics, points: &[Correspondence]) -> Pose {
    let steps = pose_steps(pose.translation.norm());
    let p = levenberg_marquardt(pose_parameters(&pose).to_vec(), &steps, |p| {
        let mut r = Vec::with_capacity(2 * points.len());
        reprojection(&pose_of(p), k, points, &mut r).map(|_| r)
    });
    pose_of(&p)
}

/// Standard deviations of the priors that hold a lens calibration near a centred pinhole: the
/// principal point within 1% of the image's longer side (a phone's is), each distortion
/// coefficient within 0.1 (a phone's JPEG is mostly undistorted already), against a corner's
/// 0.5 px. Weaker priors let views that cannot tell them apart (all straight down) move the
/// principal point by a third of the image to fit the corners' noise.
const PRINCIPAL_POINT_PRIOR: f64 = 0.01;
const DISTORTION_PRIOR: f64 = 0.1;
const CORNER_SIGMA_PX: f64 = 0.5;

/// Bundle adjustment of one phone's photos of the board (Zhang 2000 sec. 3.3): the principal
/// point, radial distortion `[k1, k2]` and, unless `fixed_focal`, the focal length shared by
/// all photos, refined with every photo's pose on all their corners. Weak priors (above) keep
/// the principal point near `k`'s and the distortion near none where the views do not
/// determine them. `size` is the image's `[width, height]`.
pub fn calibrate_lens(
    k: Intrinsics,
    fixed_focal: bool,
    size: [usize; 2],
    photos: &[(Pose, &[Correspondence])],
) -> (Intrinsics, Vec<Pose>) {
    let longer = size[0].max(size[1]) as f64;
    let centre = [k.cx, k.cy];
    let mut p = vec![k.focal, k.cx, k.cy, k.distortion[0], k.distortion[1]];
    let mut steps = vec![1e-6 * k.focal, 1e-6 * longer, 1e-6 * longer, 1e-7, 1e-7];
    for (pose, _) in photos {
        p.extend(pose_parameters(pose));
        steps.extend(pose_steps(pose.translation.norm()));
    }
    let intrinsics = |p: &[f64]| Intrinsics {
        focal: if fixed_focal { k.focal } else { p[0] },
        cx: p[1],
        cy: p[2],
        distortion: [p[3], p[4]],
    };
    let p = levenberg_marquardt(p, &steps, |p| {
        let k = intrinsics(p);
        let mut r = Vec::new();
        for (i, (_, points)) in photos.iter().enumerate() {
            reprojection(&pose_of(&p[5 + 6 * i..]), &k, points, &mut r)?;
        }
        let pp = CORNER_SIGMA_PX / (PRINCIPAL_POINT_PRIOR * longer);
        r.push((p[1] - centre[0]) * pp);
        r.push((p[2] - centre[1]) * pp);
        r.push(p[3] * CORNER_SIGMA_PX / DISTORTION_PRIOR);
        r.push(p[4] * CORNER_SIGMA_PX / DISTORTION_PRIOR);
        Some(r)
    });
    let poses = (0..photos.len())
        .map(|i| pose_of(&p[5 + 6 * i..]))
        .collect();
    (intrinsics(&p), poses)
}

//! Structural similarity (Wang, Bovik, Sheikh, Simoncelli 2004, "Image Quality Assessment: From
//! Error Visibility to Structural Similarity") on linear radiance, with masked pixels, and its
//! exact gradient with respect to the prediction.
//!
//! | choice | value | why |
//! | --- | --- | --- |
//! | window | Gaussian, sigma 1.5 px, radius 5 (11 x 11), truncated and renormalised | the paper's sec. III.C |
//! | local statistics | weighted by the window and by the pixel weights: `mu = sum g w x / sum g w`, likewise the (co)variances | masked, saturated and off-sample pixels (weight 0) do not enter any window |
//! | constants | `C1 = (0.01 L)^2`, `C2 = (0.03 L)^2` (eq. 7, 9), `L` = brightest target value of the photo | linear HDR radiance has no fixed dynamic range |
//! | map | `S = (2 mu_x mu_y + C1)(2 s_xy + C2) / ((mu_x^2 + mu_y^2 + C1)(s_x^2 + s_y^2 + C2))` (eq. 13) at every loss pixel and channel | |
//!
//! The gradient follows from `dS_i/dx_j = g_ij w_j / W_i (dS/dmu_x + 2 dS/ds_x^2 (x_j - mu_x,i) +
//! dS/ds_xy (y_j - mu_y,i))`; summing over window centres `i` is again a blur with the symmetric
//! window, so value and gradient each cost a handful of separable blurs.

use super::ImageLayout;

const SIGMA: f64 = 1.5;
const RADIUS: usize = 5;
const K1: f64 = 0.01;
const K2: f64 = 0.03;

fn window() -> [f64; 2 * RADIUS + 1] {
    let mut g = [0.0; 2 * RADIUS + 1];
    for (i, v) in g.iter_mut().enumerate() {
        let d = i as f64 - RADIUS as f64;
        *v = (-d * d / (2.0 * SIGMA * SIGMA)).exp();
    }
    let sum: f64 = g.iter().sum();
    g.map(|v| v / sum)
}

/// One pass of the window along an axis: `count` lines of `len` samples, sample `i` of line
/// `l` at `l * across + i * along`; zero outside the line.
fn blur_lines(
    image: &[f64],
    g: &[f64],
    len: usize,
    count: usize,
    along: usize,
    across: usize,
) -> Vec<f64> {
    let mut out = vec![0.0; image.len()];
    for l in 0..count {
        for i in 0..len {
            let lo = i.saturating_sub(RADIUS);
            let hi = (i + RADIUS).min(len - 1);
            out[l * across + i * along] = (lo..=hi)
                .map(|j| g[j + RADIUS - i] * image[l * across + j * along])
                .sum();
        }
    }
    out
}

/// The window blur of a `[width, height]` image (row-major), zero outside the image: the
/// local mean of every SSIM statistic (exposed for `bouncefit image blur`).
pub fn gaussian_blur(image: &[f64], size: [usize; 2]) -> Vec<f64> {
    blur(image, size, &window())
}

/// Separable blur with the window, zero outside the image (a symmetric linear map).
fn blur(image: &[f64], [width, height]: [usize; 2], g: &[f64]) -> Vec<f64> {
    let rows = blur_lines(image, g, width, height, 1, width);
    blur_lines(&rows, g, height, width, width, 1)
}

/// Local statistics and SSIM of one photo and channel, on the photo's pixel grid.
struct ChannelMaps {
    /// Dense prediction, target and weight images.
    x: Vec<f64>,
    y: Vec<f64>,
    w: Vec<f64>,
    mu_x: Vec<f64>,
    mu_y: Vec<f64>,
    /// `sum g w` at each pixel.
    window_weight: Vec<f64>,
    /// SSIM and its partial derivatives with respect to `mu_x`, `s_x^2`, `s_xy`.
    s: Vec<f64>,
    ds_dmu_x: Vec<f64>,
    ds_dvar_x: Vec<f64>,
    ds_dcov: Vec<f64>,
}

impl ChannelMaps {
    fn new(x: Vec<f64>, y: Vec<f64>, w: Vec<f64>, size: [usize; 2], range: f64) -> Self {
        let g = window();
        let product = |a: &[f64], b: &[f64]| -> Vec<f64> {
            a.iter()
                .zip(b)
                .zip(&w)
                .map(|((a, b), w)| w * a * b)
                .collect()
        };
        let ones = vec![1.0; w.len()];
        let window_weight = blur(&w, size, &g);
        let [wx, wy, wxx, wyy, wxy] = [
            product(&x, &ones),
            product(&y, &ones),
            product(&x, &x),
            product(&y, &y),
            product(&x, &y),
        ]
        .map(|m| blur(&m, size, &g));
        let (c1, c2) = ((K1 * range).powi(2), (K2 * range).powi(2));
        let n = w.len();
        let (mut mu_x, mut mu_y, mut s) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
        let (mut ds_dmu_x, mut ds_dvar_x, mut ds_dcov) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
        for i in 0..n {
            if w[i] <= 0.0 {
                continue;
            }
            let ww = window_weight[i];
            let (mx, my) = (wx[i] / ww, wy[i] / ww);
            let (vx, vy, cxy) = (
                wxx[i] / ww - mx * mx,
                wyy[i] / ww - my * my,
                wxy[i] / ww - mx * my,
            );
            let (a1, a2) = (2.0 * mx * my + c1, 2.0 * cxy + c2);
            let (b1, b2) = (mx * mx + my * my + c1, vx + vy + c2);
            let si = a1 * a2 / (b1 * b2);
            mu_x[i] = mx;
            mu_y[i] = my;
            s[i] = si;
            ds_dmu_x[i] = si * (2.0 * my / a1 - 2.0 * mx / b1);
            ds_dvar_x[i] = -si / b2;
            ds_dcov[i] = 2.0 * si / a2;
        }
        ChannelMaps {
            x,
            y,
            w,
            mu_x,
            mu_y,
            window_weight,
            s,
            ds_dmu_x,
            ds_dvar_x,
            ds_dcov,
        }
    }

    /// `d/dx_j sum_i w_i (1 - S_i)` on the photo grid.
    fn gradient(&self, size: [usize; 2]) -> Vec<f64> {
        let g = window();
        let n = self.w.len();
        let scaled = |d: &[f64], times: Option<&[f64]>| -> Vec<f64> {
            (0..n)
                .map(|i| {
                    if self.w[i] <= 0.0 {
                        0.0
                    } else {
                        self.w[i] * d[i] / self.window_weight[i] * times.map_or(1.0, |t| t[i])
                    }
                })
                .collect()
        };
        let a = blur(&scaled(&self.ds_dmu_x, None), size, &g);
        let b = blur(&scaled(&self.ds_dvar_x, None), size, &g);
        let b_mu = blur(&scaled(&self.ds_dvar_x, Some(&self.mu_x)), size, &g);
        let c = blur(&scaled(&self.ds_dcov, None), size, &g);
        let c_mu = blur(&scaled(&self.ds_dcov, Some(&self.mu_y)), size, &g);
        (0..n)
            .map(|j| {
                -self.w[j]
                    * (a[j] + 2.0 * self.x[j] * b[j] - 2.0 * b_mu[j] + self.y[j] * c[j] - c_mu[j])
            })
            .collect()
    }
}

/// The loss pixels of each photo: (loss pixel index, offset in the photo).
fn pixels_by_photo(layout: &ImageLayout) -> Vec<Vec<(usize, usize)>> {
    let mut by_photo = vec![Vec::new(); layout.sizes.len()];
    for (k, &(photo, offset)) in layout.place.iter().enumerate() {
        by_photo[photo].push((k, offset));
    }
    by_photo
}

/// Dense prediction, target and weight images of one photo and channel, and the photo's range.
fn channel_maps(
    size: [usize; 2],
    pixels: &[(usize, usize)],
    channel: usize,
    predicted: &[[f64; 3]],
    target: &[[f64; 3]],
    weight: &[f64],
) -> ChannelMaps {
    let n = size[0] * size[1];
    let (mut x, mut y, mut w) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
    let mut range = f64::MIN_POSITIVE;
    for &(k, o) in pixels {
        x[o] = predicted[k][channel];
        y[o] = target[k][channel];
        w[o] = weight[k];
        if weight[k] > 0.0 {
            range = range.max(target[k].iter().fold(0.0, |m: f64, v| m.max(*v)));
        }
    }
    ChannelMaps::new(x, y, w, size, range)
}

/// Each loss pixel's SSIM per channel (0 where the weight is 0).
pub fn similarity(
    layout: &ImageLayout,
    predicted: &[[f64; 3]],
    target: &[[f64; 3]],
    weight: &[f64],
) -> Vec<[f64; 3]> {
    let mut out = vec![[0.0; 3]; predicted.len()];
    for (photo, pixels) in pixels_by_photo(layout).iter().enumerate() {
        let maps = [0, 1, 2]
            .map(|c| channel_maps(layout.sizes[photo], pixels, c, predicted, target, weight));
        for &(k, o) in pixels {
            out[k] = [0, 1, 2].map(|c| maps[c].s[o]);
        }
    }
    out
}

/// Each loss pixel's `w sum_c (1 - S_c)`.
pub fn terms(
    layout: &ImageLayout,
    predicted: &[[f64; 3]],
    target: &[[f64; 3]],
    weight: &[f64],
) -> Vec<f64> {
    similarity(layout, predicted, target, weight)
        .iter()
        .zip(weight)
        .map(|(s, w)| w * s.iter().map(|s| 1.0 - s).sum::<f64>())
        .collect()
}

/// `d (sum of terms) / d predicted` per loss pixel and channel.
pub fn term_gradient(
    layout: &ImageLayout,
    predicted: &[[f64; 3]],
    target: &[[f64; 3]],
    weight: &[f64],
) -> Vec<[f64; 3]> {
    let mut out = vec![[0.0; 3]; predicted.len()];
    for (photo, pixels) in pixels_by_photo(layout).iter().enumerate() {
        let size = layout.sizes[photo];
        let grads = [0, 1, 2]
            .map(|c| channel_maps(size, pixels, c, predicted, target, weight).gradient(size));
        for &(k, o) in pixels {
            out[k] = [0, 1, 2].map(|c| grads[c][o]);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn window_is_normalised_and_symmetric() {
        let g = window();
        assert!((g.iter().sum::<f64>() - 1.0).abs() < 1e-15);
        for k in 0..=RADIUS {
            assert_eq!(g[k], g[2 * RADIUS - k]);
        }
    }

    #[test]
    fn uniform_images_have_the_luminance_term_only() {
        // Constant x and y: variances vanish, so S = (2 x y + C1) / (x^2 + y^2 + C1).
        let size = [6, 5];
        let n = 30;
        let (x, y) = (0.6, 1.0);
        let maps = ChannelMaps::new(vec![x; n], vec![y; n], vec![1.0; n], size, 1.0);
        let c1 = K1 * K1;
        let expected = (2.0 * x * y + c1) / (x * x + y * y + c1);
        for s in &maps.s {
            assert!((s - expected).abs() < 1e-12, "{s} vs {expected}");
        }
    }
}

//! Cholesky factor `A = R R^T` (R lower triangular) of a small dense symmetric positive
//! definite matrix, with the triangular products and solves the samplers need. Matrices are
//! row-major `Vec<f64>` of `n * n`; the dimension of a fit is at most 11, so nothing here is
//! blocked or vectorised.

use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Cholesky {
    pub n: usize,
    /// Lower-triangular factor, row-major (the upper triangle is zero).
    pub lower: Vec<f64>,
}

impl Cholesky {
    /// Factor of a symmetric matrix (only its lower triangle is read), or `None` when it is not
    /// numerically positive definite.
    pub fn new(a: &[f64], n: usize) -> Option<Cholesky> {
        let mut l = vec![0.0; n * n];
        for i in 0..n {
            for j in 0..=i {
                let s = a[i * n + j] - (0..j).map(|k| l[i * n + k] * l[j * n + k]).sum::<f64>();
                if i == j {
                    if !(s > 0.0 && s.is_finite()) {
                        return None;
                    }
                    l[i * n + i] = s.sqrt();
                } else {
                    l[i * n + j] = s / l[j * n + j];
                }
            }
        }
        Some(Cholesky { n, lower: l })
    }

    fn at(&self, i: usize, j: usize) -> f64 {
        self.lower[i * self.n + j]
    }

    /// `ln det R` (half the log determinant of `A`).
    pub fn log_det(&self) -> f64 {
        (0..self.n).map(|i| self.at(i, i).ln()).sum()
    }

    /// `R^T v`.
    pub fn transpose_times(&self, v: &[f64]) -> Vec<f64> {
        (0..self.n)
            .map(|i| (i..self.n).map(|k| self.at(k, i) * v[k]).sum())
            .collect()
    }

    /// `R^-1 v` (forward substitution).
    pub fn solve_lower(&self, v: &[f64]) -> Vec<f64> {
        let mut y = vec![0.0; self.n];
        for i in 0..self.n {
            let s = v[i] - (0..i).map(|k| self.at(i, k) * y[k]).sum::<f64>();
            y[i] = s / self.at(i, i);
        }
        y
    }

    /// `R^-T v` (back substitution).
    pub fn solve_transpose(&self, v: &[f64]) -> Vec<f64> {
        let mut y = vec![0.0; self.n];
        for i in (0..self.n).rev() {
            let s = v[i] - (i + 1..self.n).map(|k| self.at(k, i) * y[k]).sum::<f64>();
            y[i] = s / self.at(i, i);
        }
        y
    }

    /// `A^-1 v`.
    pub fn solve(&self, v: &[f64]) -> Vec<f64> {
        self.solve_transpose(&self.solve_lower(v))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn factor_products_and_solves_agree_with_the_matrix() {
        let a = [4.0, 2.0, 0.6, 2.0, 5.0, 1.0, 0.6, 1.0, 3.0];
        let c = Cholesky::new(&a, 3).unwrap();
        let v = [0.3, -1.0, 2.0];
        // A v computed directly and through R (R^T v).
        let rtv = c.transpose_times(&v);
        let av: Vec<f64> = (0..3)
            .map(|i| (0..=i).map(|k| c.at(i, k) * rtv[k]).sum())
            .collect();
        for i in 0..3 {
            let direct: f64 = (0..3).map(|j| a[i * 3 + j] * v[j]).sum();
            assert!((direct - av[i]).abs() < 1e-12);
        }
        let x = c.solve(&v);
        for i in 0..3 {
            let back: f64 = (0..3).map(|j| a[i * 3 + j] * x[j]).sum();
            assert!((back - v[i]).abs() < 1e-12);
        }
        let det = 4.0 * (5.0 * 3.0 - 1.0) - 2.0 * (2.0 * 3.0 - 0.6) + 0.6 * (2.0 - 5.0 * 0.6);
        assert!((2.0 * c.log_det() - f64::ln(det)).abs() < 1e-12);
        assert!(Cholesky::new(&[1.0, 2.0, 2.0, 1.0], 2).is_none());
    }
}

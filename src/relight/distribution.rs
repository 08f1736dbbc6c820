//! Piecewise-constant distributions on `[0, 1)` and `[0, 1)^2`, sampled by inverting their
//! cumulative distribution: the 2D one as a marginal density over rows and a conditional
//! density per row (Pharr, Jakob & Humphreys, "Physically Based Rendering", 3rd ed.,
//! sec. 13.6.7 "Piecewise-Constant 2D Distributions"; the same construction as pbrt-v4's
//! `PiecewiseConstant1D` / `PiecewiseConstant2D`).

/// A density on `[0, 1)` proportional to `func[i]` on the `i`-th of `n` equal cells.
#[derive(Clone, Debug)]
pub struct Distribution1D {
    func: Vec<f64>,
    /// `cdf[i]`: the probability of cells `0..i`; `cdf[n] = 1`.
    cdf: Vec<f64>,
    /// `integral of func` over `[0, 1)` (the mean of `func`).
    integral: f64,
}

impl Distribution1D {
    /// The distribution of the non-negative, finite values `func` (at least one); all zeros
    /// give the uniform distribution.
    pub fn new(func: Vec<f64>) -> Distribution1D {
        let n = func.len();
        assert!(n > 0, "a distribution needs at least one cell");
        debug_assert!(func.iter().all(|f| f.is_finite() && *f >= 0.0));
        let mut cdf = Vec::with_capacity(n + 1);
        cdf.push(0.0);
        for f in &func {
            cdf.push(cdf.last().expect("not empty") + f / n as f64);
        }
        let integral = cdf[n];
        if integral > 0.0 {
            cdf.iter_mut().for_each(|c| *c /= integral);
        } else {
            cdf.iter_mut()
                .enumerate()
                .for_each(|(i, c)| *c = i as f64 / n as f64);
        }
        cdf[n] = 1.0;
        Distribution1D {
            func,
            cdf,
            integral,
        }
    }

    pub fn len(&self) -> usize {
        self.func.len()
    }

    pub fn is_empty(&self) -> bool {
        self.func.is_empty()
    }

    /// The mean of the function over `[0, 1)`.
    pub fn integral(&self) -> f64 {
        self.integral
    }

    /// Density at a point of cell `i`.
    pub fn pdf(&self, i: usize) -> f64 {
        if self.integral > 0.0 {
            self.func[i] / self.integral
        } else {
            1.0
        }
    }

    /// The point `x` in `[0, 1)` whose cumulative probability is `u` in `[0, 1)`, its
    /// density and its cell.
    pub fn sample(&self, u: f64) -> (f64, f64, usize) {
        let n = self.len();
        // The last cell whose cdf is <= u: it has positive probability, since cdf[i + 1] > u.
        let i = (self.cdf.partition_point(|&c| c <= u).max(1) - 1).min(n - 1);
        let width = self.cdf[i + 1] - self.cdf[i];
        let within = if width > 0.0 {
            ((u - self.cdf[i]) / width).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let x = ((i as f64 + within) / n as f64).min(1.0 - f64::EPSILON);
        (x, self.pdf(i), i)
    }

    /// The cell holding `x` in `[0, 1]` (1 belongs to the last cell).
    pub fn cell(&self, x: f64) -> usize {
        ((x * self.len() as f64).max(0.0) as usize).min(self.len() - 1)
    }
}

/// A density on `[0, 1)^2` proportional to a function that is constant on each cell of a
/// `width` x `height` grid (row-major, row `v`, column `u`).
#[derive(Clone, Debug)]
pub struct Distribution2D {
    /// Per row: the conditional density of `u` given the row.
    rows: Vec<Distribution1D>,
    /// The marginal density of `v`: each row's integral.
    marginal: Distribution1D,
}

impl Distribution2D {
    pub fn new(func: &[f64], width: usize, height: usize) -> Distribution2D {
        assert_eq!(func.len(), width * height, "one value per cell");
        let rows: Vec<Distribution1D> = func
            .chunks_exact(width)
            .map(|row| Distribution1D::new(row.to_vec()))
            .collect();
        let marginal = Distribution1D::new(rows.iter().map(Distribution1D::integral).collect());
        Distribution2D { rows, marginal }
    }

    /// The point `(u, v)` drawn from the uniform numbers `xi` and its density.
    pub fn sample(&self, xi: [f64; 2]) -> ([f64; 2], f64) {
        let (v, pdf_v, row) = self.marginal.sample(xi[1]);
        let (u, pdf_u, _) = self.rows[row].sample(xi[0]);
        ([u, v], pdf_u * pdf_v)
    }

    /// Density at `(u, v)`.
    pub fn pdf(&self, uv: [f64; 2]) -> f64 {
        let row = self.marginal.cell(uv[1]);
        let conditional = &self.rows[row];
        conditional.pdf(conditional.cell(uv[0])) * self.marginal.pdf(row)
    }
}

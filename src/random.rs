//! Random numbers and Monte Carlo estimates: the generator every stochastic estimator draws
//! from, independent streams that do not depend on the thread count, and one way to turn
//! repeated draws into a mean with its standard error.
//!
//! One convention for fewer than two draws: the standard error is infinite (one draw says
//! nothing about its spread). A deterministic value is not an estimate of one draw but an exact
//! one; callers that know their value is deterministic say so with [`Estimate::exact`].

use rand::SeedableRng;

/// The random number generator every stochastic estimator draws from (deterministic per seed).
pub type Rng = rand_pcg::Pcg64Mcg;

/// Independent random stream `stream` of the run seeded by `seed`, the same whatever the thread
/// count (SplitMix64 finaliser of the pair, Steele et al. 2014).
pub fn rng_stream(seed: u64, stream: u64) -> Rng {
    let mut z = seed ^ stream.wrapping_add(1).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    Rng::seed_from_u64(z ^ (z >> 31))
}

/// A value per channel with its error bar.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Estimate {
    pub value: [f64; 3],
    /// Standard error of the mean (stochastic models) or quadrature error estimate (analytic).
    pub stderr: [f64; 3],
    pub samples: usize,
}

impl Estimate {
    /// A deterministic value from `samples` evaluations: no error.
    pub fn exact(value: [f64; 3], samples: usize) -> Estimate {
        Estimate {
            value,
            stderr: [0.0; 3],
            samples,
        }
    }
}

/// Running mean and standard error of the mean of `N` channels.
///
/// The mean is the plain sum over the count. The spread is accumulated on the draws shifted
/// by the first one: a constant part (an exact single bounce under a noisy multiple-bounce
/// term) would otherwise swamp the fluctuations in `E[x^2] - E[x]^2` (a 1e-9 spread on top of
/// 0.45 rounds to a zero variance).
#[derive(Clone, Copy, Debug)]
pub struct Moments<const N: usize> {
    shift: Option<[f64; N]>,
    sum: [f64; N],
    shifted_sum: [f64; N],
    shifted_sum2: [f64; N],
    count: usize,
}

impl<const N: usize> Default for Moments<N> {
    fn default() -> Self {
        Moments {
            shift: None,
            sum: [0.0; N],
            shifted_sum: [0.0; N],
            shifted_sum2: [0.0; N],
            count: 0,
        }
    }
}

impl<const N: usize> Moments<N> {
    pub fn push(&mut self, x: [f64; N]) {
        let shift = *self.shift.get_or_insert(x);
        for c in 0..N {
            let d = x[c] - shift[c];
            self.sum[c] += x[c];
            self.shifted_sum[c] += d;
            self.shifted_sum2[c] += d * d;
        }
        self.count += 1;
    }

    /// Adds the draws `other` holds (a part of the same sample accumulated apart, e.g. on
    /// another thread). The sums of the two are added in the order of the calls, so merging
    /// parts in a fixed order gives the same mean whatever the thread count.
    pub fn merge(&mut self, other: &Moments<N>) {
        let Some(theirs) = other.shift else {
            return;
        };
        let ours = *self.shift.get_or_insert(theirs);
        let n = other.count as f64;
        for c in 0..N {
            // Their draws relative to our shift: d = d' + delta.
            let delta = theirs[c] - ours[c];
            self.sum[c] += other.sum[c];
            self.shifted_sum2[c] +=
                other.shifted_sum2[c] + 2.0 * delta * other.shifted_sum[c] + n * delta * delta;
            self.shifted_sum[c] += other.shifted_sum[c] + n * delta;
        }
        self.count += other.count;
    }

    pub fn count(&self) -> usize {
        self.count
    }

    /// The mean per channel (NaN without draws).
    pub fn mean(&self) -> [f64; N] {
        self.sum.map(|s| s / self.count as f64)
    }

    /// The standard error of the mean per channel, `sqrt(s^2 / n)` with the unbiased sample
    /// variance `s^2`; infinite for fewer than two draws.
    pub fn standard_error(&self) -> [f64; N] {
        let n = self.count as f64;
        std::array::from_fn(|c| {
            if self.count < 2 {
                return f64::INFINITY;
            }
            let mean = self.shifted_sum[c] / n;
            ((self.shifted_sum2[c] / n - mean * mean).max(0.0) / (n - 1.0)).sqrt()
        })
    }
}

impl Moments<3> {
    /// The mean and its standard error as an [`Estimate`].
    pub fn estimate(&self) -> Estimate {
        Estimate {
            value: self.mean(),
            stderr: self.standard_error(),
            samples: self.count,
        }
    }
}

/// Mean and standard error of the mean of a sample (NaN for none, infinite error for one).
pub fn mean_and_standard_error(values: &[f64]) -> (f64, f64) {
    let mut moments = Moments::<1>::default();
    values.iter().for_each(|&v| moments.push([v]));
    (moments.mean()[0], moments.standard_error()[0])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mean_and_standard_error_match_the_textbook_values() {
        // Mean 2.5, sample variance 5/3, standard error sqrt(5/12).
        let (mean, se) = mean_and_standard_error(&[1.0, 2.0, 3.0, 4.0]);
        assert_eq!(mean, 2.5);
        assert!((se - (5.0f64 / 12.0).sqrt()).abs() < 1e-15, "{se}");
        let (mean, se) = mean_and_standard_error(&[7.0]);
        assert_eq!((mean, se), (7.0, f64::INFINITY));
        assert!(mean_and_standard_error(&[]).0.is_nan());
    }

    #[test]
    fn a_tiny_spread_on_a_large_constant_keeps_its_variance() {
        // Draws 0.45 + 1e-9 * (-1, +1, -1, +1, ...): standard error 1e-9 * sqrt(n / (n - 1)) / sqrt(n).
        let mut moments = Moments::<3>::default();
        let n = 1000;
        for i in 0..n {
            let v = 0.45 + if i % 2 == 0 { -1e-9 } else { 1e-9 };
            moments.push([v; 3]);
        }
        let expected = 1e-9 / ((n - 1) as f64).sqrt();
        let se = moments.standard_error()[0];
        assert!((se / expected - 1.0).abs() < 1e-6, "{se} vs {expected}");
    }

    #[test]
    fn merged_parts_give_the_moments_of_the_whole() {
        let values: Vec<[f64; 2]> = (0..50)
            .map(|i| [(i as f64 * 0.37).sin(), 3.0 + (i as f64).sqrt()])
            .collect();
        let mut whole = Moments::<2>::default();
        values.iter().for_each(|&v| whole.push(v));
        let mut merged = Moments::<2>::default();
        for part in values.chunks(7) {
            let mut moments = Moments::<2>::default();
            part.iter().for_each(|&v| moments.push(v));
            merged.merge(&moments);
        }
        merged.merge(&Moments::default());
        assert_eq!(merged.count(), 50);
        for c in 0..2 {
            assert!((merged.mean()[c] - whole.mean()[c]).abs() < 1e-14);
            let (a, b) = (merged.standard_error()[c], whole.standard_error()[c]);
            assert!((a / b - 1.0).abs() < 1e-12, "{a} vs {b}");
        }
    }

    #[test]
    fn streams_are_reproducible_and_distinct() {
        use rand::Rng as _;
        let draw = |seed, stream| rng_stream(seed, stream).random::<u64>();
        assert_eq!(draw(1, 2), draw(1, 2));
        assert_ne!(draw(1, 2), draw(1, 3));
        assert_ne!(draw(1, 2), draw(2, 2));
    }
}

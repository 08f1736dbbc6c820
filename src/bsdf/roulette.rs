//! Survival probabilities that are piecewise constant in the material parameters, so that the
//! stochastic estimators have pathwise derivatives that are unbiased and match finite
//! differences at fixed random numbers.
//!
//! | decision | probability used | weight of survival |
//! | --- | --- | --- |
//! | Russian roulette on the energy left (`bitterli`, `cui`) | `q = quantize(p)` | `1 / q` |
//! | analog continuation past a segment (`wang-pt`, `wang-bdpt`) | `q = quantize(e)` | `e / q` |
//!
//! `quantize(p)` keeps the four leading bits of the mantissa of `p` (rounding down, so
//! `p / 1.0625 < q <= p`), is 1 for `p >= 1` and 0 for `p <= 0` or NaN. Any probability gives an
//! unbiased value estimate (`E = q * weight * Y` with the weights above); the choice matters for
//! derivatives. With the walk's random numbers fixed, a decision `U < q(theta)` is a step
//! function of the parameters theta: the derivative of the estimate between steps is
//! `1[U < q] d(weight Y)/d theta`. Were `q` the smooth `p(theta)`, that derivative would miss
//! the boundary term of `d/d theta integral_0^q (...) dU` (its mean would be `E[Y'] - E[Y p'/p]`
//! for roulette, biased), while detaching `q` from the derivative would be unbiased but differ
//! from finite differences of the fixed-random-number objective the optimiser sees. A piecewise
//! constant `q` has `dq/d theta = 0` between its steps and the expected jump of the estimate at
//! a step is zero, so the dual-number derivative is both the derivative of the objective almost
//! everywhere and an unbiased estimate of the gradient of the expected value. Rounding costs at
//! most 6.25% more survivals' weight, i.e. slightly more variance.

/// `p` rounded down to four significant bits, clamped to `[0, 1]` (see the module table).
#[inline]
pub fn piecewise_constant(p: f64) -> f64 {
    if p >= 1.0 {
        1.0
    } else if p > 0.0 {
        // Sign, exponent and the four leading mantissa bits: the top 16 bits of the f64.
        f64::from_bits(p.to_bits() & 0xFFFF_0000_0000_0000)
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantized_probability_is_a_lower_step_within_one_sixteenth() {
        assert_eq!(piecewise_constant(1.5), 1.0);
        assert_eq!(piecewise_constant(-0.1), 0.0);
        assert_eq!(piecewise_constant(f64::NAN), 0.0);
        assert_eq!(piecewise_constant(0.5), 0.5);
        for k in 1..2000 {
            let p = k as f64 / 2000.0 * 0.999 + 1e-9 * k as f64;
            let q = piecewise_constant(p);
            assert!(q <= p && p < q * 1.0625, "{p} -> {q}");
            // Constant on a neighbourhood: a nearby probability rounds to the same step unless
            // a step lies in between (then it is the next step up).
            let q2 = piecewise_constant(p * (1.0 + 1e-9));
            assert!(q2 == q || q2 > p, "{p}: {q} vs {q2}");
        }
    }
}

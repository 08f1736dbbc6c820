//! Convergence diagnostics of several Markov chains of one scalar: rank-normalised split R-hat
//! and bulk effective sample size, after Vehtari, Gelman, Simpson, Carpenter and Bürkner 2021,
//! "Rank-normalization, folding, and localization: an improved R-hat for assessing convergence
//! of MCMC", Bayesian Analysis 16(2).
//!
//! | function | what | paper |
//! | --- | --- | --- |
//! | [`split_rhat`] | max of the split R-hat of the rank-normalised draws and of the rank-normalised folded draws `abs(x - median)` | eq. (4) and section 4.1 |
//! | [`bulk_ess`] | effective sample size of the rank-normalised split chains, Geyer's initial monotone sequence over the multi-chain autocorrelation | section 3.2, eqs. (10)-(11) |
//! | [`normal_quantile`] | inverse of the standard normal CDF (Acklam's rational approximation refined by one Halley step on `erfc`), used for the rank normalisation `z = Phi^-1((r - 3/8) / (S + 1/4))` | eq. (14) |
//!
//! Chains are split in halves (the middle draw of an odd chain is dropped), so a drift within a
//! chain shows up as a difference between halves. Chains of different lengths are cut to the
//! shortest. Constant draws (a parameter that never moved, or a model that was never left) have
//! no spread to compare: R-hat is then 1 and the ESS the number of draws.

/// Rank-normalised split R-hat (the maximum of the bulk and the folded version).
pub fn split_rhat(chains: &[Vec<f64>]) -> f64 {
    let split = split_chains(chains);
    if split.len() < 2 || split[0].len() < 2 {
        return f64::NAN;
    }
    let bulk = basic_rhat(&rank_normalise(&split));
    let mut pooled: Vec<f64> = split.iter().flatten().copied().collect();
    let median = median(&mut pooled);
    let folded: Vec<Vec<f64>> = split
        .iter()
        .map(|c| c.iter().map(|v| (v - median).abs()).collect())
        .collect();
    bulk.max(basic_rhat(&rank_normalise(&folded)))
}

/// Bulk effective sample size of all draws (rank-normalised split chains).
pub fn bulk_ess(chains: &[Vec<f64>]) -> f64 {
    let split = split_chains(chains);
    if split.is_empty() || split[0].len() < 4 {
        return f64::NAN;
    }
    basic_ess(&rank_normalise(&split))
}

/// Chains cut to the shortest length and split in halves.
fn split_chains(chains: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let n = chains.iter().map(Vec::len).min().unwrap_or(0);
    let half = n / 2;
    chains
        .iter()
        .flat_map(|c| [c[..half].to_vec(), c[n - half..n].to_vec()])
        .collect()
}

/// Pooled ranks (ties get their average rank, 1-based) mapped to normal scores.
fn rank_normalise(chains: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let pooled: Vec<f64> = chains.iter().flatten().copied().collect();
    let total = pooled.len();
    let mut order: Vec<usize> = (0..total).collect();
    order.sort_by(|&a, &b| pooled[a].total_cmp(&pooled[b]));
    let mut rank = vec![0.0; total];
    let mut start = 0;
    while start < total {
        let mut end = start + 1;
        while end < total && pooled[order[end]] == pooled[order[start]] {
            end += 1;
        }
        let average = (start + 1 + end) as f64 / 2.0;
        for &i in &order[start..end] {
            rank[i] = average;
        }
        start = end;
    }
    let scores: Vec<f64> = rank
        .iter()
        .map(|r| normal_quantile((r - 0.375) / (total as f64 + 0.25)))
        .collect();
    let mut offset = 0;
    chains
        .iter()
        .map(|c| {
            let chunk = scores[offset..offset + c.len()].to_vec();
            offset += c.len();
            chunk
        })
        .collect()
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len() as f64
}

fn variance(v: &[f64]) -> f64 {
    let m = mean(v);
    v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (v.len() as f64 - 1.0)
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Within-chain variance W and the pooled estimate var+ of the posterior variance.
fn variance_components(chains: &[Vec<f64>]) -> (f64, f64) {
    let n = chains[0].len() as f64;
    let means: Vec<f64> = chains.iter().map(|c| mean(c)).collect();
    let between = n * variance(&means);
    let within = mean(&chains.iter().map(|c| variance(c)).collect::<Vec<_>>());
    (within, (n - 1.0) / n * within + between / n)
}

/// Gelman-Rubin potential scale reduction of equal-length chains.
fn basic_rhat(chains: &[Vec<f64>]) -> f64 {
    let (within, pooled) = variance_components(chains);
    if within <= 0.0 || !within.is_finite() {
        return 1.0;
    }
    (pooled / within).sqrt()
}

/// Autocovariance of one chain at `lag` (biased estimator, divides by n).
fn autocovariance(chain: &[f64], chain_mean: f64, lag: usize) -> f64 {
    let n = chain.len();
    (0..n - lag)
        .map(|i| (chain[i] - chain_mean) * (chain[i + lag] - chain_mean))
        .sum::<f64>()
        / n as f64
}

/// Multi-chain ESS with Geyer's initial monotone sequence estimator.
fn basic_ess(chains: &[Vec<f64>]) -> f64 {
    let (m, n) = (chains.len(), chains[0].len());
    let total = (m * n) as f64;
    let (within, pooled) = variance_components(chains);
    if within <= 0.0 || !within.is_finite() {
        return total;
    }
    let means: Vec<f64> = chains.iter().map(|c| mean(c)).collect();
    let rho = |lag: usize| {
        let mean_autocov = chains
            .iter()
            .zip(&means)
            .map(|(c, &cm)| autocovariance(c, cm, lag) * n as f64 / (n as f64 - 1.0))
            .sum::<f64>()
            / m as f64;
        1.0 - (within - mean_autocov) / pooled
    };
    // tau = -1 + 2 sum_k P_k with P_k = rho_2k + rho_2k+1, truncated at the first negative P_k
    // and made monotone.
    let mut tau = -1.0;
    let mut previous = f64::INFINITY;
    let mut k = 0;
    while 2 * k + 1 < n {
        let pair = rho(2 * k) + rho(2 * k + 1);
        if pair < 0.0 {
            break;
        }
        let pair = pair.min(previous);
        tau += 2.0 * pair;
        previous = pair;
        k += 1;
    }
    // Antithetic chains can give tau < 1; Stan caps the ESS at S log10(S).
    let tau = tau.max(1.0 / total.log10());
    total / tau
}

/// Inverse of the standard normal CDF for `p` in (0, 1).
pub fn normal_quantile(p: f64) -> f64 {
    const A: [f64; 6] = [
        -3.969683028665376e1,
        2.209460984245205e2,
        -2.759285104469687e2,
        1.383_577_518_672_69e2,
        -3.066479806614716e1,
        2.506628277459239,
    ];
    const B: [f64; 5] = [
        -5.447609879822406e1,
        1.615858368580409e2,
        -1.556989798598866e2,
        6.680131188771972e1,
        -1.328068155288572e1,
    ];
    const C: [f64; 6] = [
        -7.784894002430293e-3,
        -3.223964580411365e-1,
        -2.400758277161838,
        -2.549732539343734,
        4.374664141464968,
        2.938163982698783,
    ];
    const D: [f64; 4] = [
        7.784695709041462e-3,
        3.224671290700398e-1,
        2.445134137142996,
        3.754408661907416,
    ];
    let tail = |q: f64| {
        let q = (-2.0 * q.ln()).sqrt();
        (((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    };
    let x = if p < 0.02425 {
        tail(p)
    } else if p > 1.0 - 0.02425 {
        -tail(1.0 - p)
    } else {
        let q = p - 0.5;
        let r = q * q;
        (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * q
            / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
    };
    // One Halley step on Phi(x) - p brings the relative error from 1e-9 to machine precision.
    let e = 0.5 * libm::erfc(-x / std::f64::consts::SQRT_2) - p;
    let u = e * (2.0 * std::f64::consts::PI).sqrt() * (x * x / 2.0).exp();
    x - u / (1.0 + x * u / 2.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_distr::StandardNormal;

    fn iid_chains(seed: u64, chains: usize, n: usize, offsets: &[f64]) -> Vec<Vec<f64>> {
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(seed);
        (0..chains)
            .map(|c| {
                (0..n)
                    .map(|_| offsets[c % offsets.len()] + rng.sample::<f64, _>(StandardNormal))
                    .collect()
            })
            .collect()
    }

    #[test]
    fn normal_quantile_inverts_the_cdf() {
        for p in [1e-10, 1e-4, 0.01, 0.025, 0.3, 0.5, 0.8, 0.975, 0.9999] {
            let x = normal_quantile(p);
            let back = 0.5 * libm::erfc(-x / std::f64::consts::SQRT_2);
            assert!((back - p).abs() < 1e-14 * p.max(1e-3), "{p}: {x} -> {back}");
        }
        assert!((normal_quantile(0.975) - 1.959_963_984_540_054).abs() < 1e-12);
    }

    #[test]
    fn iid_normal_draws_have_rhat_one_and_ess_n() {
        // 4 chains x 1000 iid draws. Under iid sampling the ESS estimate scatters around
        // S = 4000 with a relative sd of about 5% (Vehtari et al. 2021, fig. 5), and R-hat - 1
        // is of order 1/S.
        let chains = iid_chains(1, 4, 1000, &[0.0]);
        let rhat = split_rhat(&chains);
        let ess = bulk_ess(&chains);
        assert!((rhat - 1.0).abs() < 0.01, "R-hat {rhat}");
        assert!((ess - 4000.0).abs() < 0.2 * 4000.0, "ESS {ess}");
    }

    #[test]
    fn chains_with_different_means_have_large_rhat() {
        let chains = iid_chains(2, 4, 500, &[0.0, 0.0, 0.0, 3.0]);
        let rhat = split_rhat(&chains);
        assert!(rhat > 1.3, "R-hat {rhat}");
        // Different scales only: the bulk R-hat misses it, the folded one does not.
        let mut scaled = iid_chains(3, 4, 1000, &[0.0]);
        for v in &mut scaled[3] {
            *v *= 4.0;
        }
        assert!(split_rhat(&scaled) > 1.1, "{}", split_rhat(&scaled));
    }

    #[test]
    fn autocorrelated_chains_have_the_ess_of_an_ar1_process() {
        // AR(1) with coefficient phi has tau = (1 + phi) / (1 - phi) = 9 for phi = 0.8, so
        // 4 x 5000 draws are worth about 2222 independent ones. The estimate of tau from 5000
        // draws per chain has a relative sd of about 10% here (window ~ 4 tau).
        let phi: f64 = 0.8;
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(4);
        let chains: Vec<Vec<f64>> = (0..4)
            .map(|_| {
                let mut x = rng.sample::<f64, _>(StandardNormal) / (1.0 - phi * phi).sqrt();
                (0..5000)
                    .map(|_| {
                        x = phi * x + rng.sample::<f64, _>(StandardNormal);
                        x
                    })
                    .collect()
            })
            .collect();
        let ess = bulk_ess(&chains);
        let expected = 20000.0 / 9.0;
        assert!(
            (ess / expected - 1.0).abs() < 0.25,
            "ESS {ess} vs {expected}"
        );
        assert!(split_rhat(&chains) < 1.01);
    }

    #[test]
    fn constant_draws_are_converged() {
        let chains = vec![vec![2.0; 100]; 4];
        assert_eq!(split_rhat(&chains), 1.0);
        assert_eq!(bulk_ess(&chains), 400.0);
    }
}

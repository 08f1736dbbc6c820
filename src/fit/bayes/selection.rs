//! Choosing among fitted models without trusting raw loss: the Bayesian information criterion
//! under a Gaussian noise model, read on the Kass & Raftery scale, and paired held-out errors.
//!
//! Multiple scattering changes fits of real rough materials only a little (Xie, Bieron, Peers &
//! Hanrahan 2021, 100 MERL materials), so a model with a slightly lower loss is not thereby the
//! better model: the criteria below penalise parameters and say when the data cannot tell two
//! models apart.
//!
//! | quantity | definition | source |
//! | --- | --- | --- |
//! | `n` | observations: pixels in the loss x 3 channels | |
//! | `k` | free parameters of the fit ([`crate::fit::point::params::ParamSpace::dim`]) | |
//! | `rss / n` | mean squared residual `sum w (p - t)^2 / (3 sum w)` at the fitted material (the L2 loss, whatever loss was fitted) | |
//! | BIC | `n ln(rss / n) + k ln n`: Gaussian noise of unknown variance, profiled out | Schwarz 1978; Kass & Raftery 1995, eq. 9 |
//! | Delta-BIC | `BIC - min BIC`, approximately `2 ln` of the Bayes factor for the best model | Kass & Raftery 1995, section 4.1 |
//! | evidence | Delta < 2: not distinguishable; 2-6 positive; 6-10 strong; > 10 very strong | Kass & Raftery 1995, section 3.2 |
//! | held-out difference | per fold `d_f = L_other,f - L_best,f`; distinguishable when `mean d > 2 se(d)` | paired K-fold comparison |
//!
//! The held-out comparison is paired because fold losses vary far more between folds (different
//! photos) than between models on the same fold.

use crate::bsdf::Model;
use crate::random::mean_and_standard_error;
use serde::Serialize;

/// The mean squared residual is floored here so a perfect fit keeps a finite BIC.
const MIN_MEAN_SQUARED_RESIDUAL: f64 = 1e-300;

/// Strength of the evidence for the preferred model over another (Kass & Raftery 1995, 3.2).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Evidence {
    /// The candidate with the lowest BIC itself.
    Preferred,
    /// Delta-BIC below 2: the data cannot tell the two apart.
    NotDistinguishable,
    /// 2 to 6.
    Positive,
    /// 6 to 10.
    Strong,
    /// Above 10.
    VeryStrong,
}

impl Evidence {
    /// The Kass & Raftery reading of a Delta-BIC (`>= 0`) of a candidate that is not the
    /// preferred one.
    pub fn from_delta_bic(delta: f64) -> Evidence {
        if delta < 2.0 {
            Evidence::NotDistinguishable
        } else if delta < 6.0 {
            Evidence::Positive
        } else if delta < 10.0 {
            Evidence::Strong
        } else {
            Evidence::VeryStrong
        }
    }

    pub fn describe(self) -> &'static str {
        match self {
            Evidence::Preferred => "preferred",
            Evidence::NotDistinguishable => "not distinguishable",
            Evidence::Positive => "positive",
            Evidence::Strong => "strong",
            Evidence::VeryStrong => "very strong",
        }
    }
}

/// What the BIC needs from one fitted model.
#[derive(Clone, Copy, Debug)]
pub struct GaussianFit {
    pub model: Model,
    /// `rss / n`, the mean squared residual over the loss pixels and channels.
    pub mean_squared_residual: f64,
    /// Observations (pixels x 3).
    pub observations: usize,
    /// Free parameters.
    pub parameters: usize,
}

impl GaussianFit {
    /// `n ln(rss / n) + k ln n`.
    pub fn bic(&self) -> f64 {
        let n = self.observations.max(1) as f64;
        n * self
            .mean_squared_residual
            .max(MIN_MEAN_SQUARED_RESIDUAL)
            .ln()
            + self.parameters as f64 * n.ln()
    }
}

/// One candidate's line of the selection.
#[derive(Clone, Debug, Serialize)]
pub struct Candidate {
    pub model: Model,
    pub mean_squared_residual: f64,
    pub observations: usize,
    pub parameters: usize,
    pub bic: f64,
    /// BIC minus the lowest BIC of the candidates (0 for the preferred model).
    pub delta_bic: f64,
    /// Evidence for the preferred model over this one.
    pub evidence: Evidence,
}

/// The BIC ranking of a set of fitted models.
#[derive(Clone, Debug, Serialize)]
pub struct Selection {
    /// The model with the lowest BIC.
    pub preferred: Model,
    /// Candidates in the order given.
    pub candidates: Vec<Candidate>,
    /// One sentence saying which model the data prefer and which they cannot tell apart.
    pub verdict: String,
}

impl Selection {
    /// Rank `fits` (at least one) by BIC.
    pub fn rank(fits: &[GaussianFit]) -> Selection {
        let bics: Vec<f64> = fits.iter().map(GaussianFit::bic).collect();
        let best = (0..fits.len())
            .min_by(|&a, &b| bics[a].total_cmp(&bics[b]))
            .expect("at least one candidate");
        let candidates: Vec<Candidate> = fits
            .iter()
            .zip(&bics)
            .enumerate()
            .map(|(i, (fit, &bic))| {
                let delta_bic = bic - bics[best];
                Candidate {
                    model: fit.model,
                    mean_squared_residual: fit.mean_squared_residual,
                    observations: fit.observations,
                    parameters: fit.parameters,
                    bic,
                    delta_bic,
                    evidence: if i == best {
                        Evidence::Preferred
                    } else {
                        Evidence::from_delta_bic(delta_bic)
                    },
                }
            })
            .collect();
        let preferred = fits[best].model;
        let verdict = bic_verdict(preferred, &candidates);
        Selection {
            preferred,
            candidates,
            verdict,
        }
    }
}

/// A verdict sentence: `lead`, then the models the preferred one beats (`beaten_intro`) and the
/// models it cannot be told from (`tied_intro`), each described by the caller.
fn verdict_sentence(
    lead: String,
    beaten: &[String],
    beaten_intro: &str,
    tied: &[String],
    tied_intro: &str,
) -> String {
    let mut sentence = lead;
    if !beaten.is_empty() {
        sentence += &format!("{beaten_intro}{}", beaten.join(", "));
    }
    if !tied.is_empty() {
        sentence += &format!("{tied_intro}{}", tied.join(", "));
    }
    sentence + "."
}

/// The sentence of a BIC ranking: the preferred model, the strength of the evidence against the
/// others, and the models it cannot be told from.
fn bic_verdict(preferred: Model, candidates: &[Candidate]) -> String {
    let others: Vec<&Candidate> = candidates.iter().filter(|c| c.model != preferred).collect();
    if others.is_empty() {
        return format!("only {preferred} was fitted; BIC has nothing to compare.");
    }
    let (tied, beaten): (Vec<&Candidate>, Vec<&Candidate>) = others
        .into_iter()
        .partition(|c| c.evidence == Evidence::NotDistinguishable);
    let describe = |c: &&Candidate| {
        format!(
            "{} (Delta-BIC {:.1}, {})",
            c.model,
            c.delta_bic,
            c.evidence.describe()
        )
    };
    verdict_sentence(
        format!("BIC prefers {preferred}"),
        &beaten.iter().map(describe).collect::<Vec<_>>(),
        " over ",
        &tied.iter().map(describe).collect::<Vec<_>>(),
        "; the data cannot tell it apart (Delta-BIC < 2) from ",
    )
}

/// Held-out losses of one model, one per fold (the same folds for every model).
#[derive(Clone, Debug)]
pub struct HeldOutErrors {
    pub model: Model,
    pub fold_losses: Vec<f64>,
}

/// The held-out comparison of a set of models: the one with the lowest mean held-out loss, and
/// for each other model the paired difference to it.
#[derive(Clone, Debug, Serialize)]
pub struct HeldOutRanking {
    pub preferred: Model,
    pub differences: Vec<HeldOutDifference>,
    pub verdict: String,
}

/// Mean paired held-out loss difference `other - preferred` and its standard error.
#[derive(Clone, Debug, Serialize)]
pub struct HeldOutDifference {
    pub model: Model,
    pub mean: f64,
    pub standard_error: f64,
    /// `mean > 2 standard_error`: the preferred model predicts held-out photos better.
    pub distinguishable: bool,
}

impl HeldOutRanking {
    /// Rank models (at least one, all with the same number of folds) by mean held-out loss.
    pub fn rank(errors: &[HeldOutErrors]) -> HeldOutRanking {
        let means: Vec<f64> = errors
            .iter()
            .map(|e| mean_and_standard_error(&e.fold_losses).0)
            .collect();
        let best = (0..errors.len())
            .min_by(|&a, &b| means[a].total_cmp(&means[b]))
            .expect("at least one model");
        let differences: Vec<HeldOutDifference> = errors
            .iter()
            .enumerate()
            .filter(|(i, _)| *i != best)
            .map(|(_, e)| {
                let paired: Vec<f64> = e
                    .fold_losses
                    .iter()
                    .zip(&errors[best].fold_losses)
                    .map(|(other, best)| other - best)
                    .collect();
                let (mean, standard_error) = mean_and_standard_error(&paired);
                HeldOutDifference {
                    model: e.model,
                    mean,
                    standard_error,
                    distinguishable: mean > 2.0 * standard_error,
                }
            })
            .collect();
        let preferred = errors[best].model;
        let verdict = held_out_verdict(preferred, &differences);
        HeldOutRanking {
            preferred,
            differences,
            verdict,
        }
    }
}

fn held_out_verdict(preferred: Model, differences: &[HeldOutDifference]) -> String {
    if differences.is_empty() {
        return format!("only {preferred} was fitted; held-out error has nothing to compare.");
    }
    let (beaten, tied): (Vec<&HeldOutDifference>, Vec<&HeldOutDifference>) =
        differences.iter().partition(|d| d.distinguishable);
    let describe = |d: &&HeldOutDifference| {
        format!("{} (+{:.3e} +- {:.3e})", d.model, d.mean, d.standard_error)
    };
    verdict_sentence(
        format!("Held-out photos are predicted best by {preferred}"),
        &beaten.iter().map(describe).collect::<Vec<_>>(),
        "; worse by more than two standard errors: ",
        &tied.iter().map(describe).collect::<Vec<_>>(),
        "; within two standard errors, so not distinguishable: ",
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fit(model: Model, mse: f64, n: usize, k: usize) -> GaussianFit {
        GaussianFit {
            model,
            mean_squared_residual: mse,
            observations: n,
            parameters: k,
        }
    }

    #[test]
    fn bic_is_the_gaussian_profile_likelihood_plus_the_parameter_penalty() {
        // -2 ln L at the maximum over sigma^2 of n Gaussian residuals with sum of squares rss:
        // n ln(2 pi rss / n) + n; BIC drops the constants that every model shares.
        let (n, rss, k) = (300usize, 12.0, 4usize);
        let sigma2 = rss / n as f64;
        let log_likelihood =
            -0.5 * n as f64 * (2.0 * std::f64::consts::PI * sigma2).ln() - rss / (2.0 * sigma2);
        let full = -2.0 * log_likelihood + k as f64 * (n as f64).ln();
        let shared = n as f64 * ((2.0 * std::f64::consts::PI).ln() + 1.0);
        let bic = fit(Model::Single, sigma2, n, k).bic();
        assert!((bic - (full - shared)).abs() < 1e-9 * full.abs());
        // A perfect fit stays finite.
        assert!(fit(Model::Single, 0.0, n, k).bic().is_finite());
    }

    #[test]
    fn kass_raftery_bands() {
        let cases = [
            (0.0, Evidence::NotDistinguishable),
            (1.99, Evidence::NotDistinguishable),
            (2.0, Evidence::Positive),
            (5.9, Evidence::Positive),
            (6.0, Evidence::Strong),
            (9.9, Evidence::Strong),
            (10.0, Evidence::VeryStrong),
            (1e6, Evidence::VeryStrong),
        ];
        for (delta, evidence) in cases {
            assert_eq!(Evidence::from_delta_bic(delta), evidence, "delta {delta}");
        }
    }

    #[test]
    fn ranking_prefers_lower_bic_and_penalises_extra_parameters() {
        let n = 10_000;
        // Same residual, one more parameter: the simpler model wins by ln n = 9.2 (strong).
        let s = Selection::rank(&[
            fit(Model::Heitz, 1e-3, n, 5),
            fit(Model::Single, 1e-3, n, 4),
        ]);
        assert_eq!(s.preferred, Model::Single);
        assert_eq!(s.candidates[1].delta_bic, 0.0);
        assert_eq!(s.candidates[1].evidence, Evidence::Preferred);
        assert!((s.candidates[0].delta_bic - (n as f64).ln()).abs() < 1e-9);
        assert_eq!(s.candidates[0].evidence, Evidence::Strong);
        // A residual 1% lower is worth n ln(1/0.99) = 100 BIC units: very strong.
        let s = Selection::rank(&[
            fit(Model::Single, 1e-3, n, 4),
            fit(Model::KullaConty, 0.99e-3, n, 4),
        ]);
        assert_eq!(s.preferred, Model::KullaConty);
        assert_eq!(s.candidates[0].evidence, Evidence::VeryStrong);
        assert!(s.verdict.contains("prefers kulla-conty over single"));
        // A residual lower by 1e-5 relative (0.1 BIC units) cannot be told apart.
        let s = Selection::rank(&[
            fit(Model::Single, 1e-3, n, 4),
            fit(Model::KullaConty, 1e-3 * (1.0 - 1e-5), n, 4),
        ]);
        assert_eq!(s.candidates[0].evidence, Evidence::NotDistinguishable);
        assert!(
            s.verdict
                .contains("cannot tell it apart (Delta-BIC < 2) from single"),
            "{}",
            s.verdict
        );
    }

    #[test]
    fn held_out_ranking_pairs_folds() {
        // Fold losses vary by a factor 20 between folds, but kulla-conty is better on every
        // fold by about 0.01: paired, that is many standard errors; unpaired it would be lost
        // in the fold-to-fold spread.
        let single = vec![1.00, 10.0, 3.0, 0.5];
        let kulla: Vec<f64> = single
            .iter()
            .enumerate()
            .map(|(i, l)| l - 0.01 * (1.0 + 0.1 * i as f64))
            .collect();
        let unpaired_se = mean_and_standard_error(&single).1;
        assert!(unpaired_se > 100.0 * 0.0115);
        let r = HeldOutRanking::rank(&[
            HeldOutErrors {
                model: Model::Single,
                fold_losses: single.clone(),
            },
            HeldOutErrors {
                model: Model::KullaConty,
                fold_losses: kulla,
            },
        ]);
        assert_eq!(r.preferred, Model::KullaConty);
        assert!(r.differences[0].distinguishable);
        // Differences of alternating sign: not distinguishable.
        let noisy: Vec<f64> = single
            .iter()
            .enumerate()
            .map(|(i, l)| l + if i % 2 == 0 { 0.01 } else { -0.0099 })
            .collect();
        let r = HeldOutRanking::rank(&[
            HeldOutErrors {
                model: Model::Single,
                fold_losses: single,
            },
            HeldOutErrors {
                model: Model::Heitz,
                fold_losses: noisy,
            },
        ]);
        assert!(!r.differences[0].distinguishable);
        assert!(r.verdict.contains("not distinguishable"), "{}", r.verdict);
    }
}

//! The model registry: the list of models, one row of capabilities per model ([`TABLE`]), and
//! the constructors, the one place a [`Model`] becomes a BRDF object.
//!
//! Code that needs to know something about a model (whether its value is an estimate, whether
//! the fitter can differentiate it, what the batch kernel or the render plan may do with it)
//! reads the model's row through [`Model::capabilities`] rather than asking for it by name, so
//! adding a model is its file, its variant of [`Model`], its row and its arm in the
//! constructors. The render layer builds a model's batch lobe from the row's [`BatchLobe`]
//! (`crate::render::batch::Lobe::of`): it sits above this module, which only names it.
//!
//! The columns (fields of [`Capabilities`]) and the sources of their values:
//!
//! | column | question it answers | source |
//! | --- | --- | --- |
//! | `name` | the name of the command line, the material file and the fit file | PHYSICS.md |
//! | `paths` | stochastic: which paths the Monte Carlo estimate integrates | each estimator's paper |
//! | `generic` | is the value generic over the scalar type (exact or pathwise derivatives)? | [`differentiable`] |
//! | `explicit_heights` | does the walk track heights (and so ignore the `height` setting)? | Heitz et al. 2016 |
//! | `batch`, `lanes` | which lobe the batch kernel evaluates; the precision of its lanes | measured (see the fields) |
//! | `f0` | how a pixel's prediction depends on a grey Schlick F0 (variable projection) | each model's formula |
//! | `multi` | whether there is a multiple-bounce term, and which render-plan skips it allows | each model's formula |
//! | `surrogate` | the deterministic model a defect-corrected fit of a stochastic one fits | Heitz et al. 2016 |
//! | `prepared_directions` | does the lobe read direction pairs prepared once per fit? | [`tabulated`] |
//! | `conserves_toward_view` | is the white albedo 1 toward a fixed view rather than from a fixed light? | Turquin 2019 eq. 6-7 |
//!
//! A compile-time check keeps the rows in the order of the variants, and the tests check each
//! row against the objects the constructors build.

use super::single::SingleBounce;
use super::{
    bitterli, cui, fast_msx, heitz, kulla_conty, tabulated, turquin, wang, BounceCap, Brdf,
    ScalarBrdf,
};
use crate::scalar::Real;
use serde::{Deserialize, Serialize};

/// The models the command line accepts (PHYSICS.md "Multi-bounce models"), in the order of
/// [`Model::ALL`] (the order the command line lists them in).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Model {
    /// Walter et al. 2007: analytic, loses the energy of multiple bounces.
    Single,
    /// Heitz et al. 2016: random walk on the Smith microsurface with explicit heights,
    /// unbiased, energy conserving, reciprocal; the reference of the multi-bounce models.
    Heitz,
    /// Bitterli & d'Eon 2022: position-free, hyperexponential heights, unbiased.
    Bitterli,
    /// Cui et al. 2023: position-free, segment term by dynamic programming, unbiased.
    Cui,
    /// Wang et al. 2022, position-free path integral estimated by path tracing.
    WangPt,
    /// Wang et al. 2022, position-free path integral estimated bidirectionally.
    WangBdpt,
    /// Rosales et al. 2023: single plus an analytic second-bounce lobe.
    FastMsx,
    /// Kulla & Conty 2017: single plus a tabulated compensation lobe.
    KullaConty,
    /// Turquin 2019: single scaled by a tabulated compensation factor.
    Turquin,
    /// Heitz et al. 2016's multiple-bounce lobe, tabulated once by order: deterministic.
    Tabulated,
}

/// The paths whose contribution a stochastic model's estimate integrates (one path-length
/// distribution each: what [`super::bounce_tails`] tabulates).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Paths {
    /// The walk on the Smith microsurface (Heitz et al. 2016), estimated with explicit heights
    /// (`heitz`) or position-free (`bitterli`, `cui`).
    Smith,
    /// The position-free path integral of Wang et al. 2022, whose path lengths depend on the
    /// height model.
    Wang,
}

/// The whole value of a model as the batch kernel evaluates it in its lanes: the single lobe
/// and the multiple-bounce term beside it (`crate::render::batch`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BatchLobe {
    /// The single lobe alone.
    Single,
    /// Turquin 2019 eq. 6-7: the single lobe scaled by `1 + F0 (1 - E(mu_o)) / E(mu_o)`.
    Turquin,
    /// Kulla & Conty 2017: the compensation lobe added to the single lobe.
    KullaConty,
    /// Rosales et al. 2023 eq. 20: the second-bounce lobe added to the single lobe; the
    /// records carry its tilted-normal geometry.
    FastMsx,
}

/// The arithmetic of the batch kernel's lanes.
#[derive(
    Clone,
    Copy,
    Debug,
    Default,
    PartialEq,
    Eq,
    serde::Serialize,
    serde::Deserialize,
    clap::ValueEnum,
)]
#[serde(rename_all = "lowercase")]
pub enum Precision {
    /// Single precision lanes (the default): sixteen per AVX-512 instruction.
    #[default]
    F32,
    /// Double precision lanes: the reference the `f32` lanes are measured against.
    F64,
}

/// How a pixel's prediction depends on a grey Schlick F0, which decides how variable
/// projection (`crate::fit::point::projection`) solves F0 in closed form.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum F0Dependence {
    /// A polynomial of this degree, projected exactly: 1 for `single` (Schlick is linear in
    /// F0), 2 for `fast-msx` (`F^2`, Rosales et al. 2023 eq. 19) and `turquin`
    /// (`f_single (1 + F0 k)`, Turquin 2019 eq. 6-7).
    Polynomial(usize),
    /// `A + B F0 + W s(F0)`: an image `W` times the colour `s = F_ms / (pi (1 - E_avg))` of
    /// the compensation lobe (Kulla & Conty 2017), rational in F0 and exact in the basis
    /// `1, F0, s(F0)`.
    Compensated,
    /// `A + B F0 + sum_g inner_g(F0) Q_g(F0)` over the order groups of the tabulated lobe
    /// ([`tabulated::SchlickOrders`]).
    Orders,
    /// One Fresnel factor per bounce of a walk: a long polynomial, approximated.
    PerBounce,
}

/// A model's multiple-bounce term, and the render plan's skips it allows
/// (`crate::render::plan`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MultipleBounces {
    /// An additive lobe smooth in `(wi, wo)`, so that it may be interpolated from anchors
    /// (`sparse-multi`): not `turquin`, which scales the single lobe and so has its sharpness.
    pub smooth: bool,
    /// Bounded by the energy single scattering loses, `1 - E_avg(alpha)` in white (Kulla &
    /// Conty 2017 eq. 7), so that it may be dropped where that is faint (`faint-multi`): not
    /// `fast-msx`, whose lobe can exceed it (docs/models.md).
    pub within_lost_energy: bool,
}

/// One row of the table: what the rest of the program may ask about a model.
#[derive(Clone, Copy, Debug)]
pub struct Capabilities {
    pub model: Model,
    /// The name of the command line, the material file and the fit file.
    pub name: &'static str,
    /// For a stochastic model (its value a Monte Carlo estimate), the paths it integrates;
    /// `None` for a deterministic one.
    pub paths: Option<Paths>,
    /// Whether the value is generic over the scalar type ([`differentiable`]), so that a fit
    /// takes exact (for the stochastic models pathwise) derivatives by dual numbers. A model
    /// that is not gets central differences, and the fit's `auto` optimiser runs Nelder-Mead
    /// on it: `heitz`'s walks branch on explicit heights, and central differences at fixed
    /// random numbers step over the jumps where a walk changes its path.
    pub generic: bool,
    /// Whether the walk tracks explicit heights (Heitz et al. 2016): its first order is the
    /// height-correlated single bounce whatever the `height` setting says.
    pub explicit_heights: bool,
    /// What the batch kernel evaluates of the whole value; `None` where it evaluates the
    /// single lobe only and the render plan gives the multiple-bounce term to the scalar
    /// kernel.
    pub batch: Option<BatchLobe>,
    /// The lanes a fit uses unless told otherwise: `f32` for `single`, `f64` for every model
    /// with a multiple-bounce term. Measured: with `f32` lanes the cost's rounding stalls
    /// L-BFGS's last line searches of those fits. On `aluminium-pinhole` (conductor) and
    /// `copper-flash`, `f32` against `f64` lanes took: `kulla-conty` 288 and 180 evaluations
    /// against 67 and 110, `fast-msx` 234 and 124 against 57 and 65, `turquin` 186 and 206
    /// against 90 and 177, `tabulated` 206 and 272 against 73 and 195, `bitterli` 473 and 411
    /// against 100 and 224, `wang-pt` 59 and 190 against 48 and 155, to the same alpha; `f64`
    /// lanes cost less than that difference (docs/speed.md).
    pub lanes: Precision,
    /// How the prediction depends on a grey Schlick F0.
    pub f0: F0Dependence,
    /// The multiple-bounce term; `None` for `single`, which has none.
    pub multi: Option<MultipleBounces>,
    /// The deterministic model that claims the same value, on which a stochastic model is
    /// fitted by defect correction (`--stochastic-fit corrected`): `tabulated` is `heitz`'s
    /// lobe tabulated by order, and `bitterli` and `cui` estimate the same Smith walk. Wang's
    /// path integral is another value.
    pub surrogate: Option<Model>,
    /// Whether the multiple-bounce lobe is [`tabulated::Tabulated`]'s, which reads each
    /// direction pair as [`tabulated::LobeDirections`] that a fit may prepare once.
    pub prepared_directions: bool,
    /// Whether the white albedo is 1 toward a fixed *view* direction rather than from a fixed
    /// light direction: Turquin 2019 (eq. 6-7) scales the lobe by a function of `wo` alone, so
    /// `integral f cos dwi = 1` for white Fresnel while `integral f cos dwo` is unbounded at
    /// grazing.
    pub conserves_toward_view: bool,
}

impl Capabilities {
    /// Whether the value is a Monte Carlo estimate.
    #[inline]
    pub const fn stochastic(&self) -> bool {
        self.paths.is_some()
    }
}

/// A multiple-bounce term that every render-plan skip applies to.
const ADDED_LOBE: Option<MultipleBounces> = Some(MultipleBounces {
    smooth: true,
    within_lost_energy: true,
});

/// The row of a stochastic estimator of `paths` (none is served by the batch kernel).
const fn estimator(model: Model, name: &'static str, paths: Paths) -> Capabilities {
    Capabilities {
        model,
        name,
        paths: Some(paths),
        generic: true,
        explicit_heights: false,
        batch: None,
        lanes: Precision::F64,
        f0: F0Dependence::PerBounce,
        multi: ADDED_LOBE,
        surrogate: None,
        prepared_directions: false,
        conserves_toward_view: false,
    }
}

/// One row per model, in the order of the variants of [`Model`].
pub const TABLE: [Capabilities; 10] = [
    Capabilities {
        model: Model::Single,
        name: "single",
        paths: None,
        generic: true,
        explicit_heights: false,
        batch: Some(BatchLobe::Single),
        lanes: Precision::F32,
        f0: F0Dependence::Polynomial(1),
        multi: None,
        surrogate: None,
        prepared_directions: false,
        conserves_toward_view: false,
    },
    Capabilities {
        generic: false,
        explicit_heights: true,
        surrogate: Some(Model::Tabulated),
        ..estimator(Model::Heitz, "heitz", Paths::Smith)
    },
    Capabilities {
        surrogate: Some(Model::Tabulated),
        ..estimator(Model::Bitterli, "bitterli", Paths::Smith)
    },
    Capabilities {
        surrogate: Some(Model::Tabulated),
        ..estimator(Model::Cui, "cui", Paths::Smith)
    },
    estimator(Model::WangPt, "wang-pt", Paths::Wang),
    estimator(Model::WangBdpt, "wang-bdpt", Paths::Wang),
    Capabilities {
        model: Model::FastMsx,
        name: "fast-msx",
        paths: None,
        generic: true,
        explicit_heights: false,
        batch: Some(BatchLobe::FastMsx),
        lanes: Precision::F64,
        f0: F0Dependence::Polynomial(2),
        multi: Some(MultipleBounces {
            smooth: true,
            within_lost_energy: false,
        }),
        surrogate: None,
        prepared_directions: false,
        conserves_toward_view: false,
    },
    Capabilities {
        model: Model::KullaConty,
        name: "kulla-conty",
        paths: None,
        generic: true,
        explicit_heights: false,
        batch: Some(BatchLobe::KullaConty),
        lanes: Precision::F64,
        f0: F0Dependence::Compensated,
        multi: ADDED_LOBE,
        surrogate: None,
        prepared_directions: false,
        conserves_toward_view: false,
    },
    Capabilities {
        model: Model::Turquin,
        name: "turquin",
        paths: None,
        generic: true,
        explicit_heights: false,
        batch: Some(BatchLobe::Turquin),
        lanes: Precision::F64,
        f0: F0Dependence::Polynomial(2),
        multi: Some(MultipleBounces {
            smooth: false,
            within_lost_energy: true,
        }),
        surrogate: None,
        prepared_directions: false,
        conserves_toward_view: true,
    },
    Capabilities {
        model: Model::Tabulated,
        name: "tabulated",
        paths: None,
        generic: true,
        explicit_heights: false,
        batch: None,
        lanes: Precision::F64,
        f0: F0Dependence::Orders,
        multi: ADDED_LOBE,
        surrogate: None,
        prepared_directions: true,
        conserves_toward_view: false,
    },
];

// Row `i` describes the variant with discriminant `i`, so that a lookup is an index.
const _: () = {
    let mut i = 0;
    while i < TABLE.len() {
        assert!(
            TABLE[i].model as usize == i,
            "TABLE is out of the variants' order"
        );
        i += 1;
    }
};

impl Model {
    /// Every model, in the order of [`TABLE`].
    pub const ALL: [Model; TABLE.len()] = {
        let mut all = [Model::Single; TABLE.len()];
        let mut i = 0;
        while i < all.len() {
            all[i] = TABLE[i].model;
            i += 1;
        }
        all
    };

    /// The model's row of [`TABLE`].
    #[inline]
    pub const fn capabilities(self) -> &'static Capabilities {
        &TABLE[self as usize]
    }

    pub fn name(self) -> &'static str {
        self.capabilities().name
    }
}

impl std::str::FromStr for Model {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        Model::ALL
            .into_iter()
            .find(|m| m.name() == s)
            .ok_or_else(|| {
                let names: Vec<_> = Model::ALL.iter().map(|m| m.name()).collect();
                format!("unknown model '{s}' (known: {})", names.join(", "))
            })
    }
}

impl std::fmt::Display for Model {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// The one list of constructors: `$model` built on `$single` (a [`SingleBounce`]) with its
/// stochastic estimators limited to `$cap`, each model's value handed to `$wrap`; `heitz`,
/// whose walk exists at `f64` only, is `$heitz`.
macro_rules! construct {
    ($model:expr, $single:expr, $cap:expr, $wrap:path, heitz: $heitz:expr) => {{
        let (single, cap) = ($single, $cap);
        let (mf, fresnel) = (single.microfacet, single.fresnel);
        let wang = |estimator| wang::Wang::new(single, estimator).with_bounce_cap(cap);
        match $model {
            Model::Single => $wrap(single),
            Model::FastMsx => $wrap(fast_msx::FastMsx { single }),
            Model::KullaConty => $wrap(kulla_conty::KullaConty::new(single)),
            Model::Turquin => $wrap(turquin::Turquin::new(single)),
            Model::Tabulated => $wrap(tabulated::Tabulated::new(single)),
            Model::Bitterli => $wrap(bitterli::Bitterli::new(mf, fresnel).with_bounce_cap(cap)),
            Model::Cui => $wrap(cui::Cui::new(mf, fresnel).with_bounce_cap(cap)),
            Model::WangPt => $wrap(wang(wang::WangEstimator::PathTracing)),
            Model::WangBdpt => $wrap(wang(wang::WangEstimator::Bidirectional)),
            Model::Heitz => $heitz,
        }
    }};
}

/// `model` built on `single` as a BRDF object, its stochastic estimators limited to paths of
/// `cap` reflections (the analytic models ignore it). `heitz` ignores `single.height`: its
/// first order is the height-correlated single bounce.
pub fn brdf(model: Model, single: SingleBounce<f64>, cap: BounceCap) -> Box<dyn Brdf> {
    construct!(model, single, cap, Box::new, heitz: Box::new(
        heitz::Heitz::new(single.microfacet, single.fresnel).with_bounce_cap(cap)
    ))
}

/// `model` built on `single` at scalar type `T`, its stochastic estimators limited to `cap`,
/// for the models whose value is generic over the scalar ([`Capabilities::generic`]); `None`
/// for `heitz` (explicit heights: finite differences only).
pub fn differentiable<T: Real>(
    model: Model,
    single: SingleBounce<T>,
    cap: BounceCap,
) -> Option<Box<dyn ScalarBrdf<T>>> {
    construct!(model, single, cap, boxed_scalar, heitz: None)
}

/// A model's value at scalar type `T` as the object [`differentiable`] returns.
fn boxed_scalar<T: Real, B: ScalarBrdf<T> + 'static>(brdf: B) -> Option<Box<dyn ScalarBrdf<T>>> {
    Some(Box::new(brdf))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::microfacet::{Fresnel, Height, Microfacet, NdfKind};

    fn single() -> SingleBounce<f64> {
        SingleBounce {
            microfacet: Microfacet::new(NdfKind::Ggx, 0.5, 0.5),
            fresnel: Fresnel::White,
            height: Height::Correlated,
        }
    }

    #[test]
    fn rows_agree_with_the_objects_the_constructors_build() {
        for model in Model::ALL {
            let row = model.capabilities();
            let brdf = brdf(model, single(), BounceCap::NONE);
            assert_eq!(brdf.is_stochastic(), row.stochastic(), "{model}");
            let generic = differentiable(model, single(), BounceCap::NONE).is_some();
            assert_eq!(generic, row.generic, "{model}");
            assert!(
                row.generic || row.explicit_heights,
                "{model}: why not generic?"
            );
        }
    }

    #[test]
    fn names_are_the_serialised_names_and_parse_back() {
        for model in Model::ALL {
            let json = serde_json::to_string(&model).unwrap();
            assert_eq!(json, format!("\"{}\"", model.name()));
            assert_eq!(model.name().parse::<Model>(), Ok(model));
        }
    }

    #[test]
    fn a_surrogate_is_deterministic_and_a_stochastic_model_has_one_only_for_its_own_value() {
        for model in Model::ALL {
            if let Some(surrogate) = model.capabilities().surrogate {
                assert!(model.capabilities().stochastic(), "{model}");
                assert!(!surrogate.capabilities().stochastic(), "{model}");
                assert_eq!(model.capabilities().paths, Some(Paths::Smith), "{model}");
            }
        }
    }
}

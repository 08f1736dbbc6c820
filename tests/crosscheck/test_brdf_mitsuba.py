"""The `single` BRDF (`bouncefit brdf --model single --height uncorrelated --pairs`) against
Mitsuba 3's `roughconductor` (variant scalar_rgb, float32).

| convention | ours | Mitsuba |
| --- | --- | --- |
| directions | `wi` to the light, `wo` to the camera, z = normal | `si.wi` to the camera, `eval`'s `wo` to the light, in the shading frame |
| value | `f` in 1/sr | `eval` returns `f * cos(theta)` of the light direction, so we divide by the light's z |
| masking-shadowing | `--height uncorrelated`: `G1(wi) G1(wo)`, exact Smith `G1` for GGX and Beckmann | `G1(wi) G1(wo)`; exact for GGX, for Beckmann the rational approximation of Walter et al. 2007 eq. 27 (< 0.35% per G1) |
| Fresnel | exact conductor, RGB `eta + i k` | exact conductor; built-in materials ('Cu', 'Au', 'Al') are spectral tables that scalar_rgb converts to RGB `eta`, `k`: we read those values back with `mi.traverse` and give our tool the same |

`sample_visible` only changes Mitsuba's sampling, not `eval`. Beckmann values are compared after
replacing Mitsuba's rational `G1` by the exact one (both formulas below; the uncorrected
difference is printed too: it is the approximation's own error). Values below 1e-6 1/sr, where
float32 Beckmann `D` underflows to 0, are compared in absolute terms instead.
"""

import json
from math import erf, exp, pi, sqrt

import mitsuba as mi
import numpy as np
import pytest

from conftest import ROOT, report, run_json

RELATIVE_TOLERANCE = 1e-4
SMALL = 1e-6
THETAS = [0, 10, 25, 40, 55, 70, 80, 87]
PHIS = [0, 45, 90, 135, 180]
ALPHAS = [0.02, 0.1, 0.3, 0.6, 1.0]
COPPER = json.loads((ROOT / "datasets/copper-flash/material.json").read_text())["fresnel"]


def direction(theta, phi):
    t, p = np.radians(theta), np.radians(phi)
    return [np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)]


PAIRS = [(direction(ti, 0), direction(to, po)) for ti in THETAS for to in THETAS for po in PHIS]


def smith_argument(w, alpha):
    """a = 1 / (alpha tan theta) of a unit direction (infinite at the normal)."""
    tangent = sqrt(max(0.0, 1.0 - w[2] ** 2)) / w[2]
    return np.inf if tangent == 0 else 1.0 / (alpha * tangent)


def beckmann_g1_exact(a):
    """1 / (1 + Lambda(a)), Lambda = (erf(a) - 1) / 2 + exp(-a^2) / (2 a sqrt(pi)) (Walter 2007 eq. 25)."""
    return 1.0 if np.isinf(a) else 1.0 / (1.0 + (erf(a) - 1.0) / 2.0 + exp(-a * a) / (2.0 * a * sqrt(pi)))


def beckmann_g1_rational(a):
    """Walter et al. 2007 eq. 27, which Mitsuba 3 evaluates for Beckmann."""
    return 1.0 if a >= 1.6 else (3.535 * a + 2.181 * a * a) / (1.0 + 2.276 * a + 2.577 * a * a)


def mitsuba_values(bsdf):
    """f = eval / cos(light) at every pair, shape (pairs, 3)."""
    context = mi.BSDFContext()
    interaction = mi.SurfaceInteraction3f()
    interaction.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
    values = []
    for wi, wo in PAIRS:
        interaction.wi = mi.Vector3f(*wo)
        value = bsdf.eval(context, interaction, mi.Vector3f(*wi))
        values.append([value[0] / wi[2], value[1] / wi[2], value[2] / wi[2]])
    return np.array(values)


def conductor(name):
    """The roughconductor parameters and the eta, k the Mitsuba BSDF actually uses."""
    if name == "explicit":
        parameters = {"eta": {"type": "rgb", "value": COPPER["eta"]}, "k": {"type": "rgb", "value": COPPER["k"]}}
    else:
        parameters = {"material": name}
    probe = mi.traverse(mi.load_dict({"type": "roughconductor", **parameters}))
    eta = [float(probe["eta.value"][c]) for c in range(3)]
    k = [float(probe["k.value"][c]) for c in range(3)]
    return parameters, eta, k


def ours(tmp_path, ndf, alpha, eta, k):
    pairs = tmp_path / "pairs.json"
    pairs.write_text(json.dumps(PAIRS))
    fresnel = "conductor:" + ",".join(map(repr, eta)) + ":" + ",".join(map(repr, k))
    out = run_json("brdf", "--model", "single", "--ndf", ndf, "--alpha", alpha, "--height", "uncorrelated",
                   "--fresnel", fresnel, "--pairs", pairs)
    return np.array(out["f"])


def worst_error(ours_f, reference):
    large = reference > SMALL
    relative = np.abs(ours_f - reference)[large] / reference[large]
    absolute = np.abs(ours_f - reference)[~large]
    return relative.max(), absolute.max(initial=0.0), large.sum()


@pytest.mark.parametrize("material", ["explicit", "Cu", "Au", "Al"])
@pytest.mark.parametrize("ndf", ["ggx", "beckmann"])
def test_single_matches_roughconductor(tmp_path, material, ndf):
    parameters, eta, k = conductor(material)
    worst_relative, worst_absolute, worst_uncorrected = 0.0, 0.0, 0.0
    compared, values = 0, 0
    for alpha in ALPHAS:
        bsdf = mi.load_dict({"type": "roughconductor", "distribution": ndf, "alpha": alpha, **parameters})
        reference = mitsuba_values(bsdf)
        f = ours(tmp_path, ndf, alpha, eta, k)
        if ndf == "beckmann":
            worst_uncorrected = max(worst_uncorrected, worst_error(f, reference)[0])
            ratio = [
                np.prod([beckmann_g1_exact(smith_argument(w, alpha)) / beckmann_g1_rational(smith_argument(w, alpha))
                         for w in pair])
                for pair in PAIRS
            ]
            reference = reference * np.array(ratio)[:, None]
        relative, absolute, large = worst_error(f, reference)
        compared, values = compared + large, values + reference.size
        worst_relative, worst_absolute = max(worst_relative, relative), max(worst_absolute, absolute)
    name = f"single vs roughconductor, {ndf}, {material} (eta {np.round(eta, 4)}, k {np.round(k, 4)})"
    report(name + ", relative", worst_relative, RELATIVE_TOLERANCE)
    report(name + f", absolute below {SMALL} 1/sr", worst_absolute, 1e-10)
    print(f"  {compared} of {values} values compared in relative terms")
    if ndf == "beckmann":
        print(f"  without the G1 correction: worst relative {worst_uncorrected:.3e} (Mitsuba's rational G1)")
    assert worst_relative < RELATIVE_TOLERANCE
    assert worst_absolute < 1e-10
    assert compared > values / 2

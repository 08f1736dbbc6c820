"""Same-run speed of `single` against Mitsuba 3's vectorised `roughconductor` (issue #15 item 4).

Not a test (pytest does not collect it): a report, run after `tests/crosscheck/setup.sh` with

    tests/crosscheck/.venv/bin/python tests/crosscheck/speed_vs_mitsuba.py

| figure | ours | Mitsuba 3 |
| --- | --- | --- |
| what is evaluated | `single`, GGX, height-correlated, copper conductor, alpha 0.3 | `roughconductor`, GGX, the same copper `eta`, `k` as RGB, alpha 0.3 (uncorrelated G2: the same work) |
| how | the kernel row of `bouncefit bench --no-jobs --quick` (65536 pairs, one thread): scalar reference and batch kernel | variant `llvm_ad_rgb`, `bsdf.eval` on `PAIRS` direction pairs in one call, Dr.Jit limited to one thread; the median of `REPEATS` calls after a warm-up call that compiles the kernel |
| unit | CPU ns per evaluation on one core | wall ns per evaluation on one thread |

Prints one table and the ratios (ours / Mitsuba: below 1 is faster). Both run on this machine in
this process's lifetime, so they share its load.

Dr.Jit 1.5 emits the `fmaximum` intrinsic, which LLVM 14 and 15 cannot compile ("Cannot select");
install Debian's `libllvm19` (`apt-get install libllvm19`). The script points Dr.Jit at the
newest `libLLVM-1[6-9]` it finds unless `DRJIT_LIBLLVM_PATH` is set.
"""

import glob
import json
import os
import statistics
import subprocess
import time

if "DRJIT_LIBLLVM_PATH" not in os.environ:
    found = sorted(glob.glob("/usr/lib/*/libLLVM-1[6-9].so*") + glob.glob("/usr/lib/*/libLLVM.so.1[6-9]*"))
    if found:
        os.environ["DRJIT_LIBLLVM_PATH"] = found[-1]

import drjit as dr  # noqa: E402 (after choosing the LLVM library)
import mitsuba as mi  # noqa: E402
import numpy as np  # noqa: E402

from conftest import ROOT  # noqa: E402

PAIRS = 1 << 20
REPEATS = 7
ALPHA = 0.3
COPPER = json.loads((ROOT / "datasets/copper-flash/material.json").read_text())["fresnel"]


def mitsuba_ns_per_eval():
    mi.set_variant("llvm_ad_rgb")
    dr.set_thread_count(1)
    bsdf = mi.load_dict({
        "type": "roughconductor",
        "distribution": "ggx",
        "alpha": ALPHA,
        "eta": {"type": "rgb", "value": COPPER["eta"]},
        "k": {"type": "rgb", "value": COPPER["k"]},
    })
    rng = np.random.default_rng(1)

    def upper(n):
        z = rng.uniform(0.05, 1.0, n)
        phi = rng.uniform(0.0, 2.0 * np.pi, n)
        r = np.sqrt(1.0 - z * z)
        return mi.Vector3f(r * np.cos(phi), r * np.sin(phi), z)

    si = dr.zeros(mi.SurfaceInteraction3f, PAIRS)
    si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
    si.wi = upper(PAIRS)
    wo = upper(PAIRS)
    context = mi.BSDFContext()
    times = []
    for repeat in range(REPEATS + 1):
        start = time.perf_counter()
        value = bsdf.eval(context, si, wo)
        dr.eval(value)
        dr.sync_thread()
        if repeat > 0:
            times.append(time.perf_counter() - start)
    return statistics.median(times) * 1e9 / PAIRS


def bouncefit_kernel():
    binary = os.environ.get("BOUNCEFIT_BIN", str(ROOT / "target/release/bouncefit"))
    out = subprocess.run(
        [binary, "bench", "--no-jobs", "--quick", "--models", "single", "--json", "--quiet"],
        check=True, capture_output=True, text=True, cwd=ROOT,
    ).stdout
    return json.loads(out)["kernel"]


def main():
    ours = bouncefit_kernel()
    theirs = mitsuba_ns_per_eval()
    rows = [
        ("bouncefit single, batch kernel (f64, SIMD)", ours["batch_ns_per_eval"]),
        ("bouncefit single, scalar reference (f64)", ours["scalar_ns_per_eval"]),
        ("Mitsuba 3 roughconductor, llvm_ad_rgb (f32, SIMD)", theirs),
    ]
    print(f"{'evaluation, one core':<52} {'ns/eval':>8} {'/ Mitsuba':>10}")
    for name, ns in rows:
        print(f"{name:<52} {ns:>8.2f} {ns / theirs:>10.2f}")


if __name__ == "__main__":
    main()

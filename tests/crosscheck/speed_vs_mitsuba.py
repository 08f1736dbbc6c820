"""Same-run speed of bouncefit against Mitsuba 3: evaluation and a whole fit (issue #15 item 4).

Not a test (pytest does not collect it): a report, run after `tests/crosscheck/setup.sh` and a
release build with

    tests/crosscheck/.venv/bin/python tests/crosscheck/speed_vs_mitsuba.py

(`BOUNCEFIT_BIN` names the binary when it is not `target/release/bouncefit`). Both sides run on
this machine in this process's lifetime, so they share its load.

Evaluation, one thread each:

| | ours | Mitsuba 3 |
| --- | --- | --- |
| what | `single`, GGX, height-correlated, copper conductor, alpha 0.3 | `roughconductor`, GGX, the same copper `eta`, `k` as RGB, alpha 0.3 (uncorrelated G2: the same work) |
| how | the kernel row of `bouncefit bench --no-jobs --quick` (65536 pairs): scalar reference and batch kernel, one pair to a pixel, and 4 pairs to a pixel as `fit` lays out its sub-samples (a quarter of the pixel sums and outputs) | variant `llvm_ad_rgb`, `bsdf.eval` on `PAIRS` direction pairs in one call; the median of `REPEATS` calls after a warm-up call that compiles the kernel |
| unit | CPU ns per evaluation | wall ns per evaluation |

Fit of `datasets/copper-flash` (9 flash photos, 128x128, rectified camera), `FIT_THREADS` threads
each (`RAYON_NUM_THREADS`, `dr.set_thread_count`), against the truth of `material.json`: alpha
within 1% and F0 (normal-incidence reflectance of its eta, k) within 0.01 in every channel.

- ours: `bouncefit fit datasets/copper-flash` (`single`, Schlick F0, its own start), the whole
  process, median of `FIT_RUNS` runs; alpha and F0 read from the fit file.
- Mitsuba 3: the scenes of `bouncefit export --format mitsuba --scene` (the truth with
  `height: uncorrelated`, Mitsuba's G2; a perspective sensor and a point light at the camera, the
  `direct` integrator), variant `llvm_ad_rgb`, differentiated through `mi.render`. Loss: the sum
  over the 9 photos of the mean squared difference to the set's own photos. Parameters: alpha and,
  per channel, F0 and eta of a conductor, with k = sqrt((F0 (eta+1)^2 - (eta-1)^2) / (1 - F0)), so
  that F0 is a parameter of its own (a Schlick-like reparameterisation of eta, k; eta alone is
  barely seen by these near-normal views). Neutral start `START` (alpha 0.5, F0 0.5, eta 1, so
  k 2). `mi.ad.Adam` with `BETAS`, learning rates `LEARNING_RATES` decayed by `DECAY` per
  iteration, `ITERATIONS` iterations at `SPP` samples per pixel, a new seed each iteration. The
  schedule was tuned on this set knowing the answer: with Adam's default betas (0.9, 0.999) the
  second moment remembers the first, large gradients and the loop stalls in the valley where
  alpha and F0 trade off. Timed: each iteration (9 renders, backward, step, evaluation of the
  parameters), summed; not timed: loading the scenes, `WARMUP` iterations that compile the
  kernels, and the check of the criterion after each iteration. The time to the criterion is the
  summed time up to the iteration from which every later iterate meets it.

Before fitting, Mitsuba renders each scene at the truth (`SANITY_SPP`) and the mean relative
difference to the set's photos is printed: the scenes must render the photos being fitted. Then
two tables with the ratios of bouncefit to Mitsuba 3 (below 1: bouncefit is faster), and the
machine's load average before and after. Fits report wall time and CPU time (user + system over
all threads: `getrusage` of the `bouncefit` child, `time.process_time` around each Mitsuba
iteration); on a machine shared with other work the CPU time moves less than the wall time.

Dr.Jit 1.5 emits the `fmaximum` intrinsic, which LLVM 14 and 15 cannot compile ("Cannot select");
install Debian's `libllvm19` (`apt-get install libllvm19`). The script points Dr.Jit at the
newest `libLLVM-1[6-9]` it finds unless `DRJIT_LIBLLVM_PATH` is set.
"""

import glob
import json
import os
import resource
import statistics
import subprocess
import tempfile
import time
from pathlib import Path

if "DRJIT_LIBLLVM_PATH" not in os.environ:
    found = sorted(glob.glob("/usr/lib/*/libLLVM-1[6-9].so*") + glob.glob("/usr/lib/*/libLLVM.so.1[6-9]*"))
    if found:
        os.environ["DRJIT_LIBLLVM_PATH"] = found[-1]

import drjit as dr  # noqa: E402 (after choosing the LLVM library)
import mitsuba as mi  # noqa: E402
import numpy as np  # noqa: E402

from conftest import ROOT, binary, exported_scenes, read_exr  # noqa: E402

PAIRS = 1 << 20
REPEATS = 7
ALPHA = 0.3
COPPER = json.loads((ROOT / "datasets/copper-flash/material.json").read_text())["fresnel"]

SET = "copper-flash"
FIT_THREADS = 2
FIT_RUNS = 5
SPP = 4
ITERATIONS = 80
WARMUP = 2
START = {"alpha": 0.5, "f0": 0.5, "eta": 1.0}
LEARNING_RATES = {"alpha": 0.05, "f0": 0.05, "eta": 0.01}
DECAY = 0.97
BETAS = (0.8, 0.9)
SANITY_SPP = 256
ALPHA_TOLERANCE = 0.01  # relative
F0_TOLERANCE = 0.01  # absolute, every channel


def normal_reflectance(eta, k):
    eta, k = np.asarray(eta, dtype=np.float64), np.asarray(k, dtype=np.float64)
    return ((eta - 1) ** 2 + k**2) / ((eta + 1) ** 2 + k**2)


def accurate(alpha, f0, truth_alpha, truth_f0):
    return abs(alpha - truth_alpha) <= ALPHA_TOLERANCE * truth_alpha and bool(
        np.all(np.abs(np.asarray(f0) - truth_f0) <= F0_TOLERANCE)
    )


def mitsuba_ns_per_eval():
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
    out = subprocess.run(
        [binary(), "bench", "--no-jobs", "--quick", "--models", "single", "--json", "--quiet"],
        check=True, capture_output=True, text=True, cwd=ROOT,
    ).stdout
    return json.loads(out)["kernel"]


def bouncefit_fit(folder, out):
    """`bouncefit fit` of the set, whole process, FIT_RUNS times: the median (wall, CPU) seconds,
    alpha and F0."""
    env = dict(os.environ, RAYON_NUM_THREADS=str(FIT_THREADS))
    walls, cpus = [], []
    for _ in range(FIT_RUNS):
        cpu = children_cpu()
        start = time.perf_counter()
        subprocess.run([binary(), "fit", folder, "-o", out, "--force", "--quiet"],
                       check=True, capture_output=True, cwd=ROOT, env=env)
        walls.append(time.perf_counter() - start)
        cpus.append(children_cpu() - cpu)
    fit = json.loads(Path(out).read_text())
    return (statistics.median(walls), statistics.median(cpus)), fit["alpha"][0], fit["f0"]


def children_cpu():
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


class MitsubaFit:
    """The 9 exported scenes in llvm_ad_rgb, sharing one alpha, F0 and eta."""

    KEYS = {"alpha": "fitted.alpha.value", "eta": "fitted.eta.value", "k": "fitted.k.value"}

    def __init__(self, scenes, folder):
        files = sorted(scenes.glob("*.xml"))
        self.scenes = [mi.load_file(str(f)) for f in files]
        self.params = [mi.traverse(s) for s in self.scenes]
        self.photos = [read_exr(folder / f"{f.stem}.exr") for f in files]
        self.targets = [mi.TensorXf(p.astype(np.float32)) for p in self.photos]

    def sanity(self):
        """Mean relative difference of Mitsuba's render at the truth to the photos, all pixels."""
        differences = []
        for seed, (scene, photo) in enumerate(zip(self.scenes, self.photos)):
            image = np.array(mi.render(scene, spp=SANITY_SPP, seed=seed), dtype=np.float64)
            lit = photo > 0
            differences.append(np.abs(image - photo)[lit] / photo[lit])
        return float(np.concatenate(differences).mean())

    @staticmethod
    def conductor(f0, eta):
        """The conductor's k of normal reflectance F0 and index eta."""
        k2 = (f0 * dr.square(eta + 1) - dr.square(eta - 1)) / (1 - f0)
        return dr.sqrt(dr.maximum(k2, 0.0))

    def run(self, iterations, truth_alpha, truth_f0):
        """Adam from the neutral start: summed (wall, CPU) seconds of the iterations, and per
        iteration ((wall, CPU) so far, alpha, F0, criterion met)."""
        opt = mi.ad.Adam(lr=1.0, beta_1=BETAS[0], beta_2=BETAS[1])
        opt["alpha"] = mi.Float(START["alpha"])
        opt["f0"] = mi.Color3f(START["f0"])
        opt["eta"] = mi.Color3f(START["eta"])
        wall, cpu, records = 0.0, 0.0, []
        for iteration in range(iterations):
            start, start_cpu = time.perf_counter(), time.process_time()
            for name, rate in LEARNING_RATES.items():
                opt.set_learning_rate({name: rate * DECAY**iteration})
            k = self.conductor(opt["f0"], opt["eta"])
            loss = mi.Float(0.0)
            for scene, params, target in zip(self.scenes, self.params, self.targets):
                params[self.KEYS["alpha"]] = opt["alpha"]
                params[self.KEYS["eta"]] = opt["eta"]
                params[self.KEYS["k"]] = k
                params.update()
                image = mi.render(scene, params, spp=SPP, seed=iteration)
                loss += dr.mean(dr.square(image - target), axis=None)
            dr.backward(loss)
            opt.step()
            opt["alpha"] = dr.clip(opt["alpha"], 0.02, 1.0)
            opt["eta"] = dr.clip(opt["eta"], 0.05, 10.0)
            opt["f0"] = dr.clip(opt["f0"], 0.02, 0.98)
            dr.eval(opt["alpha"], opt["f0"], opt["eta"])
            dr.sync_thread()
            wall += time.perf_counter() - start
            cpu += time.process_time() - start_cpu
            alpha = float(opt["alpha"].numpy()[0])
            f0 = np.array(opt["f0"], dtype=np.float64).ravel()
            records.append(((wall, cpu), alpha, f0, accurate(alpha, f0, truth_alpha, truth_f0)))
        return (wall, cpu), records


def time_to_criterion(records):
    """Summed (wall, CPU) time up to the iteration from which every later iterate meets the
    criterion."""
    reached = None
    for elapsed, _, _, ok in records:
        if ok and reached is None:
            reached = elapsed
        elif not ok:
            reached = None
    return reached


def main():
    mi.set_variant("llvm_ad_rgb")
    load_before = os.getloadavg()[0]
    ours_kernel = bouncefit_kernel()
    theirs_ns = mitsuba_ns_per_eval()

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        folder, material = exported_scenes(tmp, SET)
        truth_alpha = material["alpha"][0]
        truth_f0 = normal_reflectance(material["fresnel"]["eta"], material["fresnel"]["k"])
        fit_time, fit_alpha, fit_f0 = bouncefit_fit(folder, tmp / "fit.json")

        dr.set_thread_count(FIT_THREADS)
        mitsuba = MitsubaFit(tmp / "scenes", folder)
        sanity = mitsuba.sanity()
        mitsuba.run(WARMUP, truth_alpha, truth_f0)
        loop_time, records = mitsuba.run(ITERATIONS, truth_alpha, truth_f0)
    reached = time_to_criterion(records)
    _, last_alpha, last_f0, last_ok = records[-1]
    ours_ok = accurate(fit_alpha, fit_f0, truth_alpha, truth_f0)

    print(f"{os.cpu_count()} CPUs; 1-minute load average {load_before:.1f} before, {os.getloadavg()[0]:.1f} after")
    print(f"sanity: Mitsuba 3 render of the {SET} scenes at the truth ({SANITY_SPP} spp) vs the set's photos: "
          f"mean relative difference {sanity:.2e}")
    print(f"truth: alpha {truth_alpha}, F0 {np.round(truth_f0, 4).tolist()}")
    print(f"bouncefit fit: alpha {fit_alpha:.5f}, F0 {np.round(fit_f0, 4).tolist()}, within 1% / 0.01: {ours_ok}")
    print(f"Mitsuba 3 after {ITERATIONS} iterations: alpha {last_alpha:.5f}, F0 {np.round(last_f0, 4).tolist()}, "
          f"within 1% / 0.01: {last_ok}")
    print()
    evaluation = [
        ("bouncefit single, batch kernel (f32 lanes, SIMD; what fits use)", ours_kernel["batch_ns_per_eval"]),
        ("  the same, 4 pairs to a pixel (fit's layout)", ours_kernel["batch_fit_layout_ns_per_eval"]),
        ("bouncefit single, batch kernel (f64 lanes, SIMD)", ours_kernel["batch_f64_ns_per_eval"]),
        ("bouncefit single, scalar reference (f64)", ours_kernel["scalar_ns_per_eval"]),
        ("Mitsuba 3 roughconductor, llvm_ad_rgb (f32, SIMD)", theirs_ns),
    ]
    print(f"{'evaluation, one thread':<64} {'ns/eval':>8} {'/ Mitsuba':>10}")
    for name, ns in evaluation:
        print(f"{name:<64} {ns:>8.2f} {ns / theirs_ns:>10.3f}")
    print()
    fits = [
        (f"bouncefit fit, whole process (median of {FIT_RUNS})", fit_time),
        (f"Mitsuba 3 inverse rendering, {ITERATIONS} iterations at {SPP} spp", loop_time),
        ("Mitsuba 3 inverse rendering, up to alpha 1% and F0 0.01", reached),
    ]
    print(f"{f'fit of {SET}, {FIT_THREADS} threads':<60} {'wall s':>8} {'CPU s':>8} {'bouncefit / (wall, CPU)':>24}")
    for name, seconds in fits:
        if seconds is None:
            print(f"{name:<60} {'never':>8}")
        else:
            ratios = f"{fit_time[0] / seconds[0]:.3f}, {fit_time[1] / seconds[1]:.3f}"
            print(f"{name:<60} {seconds[0]:>8.3f} {seconds[1]:>8.3f} {ratios:>24}")

if __name__ == "__main__":
    main()

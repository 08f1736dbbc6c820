"""Fit many photo sets as independent tasks on a Dask cluster (a local one by default).

    python -m bouncefit.batch SETS... -o OUT [--models single] [--workers 2] [--scheduler ADDR]
        [-- FIT OPTIONS...]

Each SET is a photo set (a folder with ``capture.toml``, or a manifest) or a folder whose
subfolders are photo sets. Words after ``--`` are ``bouncefit fit`` options, passed unchanged
(``-- --fresnel conductor --maps --holdout-photo 8``). Each set is fitted by the same library
call as ``bouncefit fit SET`` (:func:`bouncefit.fit`), so its fit file holds the same numbers.

``OUT`` receives, each file written atomically (temporary file, then rename):

- ``fits/<set>.json``: the fit file (a maps fit: with ``fits/<set>.maps/``);
- ``rows/<set>.json``: the set's summary row, written last: a set with an ``ok`` row is
  skipped when the batch runs again, a failed one is fitted again;
- ``library/<set>.gltf`` and ``library/index.json``: the material library (glTF exports and
  an index of the fitted materials);
- ``summary.csv`` and ``summary.json``: set, status, model, alpha, F0, held-out error (the
  fit file's ``holdout``: fits with ``--holdout-photo N``, uniform or maps), time, error.

A set that fails is reported with its error (the command line's message) and does not stop the
others; the exit status is 1 when any set failed.
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Iterable, Optional, Sequence

COLUMNS = [
    "set",
    "status",
    "model",
    "alpha_x",
    "alpha_y",
    "f0_r",
    "f0_g",
    "f0_b",
    "heldout_error",
    "seconds",
    "error",
]


def find_sets(paths: Iterable[os.PathLike[str] | str]) -> list[Path]:
    """The photo sets ``paths`` name: a manifest or a folder holding ``capture.toml`` is one,
    another folder stands for its subfolders (sorted by name)."""
    sets: list[Path] = []
    for path in map(Path, paths):
        if path.is_file() or (path / "capture.toml").is_file():
            sets.append(path)
        elif path.is_dir():
            sets.extend(sorted(p for p in path.iterdir() if p.is_dir()))
        else:
            raise FileNotFoundError(f"{path}: no such photo set or folder")
    names = [set_name(s) for s in sets]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise ValueError(f"two photo sets share the name {', '.join(twice)}: fit them separately")
    return sets


def set_name(path: Path) -> str:
    """A set's name in the outputs: its folder's name (a manifest: the file's stem)."""
    return path.stem if path.is_file() else path.name


def write_text(path: Path, text: str) -> None:
    """Writes ``path`` atomically: a temporary file in the same folder, then a rename."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, temporary = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.replace(temporary, path)
    except BaseException:
        os.unlink(temporary)
        raise


def fit_set(path: str, out: str, argv: list[str]) -> dict[str, Any]:
    """One task: fits the set at ``path`` with ``bouncefit fit`` options ``argv``, writes its fit
    file, glTF export and row under ``out``, and returns the row (a failure is a row too)."""
    import bouncefit
    from bouncefit import _native

    name = set_name(Path(path))
    root = Path(out)
    fit_file = root / "fits" / f"{name}.json"
    row: dict[str, Any] = {c: None for c in COLUMNS}
    row["set"] = name
    start = time.perf_counter()
    try:
        fit_file.parent.mkdir(parents=True, exist_ok=True)
        raw = _native.fit(path, argv, None)
        if raw is None:
            raise bouncefit.BouncefitError("the MCMC run stopped early; its checkpoint is left")
        raw["output"].save(os.fspath(fit_file))
        data = json.loads(raw["json"])
        gltf = root / "library" / f"{name}.gltf"
        gltf.parent.mkdir(parents=True, exist_ok=True)
        bouncefit.export(fit_file, "gltf", gltf, force=True)
        f0 = data.get("f0") or [None] * 3
        row.update(
            status="ok",
            model=data["model"],
            alpha_x=data["alpha"][0],
            alpha_y=data["alpha"][1],
            f0_r=f0[0],
            f0_g=f0[1],
            f0_b=f0[2],
            heldout_error=(data.get("holdout") or {}).get("relative_error"),
        )
    except Exception as err:  # every failure is the set's row, not the batch's end
        row.update(status="failed", error=str(err))
    row["seconds"] = round(time.perf_counter() - start, 3)
    write_text(root / "rows" / f"{name}.json", json.dumps(row, indent=1))
    return row


def finished(out: Path, name: str) -> bool:
    """Whether an earlier run fitted this set (its row says ``ok``)."""
    try:
        row = json.loads((out / "rows" / f"{name}.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    return row.get("status") == "ok" and (out / "fits" / f"{name}.json").is_file()


def write_summary(out: Path, names: Sequence[str]) -> list[dict[str, Any]]:
    """``summary.csv``, ``summary.json`` and ``library/index.json`` from the rows of ``names``."""
    rows = [json.loads((out / "rows" / f"{n}.json").read_text(encoding="utf-8")) for n in names]
    write_text(out / "summary.json", json.dumps(rows, indent=1))
    table = io.StringIO()
    writer = csv.DictWriter(table, fieldnames=COLUMNS, lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    write_text(out / "summary.csv", table.getvalue())
    index = [
        {
            "set": r["set"],
            "model": r["model"],
            "alpha": [r["alpha_x"], r["alpha_y"]],
            "f0": [r["f0_r"], r["f0_g"], r["f0_b"]],
            "fit": f"../fits/{r['set']}.json",
            "gltf": f"{r['set']}.gltf",
        }
        for r in rows
        if r["status"] == "ok"
    ]
    write_text(out / "library" / "index.json", json.dumps({"materials": index}, indent=1))
    return rows


def run(
    sets: Sequence[os.PathLike[str] | str],
    out: os.PathLike[str] | str,
    argv: Sequence[str] = (),
    *,
    workers: int = 2,
    scheduler: Optional[str] = None,
    log=print,
) -> list[dict[str, Any]]:
    """Fits every photo set of ``sets`` (see :func:`find_sets`) with ``bouncefit fit`` options
    ``argv`` on a local Dask cluster of ``workers`` processes (or the cluster at ``scheduler``),
    skipping sets fitted by an earlier run; returns the summary rows, one per set."""
    from dask.distributed import Client, LocalCluster, as_completed

    out = Path(out)
    paths = find_sets(sets)
    names = [set_name(p) for p in paths]
    todo = [p for p in paths if not finished(out, set_name(p))]
    log(f"{len(paths)} photo sets, {len(paths) - len(todo)} already fitted")
    if todo:
        if scheduler is None:
            # Each worker's fits use its share of the cores (rayon threads), not all of them.
            threads = max(1, (os.cpu_count() or 1) // workers)
            cluster = LocalCluster(
                n_workers=workers,
                threads_per_worker=1,
                processes=True,
                dashboard_address=None,
                env={"RAYON_NUM_THREADS": str(threads)},
            )
        else:
            cluster = None
        with Client(cluster if cluster is not None else scheduler) as client:
            futures = [client.submit(fit_set, os.fspath(p), os.fspath(out), list(argv),
                                     key=f"fit-{set_name(p)}-{time.time_ns()}", pure=False)
                       for p in todo]
            for future in as_completed(futures):
                row = future.result()
                detail = row["error"] if row["status"] == "failed" else (
                    f"{row['model']} alpha {row['alpha_x']:.4f}")
                log(f"{row['set']}: {row['status']} ({row['seconds']:.1f} s): {detail}")
        if cluster is not None:
            cluster.close()
    return write_summary(out, names)


def main(args: Optional[Sequence[str]] = None) -> int:
    argv = list(sys.argv[1:] if args is None else args)
    fit_options: list[str] = []
    if "--" in argv:
        cut = argv.index("--")
        argv, fit_options = argv[:cut], argv[cut + 1 :]
    parser = argparse.ArgumentParser(
        prog="python -m bouncefit.batch",
        description="Fit photo sets as independent tasks on a Dask cluster; "
        "words after -- are `bouncefit fit` options.",
    )
    parser.add_argument("sets", nargs="+", help="photo sets, or folders of photo sets")
    parser.add_argument("-o", "--output", required=True, help="output folder")
    parser.add_argument("--models", default="single", help="models, comma-separated")
    parser.add_argument("--workers", type=int, default=2, help="local worker processes")
    parser.add_argument("--scheduler", help="address of a running Dask scheduler")
    options = parser.parse_args(argv)
    start = time.perf_counter()
    try:
        rows = run(
            options.sets,
            options.output,
            [f"--models={options.models}", *fit_options],
            workers=options.workers,
            scheduler=options.scheduler,
        )
    except (OSError, ValueError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    failed = [r for r in rows if r["status"] != "ok"]
    print(
        f"{len(rows) - len(failed)} fitted, {len(failed)} failed, "
        f"{time.perf_counter() - start:.1f} s; {Path(options.output) / 'summary.csv'}"
    )
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())

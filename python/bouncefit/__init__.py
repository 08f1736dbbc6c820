"""bouncefit in Python: fit microfacet materials (roughness, Fresnel, single- or multi-bounce
model, or material maps) to photos of flat samples.

Every function calls the library pipeline the ``bouncefit`` command line runs, so a fit here
gives the numbers ``bouncefit fit`` gives. Options are the command line's flags as keyword
arguments (``--pixel-samples 9`` is ``pixel_samples=9``, ``--anisotropic`` is
``anisotropic=True``, a list is comma-separated); docs/reference.md lists them.

    >>> import bouncefit
    >>> fit = bouncefit.fit("datasets/copper-flash", models=["single", "kulla-conty"])
    >>> fit.model, fit.alpha, fit.f0

A photo set is a folder or manifest on disk (:func:`load`), or arrays and the manifest's
geometry in memory (:meth:`PhotoSet.from_arrays`).
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterator, Mapping, Optional, Sequence, Union

import numpy as np

from . import _native
from .errors import BouncefitError, BouncefitWarning, FileError, InvalidInputError

__all__ = [
    "BouncefitError",
    "BouncefitWarning",
    "FileError",
    "InvalidInputError",
    "PhotoSet",
    "Fit",
    "TqdmProgress",
    "load",
    "fit",
    "render",
    "compare",
    "export",
    "command_line",
]
__version__: str = _native.VERSION

PathLike = Union[str, "os.PathLike[str]"]
Progress = Callable[[str, int, int, str], None]
"""``progress(stage, done, total, message)``: ``done`` of ``total`` steps of ``stage``."""
Table = Mapping[str, Any]
"""A table of the photo-set manifest (``capture.toml``) as a dict: ``{"kind": "point",
"position": [0, 0, 30], "intensity": [1000, 1000, 1000]}``; numpy values are accepted."""


@dataclass(frozen=True)
class PhotoSet:
    """A photo set as the fits see it: on disk (``capture.toml`` folder, manifest or
    MaterialGAN folder, :func:`load`) or in memory (:meth:`from_arrays`, ``path`` ``None``)."""

    path: Optional[str]
    name: str
    units: str
    sample: tuple[float, float]
    """Width and height of the sample, in ``units``."""
    depth: float
    photos: list[str]
    """The photos' image stems, in capture order."""
    images: list[np.ndarray] = field(repr=False)
    """Per photo, the linear image the fit sees, ``(height, width, 3)`` float64 (a non-finite
    pixel, which the fits leave out, as 0)."""
    _native: Any = field(default=None, repr=False, compare=False)
    """The photo set held in memory (:meth:`from_arrays`), else ``None``."""

    @classmethod
    def from_arrays(
        cls,
        images: Sequence[np.ndarray],
        *,
        lights: Union[Table, Sequence[Table]],
        sample: Union[Table, tuple[float, float]],
        camera: Optional[Table] = None,
        cameras: Optional[Sequence[Optional[Table]]] = None,
        exposures: Optional[Sequence[float]] = None,
        weights: Optional[Sequence[float]] = None,
        masks: Optional[Sequence[Optional[np.ndarray]]] = None,
        stems: Optional[Sequence[str]] = None,
        name: str = "arrays",
        units: str = "cm",
    ) -> "PhotoSet":
        """A photo set from linear images in memory and the geometry a ``capture.toml`` holds.

        ``images`` are ``(height, width, 3)`` linear RGB arrays (stored as float32, as the
        image loader stores EXR pixels). The other arguments are the manifest's fields
        (docs/files.md): ``lights`` one ``light`` table per image (or one for all),
        ``sample`` the ``[sample]`` table (``width``, ``height``, optional ``depth``) or
        ``(width, height)``, ``camera`` the ``[camera]`` table every photo starts from,
        ``cameras`` each photo's own ``camera`` table (``None``: none), ``exposures`` and
        ``weights`` each photo's ``exposure`` and ``weight``, ``masks`` per image an optional
        ``(height, width)`` array, false for pixels to leave out. A camera's ``resolution``
        defaults to its image's size; ``stems`` name the photos (default ``00``, ``01``, ...).

        The manifest reader checks them, so bad geometry raises
        :class:`InvalidInputError` with the command line's message, the field named as in
        the manifest (``arrays: photo[2].light.position: must be above the sample plane``);
        a non-finite or negative pixel is left out of fits with a warning, as in an EXR file.
        Unknown keys are warned of (:class:`BouncefitWarning`).
        """
        count = len(images)

        def per_photo(values: Any, what: str, one: bool = False) -> list[Any]:
            if values is None:
                return [None] * count
            if one and isinstance(values, Mapping):
                return [values] * count
            values = list(values)
            if len(values) != count:
                raise InvalidInputError(
                    f"{what}: {len(values)} given for {count} images; expected one per image"
                    + (" or one for all" if one else ""))
            return values

        arrays = []
        for i, image in enumerate(images):
            array = np.ascontiguousarray(image, dtype=np.float32)
            if array.ndim != 3 or array.shape[2] != 3:
                raise InvalidInputError(
                    f"images[{i}]: expected a (height, width, 3) array of linear RGB, "
                    f"got shape {array.shape}")
            arrays.append(array)
        keep = []
        for i, mask in enumerate(per_photo(masks, "masks")):
            mask = None if mask is None else np.ascontiguousarray(mask, dtype=bool)
            if mask is not None and mask.shape != arrays[i].shape[:2]:
                raise InvalidInputError(
                    f"masks[{i}]: shape {mask.shape} differs from images[{i}]'s "
                    f"{arrays[i].shape[:2]}")
            keep.append(mask)
        if not isinstance(sample, Mapping):
            width, height = sample
            sample = {"width": width, "height": height}
        photos = []
        for i, (light, own, exposure, weight, stem) in enumerate(zip(
                per_photo(lights, "lights", one=True), per_photo(cameras, "cameras"),
                per_photo(exposures, "exposures"), per_photo(weights, "weights"),
                per_photo(stems, "stems"))):
            own = dict(own or {})
            if "resolution" not in own and "resolution" not in (camera or {}):
                own["resolution"] = [arrays[i].shape[1], arrays[i].shape[0]]
            photos.append({"image": f"{i:02}" if stem is None else stem, "color": "linear",
                           "light": light, "exposure": exposure, "weight": weight,
                           "camera": own})
        manifest = {"name": name, "units": units, "sample": sample, "camera": camera,
                    "photo": photos}
        raw = _native.photo_set_from_arrays(name, json.dumps(_plain(manifest)), arrays, keep)
        for warning in raw.pop("warnings"):
            warnings.warn(warning, BouncefitWarning, stacklevel=2)
        return cls._of(raw)

    @classmethod
    def _of(cls, raw: dict[str, Any]) -> "PhotoSet":
        raw.pop("warnings", None)
        raw["sample"] = tuple(raw["sample"])
        raw["_native"] = raw.pop("native")
        return cls(**raw)


def _plain(value: Any) -> Any:
    """``value`` with numpy arrays and numbers as lists and Python numbers, and ``None``
    entries left out (a manifest has no null)."""
    if isinstance(value, Mapping):
        return {k: _plain(v) for k, v in value.items() if v is not None}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


@dataclass
class Fit:
    """A fit: the fit file the command line writes (``json``, ``data``) and its images."""

    json: str
    """The fit file's text, exactly as ``bouncefit fit`` writes it (a maps fit: without the
    ``maps`` entry naming image files, which :meth:`save` adds)."""
    photos: list[str]
    prediction: list[np.ndarray] = field(repr=False)
    """Per photo, the fitted material's render, ``(height, width, 3)``."""
    residuals: list[np.ndarray] = field(repr=False)
    """Per photo, prediction minus photo (zero where a pixel was left out)."""
    maps: Optional[dict[str, np.ndarray]] = field(repr=False)
    """A maps fit's texel maps (``diffuse``, ``specular``: ``(h, w, 3)``; ``roughness``:
    ``(h, w, 2)`` alpha_x, alpha_y; ``normal``), else ``None``."""
    _output: Any = field(repr=False)

    @property
    def data(self) -> dict[str, Any]:
        """The fit file as a dict."""
        return json.loads(self.json)

    @property
    def model(self) -> str:
        return str(self.data["model"])

    @property
    def alpha(self) -> tuple[float, float]:
        """Roughness ``(alpha_x, alpha_y)`` (a maps fit: its base material's)."""
        a = self.data["alpha"]
        return (a[0], a[1])

    @property
    def f0(self) -> Optional[tuple[float, float, float]]:
        """Reflectance at normal incidence of a uniform fit (``None`` for maps)."""
        f0 = self.data.get("f0")
        return None if f0 is None else (f0[0], f0[1], f0[2])

    def save(self, path: PathLike) -> None:
        """Write the fit file (and a maps fit's images beside it) as ``bouncefit fit -o PATH``
        does, atomically; an existing file is replaced."""
        self._output.save(os.fspath(path))


def _argv(options: Mapping[str, Any]) -> list[str]:
    """Keyword options as command-line words: ``True`` a bare flag, ``None``/``False`` left
    out, a list comma-separated, anything else ``--name=value``."""
    argv = []
    for name, value in options.items():
        flag = "--" + name.replace("_", "-")
        if value is None or value is False:
            continue
        if value is True:
            argv.append(flag)
        elif isinstance(value, (list, tuple)):
            argv.append(f"{flag}={','.join(str(v) for v in value)}")
        else:
            argv.append(f"{flag}={os.fspath(value) if isinstance(value, os.PathLike) else value}")
    return argv


def _path(photos: Union[PathLike, PhotoSet]) -> str:
    """The path of a photo set on disk; a set in memory is refused (the commands read files)."""
    if isinstance(photos, PhotoSet):
        if photos.path is None:
            raise InvalidInputError(
                f"{photos.name}: the photo set is held in memory; this runs the command line, "
                "which reads a photo set on disk")
        return photos.path
    return os.fspath(photos)


def _source(photos: Union[PathLike, PhotoSet]) -> tuple[str, Any]:
    """What the native functions open: a path, or a set in memory and the name it goes by."""
    if isinstance(photos, PhotoSet) and photos._native is not None:
        return photos.name, photos._native
    return _path(photos), None


def _progress(progress: Union[None, str, Progress]) -> Optional[Progress]:
    if progress == "tqdm":
        return TqdmProgress()
    if isinstance(progress, str):
        raise InvalidInputError(f"progress: `{progress}`; expected a callable or \"tqdm\"")
    return progress


class TqdmProgress:
    """A progress callback that shows a tqdm bar per stage (``fit(..., progress="tqdm")``)."""

    def __init__(self, **tqdm_options: Any) -> None:
        from tqdm.auto import tqdm  # optional: pip install tqdm

        self._tqdm = tqdm
        self._options = tqdm_options
        self._bars: dict[str, Any] = {}

    def __call__(self, stage: str, done: int, total: int, message: str) -> None:
        bar = self._bars.get(stage)
        if bar is None:
            bar = self._bars[stage] = self._tqdm(total=total, desc=stage, **self._options)
        bar.update(done - bar.n)
        if message:
            bar.set_postfix_str(message, refresh=False)
        if done >= total:
            bar.close()


def command_line(command: str, photos: Union[PathLike, PhotoSet], **options: Any) -> list[str]:
    """The ``bouncefit`` command line that does what ``command`` (``fit``, ``compare``) does here
    with these options (as a list of words)."""
    return ["bouncefit", command, _path(photos), *_argv(options)]


def load(path: PathLike, *, depth: Optional[float] = None) -> PhotoSet:
    """Open a photo set; ``depth`` replaces the manifest's ``[sample] depth`` (``--depth``)."""
    return PhotoSet._of(_native.load_photo_set(os.fspath(path), depth))


def fit(
    photos: Union[PathLike, PhotoSet],
    models: Union[str, Sequence[str]] = "single",
    *,
    maps: bool = False,
    output: Optional[PathLike] = None,
    force: bool = False,
    progress: Union[None, str, Progress] = None,
    **options: Any,
) -> Optional[Fit]:
    """Fit ``models`` to a photo set, uniform or (``maps=True``) material maps.

    ``options`` are ``bouncefit fit``'s flags (``optimizer``, ``fresnel``, ``anisotropic``,
    ``diffuse``, ``pixel_samples``, ``seed``, ``mcmc``, ``texels``, ``holdout_photo``, ...).
    With ``output`` the fit file is written there too (refused over an existing file unless
    ``force``). The fit runs with the GIL released; ``progress(stage, done, total, message)``
    is called (with the GIL) as it goes: per iteration of each model's search (stage
    ``"fit MODEL"``, message the loss), per stage of a maps fit (``"maps fit"``, and
    ``"maps WxH"`` with texels), per MCMC iteration (``"mcmc"``), and per finished model
    (``"fitted"``, the line ``bouncefit fit`` prints); ``done`` never decreases within a
    stage and equals ``total`` when it ends. An exception raised in ``progress`` stops the
    fit and is raised by ``fit``. ``progress="tqdm"`` shows tqdm bars (:class:`TqdmProgress`).
    The command line's warnings are issued as :class:`BouncefitWarning`. Returns ``None``
    only when an MCMC run stopped early (``mcmc_stop_after``) and left its checkpoint.
    """
    argv = _argv({"models": models, "maps": maps, "output": output, "force": force, **options})
    path, native = _source(photos)
    raw = _native.fit(path, argv, _progress(progress), native)
    if raw is None:
        return None
    return Fit(
        json=raw["json"],
        photos=raw["photos"],
        prediction=raw["prediction"],
        residuals=raw["residuals"],
        maps=raw["maps"],
        _output=raw["output"],
    )


def render(
    photos: Union[PathLike, PhotoSet],
    material: Union[PathLike, Fit],
    *,
    pixel_samples: int = 4,
    seed: int = 0,
    depth: Optional[float] = None,
) -> list[np.ndarray]:
    """Render every photo of a photo set with a :class:`Fit`, a material or a fit file (uniform
    or maps; a fit's fitted exposure applied), as ``bouncefit render``: per photo a linear ``(h, w, 3)`` array."""
    path, native = _source(photos)
    with _material_file(material) as material_path:
        return _native.render(path, material_path, pixel_samples, seed, depth, native)


def compare(
    photos: Union[PathLike, PhotoSet],
    models: Sequence[str],
    output: PathLike,
    *,
    holdout: Union[None, bool, int, str] = None,
    force: bool = False,
    **options: Any,
) -> dict[str, Any]:
    """``bouncefit compare``: fit each model, rank them (BIC, held-out error with ``holdout=K``
    or ``holdout=True`` for leave-one-out) and write the report folder ``output``; returns its
    ``report.json``."""
    path, native = _source(photos)
    argv = [path, *_argv({"models": models, "holdout": holdout, "output": output,
                          "force": force, "quiet": True, **options})]
    _native.compare(argv, native)
    with open(Path(output) / "report.json", encoding="utf-8") as f:
        return json.load(f)


def export(
    material: Union[PathLike, Fit],
    format: str,
    output: PathLike,
    *,
    scene: Optional[PathLike] = None,
    force: bool = False,
) -> Path:
    """``bouncefit export``: write a fit (a :class:`Fit`, or a fit or material file) as
    ``json``, ``mitsuba``, ``gltf`` or ``materialx`` (maps: with their textures beside it);
    returns ``output``."""
    with _material_file(material) as path:
        argv = [path, *_argv({"format": format, "output": output, "scene": scene,
                              "force": force})]
        _native.export(argv)
    return Path(output)


@contextlib.contextmanager
def _material_file(material: Union[PathLike, Fit]) -> Iterator[str]:
    """The path of a material or fit file: ``material`` itself, or a :class:`Fit` saved (with
    its maps) into a temporary folder that is removed afterwards."""
    if not isinstance(material, Fit):
        yield os.fspath(material)
        return
    with tempfile.TemporaryDirectory(prefix="bouncefit-") as folder:
        path = os.path.join(folder, "fit.json")
        material.save(path)
        yield path

"""bouncefit in Python: fit microfacet materials (roughness, Fresnel, single- or multi-bounce
model, or material maps) to photos of flat samples.

Every function calls the library pipeline the ``bouncefit`` command line runs, so a fit here
gives the numbers ``bouncefit fit`` gives. Options are the command line's flags as keyword
arguments (``--pixel-samples 9`` is ``pixel_samples=9``, ``--anisotropic`` is
``anisotropic=True``, a list is comma-separated); docs/reference.md lists them.

    >>> import bouncefit
    >>> fit = bouncefit.fit("datasets/copper-flash", models=["single", "kulla-conty"])
    >>> fit.model, fit.alpha, fit.f0
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping, Optional, Sequence, Union

import numpy as np

from . import _native
from .errors import BouncefitError, FileError, InvalidInputError

__all__ = [
    "BouncefitError",
    "FileError",
    "InvalidInputError",
    "PhotoSet",
    "Fit",
    "load",
    "fit",
    "render",
    "compare",
    "export",
    "command_line",
]
__version__: str = _native.VERSION

PathLike = Union[str, "os.PathLike[str]"]
Progress = Callable[[str, str], None]


@dataclass(frozen=True)
class PhotoSet:
    """A photo set (``capture.toml`` folder, manifest or MaterialGAN folder) as the fits see it."""

    path: str
    name: str
    units: str
    sample: tuple[float, float]
    """Width and height of the sample, in ``units``."""
    depth: float
    photos: list[str]
    """The photos' image stems, in capture order."""
    images: list[np.ndarray] = field(repr=False)
    """Per photo, the linear image the fit sees, ``(height, width, 3)`` float64."""


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
    return photos.path if isinstance(photos, PhotoSet) else os.fspath(photos)


def command_line(command: str, photos: Union[PathLike, PhotoSet], **options: Any) -> list[str]:
    """The ``bouncefit`` command line that does what ``command`` (``fit``, ``compare``) does here
    with these options (as a list of words)."""
    return ["bouncefit", command, _path(photos), *_argv(options)]


def load(path: PathLike, *, depth: Optional[float] = None) -> PhotoSet:
    """Open a photo set; ``depth`` replaces the manifest's ``[sample] depth`` (``--depth``)."""
    raw = _native.load_photo_set(os.fspath(path), depth)
    raw["sample"] = tuple(raw["sample"])
    return PhotoSet(**raw)


def fit(
    photos: Union[PathLike, PhotoSet],
    models: Union[str, Sequence[str]] = "single",
    *,
    maps: bool = False,
    output: Optional[PathLike] = None,
    force: bool = False,
    progress: Optional[Progress] = None,
    **options: Any,
) -> Optional[Fit]:
    """Fit ``models`` to a photo set, uniform or (``maps=True``) material maps.

    ``options`` are ``bouncefit fit``'s flags (``optimizer``, ``fresnel``, ``anisotropic``,
    ``diffuse``, ``pixel_samples``, ``seed``, ``mcmc``, ``texels``, ``holdout_photo``, ...).
    With ``output`` the fit file is written there too (refused over an existing file unless
    ``force``). ``progress(stage, message)`` is called with ``"warning"`` messages and a line per
    finished fit (``"fitted"``); the fit runs with the GIL released. Returns ``None`` only when
    an MCMC run stopped early (``mcmc_stop_after``) and left its checkpoint.
    """
    argv = _argv({"models": models, "maps": maps, "output": output, "force": force, **options})
    raw = _native.fit(_path(photos), argv, progress)
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
    material: PathLike,
    *,
    pixel_samples: int = 4,
    seed: int = 0,
    depth: Optional[float] = None,
) -> list[np.ndarray]:
    """Render every photo of a photo set with a material or fit file (uniform or maps; a fit's
    fitted exposure applied), as ``bouncefit render``: per photo a linear ``(h, w, 3)`` array."""
    return _native.render(_path(photos), os.fspath(material), pixel_samples, seed, depth)


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
    argv = [_path(photos), *_argv({"models": models, "holdout": holdout, "output": output,
                                   "force": force, "quiet": True, **options})]
    _native.compare(argv)
    with open(Path(output) / "report.json", encoding="utf-8") as f:
        return json.load(f)


def export(
    material: PathLike,
    format: str,
    output: PathLike,
    *,
    scene: Optional[PathLike] = None,
    force: bool = False,
) -> Path:
    """``bouncefit export``: write a fit or material file as ``json``, ``mitsuba``, ``gltf`` or
    ``materialx`` (maps: with their textures beside it); returns ``output``."""
    argv = [os.fspath(material), *_argv({"format": format, "output": output, "scene": scene,
                                         "force": force})]
    _native.export(argv)
    return Path(output)

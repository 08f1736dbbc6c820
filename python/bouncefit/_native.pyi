"""Type hints of the compiled module (python/src/lib.rs); use the ``bouncefit`` package."""

from typing import Any, Callable, Optional

import numpy as np

VERSION: str

class FitOutput:
    def save(self, path: str) -> None: ...

class Photos:
    """A photo set held in memory."""

def load_photo_set(path: str, depth: Optional[float] = None) -> dict[str, Any]: ...
def photo_set_from_arrays(
    source: str,
    manifest: str,
    images: list[np.ndarray],
    masks: list[Optional[np.ndarray]],
) -> dict[str, Any]: ...
def fit(
    path: str,
    argv: list[str],
    progress: Optional[Callable[[str, int, int, str], None]] = None,
    photos: Optional[Photos] = None,
) -> Optional[dict[str, Any]]: ...
def render(
    capture: str,
    material: str,
    pixel_samples: int = 4,
    seed: int = 0,
    depth: Optional[float] = None,
    photos: Optional[Photos] = None,
) -> list[np.ndarray]: ...
def compare(argv: list[str], photos: Optional[Photos] = None) -> None: ...
def export(argv: list[str]) -> None: ...

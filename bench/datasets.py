"""The height fields of the quality benchmark (bench_quality.py): real ones that ship inside packages
installed here, and the dissertation's synthetic sets.  Nothing is downloaded at run time.

Each grid is an (H, W) float64 array, row 0 first as stored (north for the DEMs), no-data filled.
Sources and licences: bench/README.md ("Data sets").
"""

from __future__ import annotations

import gzip
import importlib.metadata
from dataclasses import dataclass
from pathlib import Path

import numpy as np


@dataclass(frozen=True)
class Grid:
    name: str
    kind: str  # "terrain", "disparity", "intensity", "synthetic"
    source: str  # where it comes from (package and file)
    units: str
    values: np.ndarray  # (H, W) float64

    @property
    def shape(self) -> tuple[int, int]:
        return self.values.shape

    @property
    def height_range(self) -> float:
        return float(self.values.max() - self.values.min())


def package_file(dist: str, rel: str) -> Path:
    """A file shipped inside an installed distribution, found without importing the package."""
    try:
        files = importlib.metadata.files(dist) or []
    except importlib.metadata.PackageNotFoundError:
        raise FileNotFoundError(f"{dist} is not installed (make bench installs bench/requirements-data.txt)"
                                ) from None
    for f in files:
        if str(f).replace("\\", "/") == rel:
            return Path(f.locate())
    raise FileNotFoundError(f"{rel} is not in {dist}")


def _mpl(name: str) -> Path:
    import matplotlib.cbook as cbook

    return Path(cbook.get_sample_data(name, asfileobj=False))


def jacksboro() -> np.ndarray:
    return np.load(_mpl("jacksboro_fault_dem.npz"))["elevation"].astype(np.float64)


def topobathy() -> np.ndarray:
    return np.load(_mpl("topobathy.npz"))["topo"].astype(np.float64)


def mri() -> np.ndarray:
    with gzip.open(_mpl("s1045.ima.gz")) as f:  # as matplotlib's image demo reads it
        return np.frombuffer(f.read(), np.uint16).reshape(256, 256).astype(np.float64)


def lidar_dem() -> np.ndarray:
    import logging

    import tifffile

    # tifffile warns that the GDAL_NODATA tag (-3.4e38) does not fit float32; the file has no no-data
    logging.getLogger("tifffile").setLevel(logging.ERROR)
    return tifffile.imread(package_file("lidar", "lidar/data/dem.tif")).astype(np.float64)


def motorcycle() -> np.ndarray:
    """Middlebury 2014 Motorcycle ground-truth disparity (skimage's copy); unknown pixels (inf) filled
    with the nearest known disparity (wavemesh's --fill nearest)."""
    from wavemesh.io.heightfield import fill_nearest

    d = np.load(package_file("scikit-image", "skimage/data/motorcycle_disp.npz"))["arr_0"].astype(np.float64)
    bad = ~np.isfinite(d)
    return fill_nearest(d, bad) if bad.any() else d


def moon() -> np.ndarray:
    from PIL import Image

    with Image.open(package_file("scikit-image", "skimage/data/moon.png")) as im:
        return np.asarray(im, dtype=np.float64)


def _synth(name: str):
    def make() -> np.ndarray:
        from wavemesh.io.synth import make as synth

        return synth(name).astype(np.float64)

    return make


# name -> (kind, source, units, loader); sizes are the files' own, whole (no crop, no decimation)
SETS = {
    "jacksboro": ("terrain", "matplotlib: mpl-data/sample_data/jacksboro_fault_dem.npz ('elevation')", "m",
                  jacksboro),
    "topobathy": ("terrain", "matplotlib: mpl-data/sample_data/topobathy.npz ('topo')", "m", topobathy),
    "lidar_dem": ("terrain", "lidar (PyPI): lidar/data/dem.tif", "m", lidar_dem),
    "motorcycle": ("disparity", "scikit-image: skimage/data/motorcycle_disp.npz", "px", motorcycle),
    "mri": ("intensity", "matplotlib: mpl-data/sample_data/s1045.ima.gz", "grey level", mri),
    "moon": ("intensity", "scikit-image: skimage/data/moon.png", "grey level", moon),
    **{n: ("synthetic", f"wavemesh synth {n}", "unit", _synth(n)) for n in ("f1", "f2", "f3", "f4", "f5",
                                                                            "ball", "box")},
}


def load(name: str) -> Grid:
    kind, source, units, loader = SETS[name]
    return Grid(name, kind, source, units, np.ascontiguousarray(loader(), dtype=np.float64))


def terrain(n: int, extent: float = 1.0, seed: int = 20261122, modes: int = 400, fmax: float = 48.0,
            beta: float = 2.0, rows: slice | None = None) -> np.ndarray:
    """A seeded synthetic terrain, one continuous surface, sampled n x n over [0, extent]^2 (heights about
    0..1000 "m" on the unit square).  extent 1 at every n: the same area sampled finer; extent
    (n - 1) / 255: the same sample spacing over a larger area.  A sum of `modes` plane waves with random
    directions and phases, spatial frequencies 1..fmax cycles across the square, amplitude ~ f^-beta/2
    (a fractal-like spectrum, power ~ f^-beta), evaluated separably (cos(a + b) expanded) as two matrix
    products.  The scale (0..1000) is fixed from the 256 x 256 sampling so every size has the same heights
    at the same points.  ``rows``: only those rows (n columns), so that a large grid can be written strip by
    strip (bench/bench_tiles.py)."""
    rng = np.random.default_rng(seed)
    f = np.exp(rng.uniform(0.0, np.log(fmax), modes))  # log-uniform in 1..fmax
    th = rng.uniform(0.0, 2 * np.pi, modes)
    ph = rng.uniform(0.0, 2 * np.pi, modes)
    amp = f ** (-beta / 2)
    fx, fy = f * np.cos(th), f * np.sin(th)

    def sample(m: int, ext: float, r: slice = slice(None)) -> np.ndarray:
        t = np.linspace(0.0, ext, m)
        ax = 2 * np.pi * np.outer(fx, t)  # (modes, m): columns
        ay = 2 * np.pi * np.outer(fy, t[r]) + ph[:, None]  # rows
        # sum_k amp_k cos(ax_k + ay_k) = sum_k amp_k (cos ay cos ax - sin ay sin ax)
        return (np.cos(ay).T * amp) @ np.cos(ax) - (np.sin(ay).T * amp) @ np.sin(ax)

    ref = sample(256, 1.0)
    lo, hi = float(ref.min()), float(ref.max())
    return (sample(n, extent, rows if rows is not None else slice(None)) - lo) * (1000.0 / (hi - lo))

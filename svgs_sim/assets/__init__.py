"""Package data: the SVGS app's settings (``app/``), camera profiles and their fitted overlays
(``cameras/``), labs (``labs/``), materials (``materials/``), target patterns (``patterns/``) as
TOML, and the papers' tables (``data/``, read by :mod:`svgs_sim.assets.papers`).

The files are found with :mod:`importlib.resources`, wherever the package is installed.
"""

from importlib.resources import files
from pathlib import Path

#: The folder of the package data (a real folder: the package is installed unzipped).
ASSETS_DIR = Path(str(files(__name__)))


def package_relative(path) -> str:
    """A data file's name relative to the ``svgs_sim`` package (``assets/cameras/galaxy-nexus.toml``),
    never an absolute path of this machine; the file's own name when it lies outside the package.

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    str
    """
    try:
        return str(Path(path).resolve().relative_to(ASSETS_DIR.parent))
    except (ValueError, OSError, TypeError):
        return Path(str(path)).name if path else ""

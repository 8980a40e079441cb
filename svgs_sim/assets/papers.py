"""The two seeds' published result tables - one home, one reader.

- ``data/svgs_2014_results.csv``: Becker, Howard & Rakoczy (2014), Tables 2-5 - mean error
  and standard deviation of each state component per phone and range.
- ``data/tof_2022_stability.csv``: Zhu et al. (2022), Tables 1-3 - the ToF sensor's
  stability runs at 697 mm and 5712 mm.

Lines starting with ``#`` are comments (the source of each table).
"""

from __future__ import annotations

import csv

from . import ASSETS_DIR

DATA_DIR = ASSETS_DIR / "data"
SVGS_2014_CSV = DATA_DIR / "svgs_2014_results.csv"
TOF_2022_CSV = DATA_DIR / "tof_2022_stability.csv"

#: Columns of the SVGS table that identify a row (the rest are state components, m and deg).
SVGS_ROW_KEYS = ("phone", "statistic", "range_m")


def read_table(path) -> list[dict]:
    """Rows of a comment-headed CSV table as dicts of strings.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    list of dict
        One dict per data row, keyed by the header's column names.
    """
    with open(path, newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(line for line in fh if not line.startswith("#")))


def svgs_2014_results(path=SVGS_2014_CSV) -> dict:
    """The SVGS paper's Tables 2-5.

    Returns
    -------
    dict
        ``{(phone, statistic, range_m): {component: value}}``; ``statistic`` is
        ``"mean_error"`` or ``"std"``, components are the file's other columns
        (``x_m ... yaw_deg``, the paper's state: :data:`svgs_sim.svgs.frames.STATE_KEYS`).
    """
    return {(r["phone"], r["statistic"], float(r["range_m"])): {k: float(v) for k, v in r.items() if k not in SVGS_ROW_KEYS}
            for r in read_table(path)}


def svgs_2014_rows(phone: str, statistic: str, path=SVGS_2014_CSV) -> list[dict]:
    """Rows of Tables 2-5 for one phone and statistic, by increasing range.

    Returns
    -------
    list of dict
        ``{"phone", "statistic", "range_m", <component>: value}`` with floats for the numbers.
    """
    rows = [{**{k: r[k] for k in ("phone", "statistic")}, "range_m": rng, **vals}
            for (ph, st, rng), vals in svgs_2014_results(path).items()
            for r in [{"phone": ph, "statistic": st}] if ph == phone and st == statistic]
    return sorted(rows, key=lambda r: r["range_m"])


def tof_2022_stability(path=TOF_2022_CSV) -> list[dict]:
    """Rows of the ToF paper's stability Tables 1-3 (strings, as in the file)."""
    return read_table(path)

"""Progress bar with an ETA on stderr (tqdm), or nothing."""

from __future__ import annotations

import contextlib
import sys


class _NoBar:
    def update(self, n: int = 1) -> None:
        pass


@contextlib.contextmanager
def progress_bar(total: int, description: str, enabled: bool = True, unit: str = "trial"):
    """A tqdm bar over ``total`` trials on stderr (rate and ETA); a no-op when disabled.

    Yields
    ------
    object with ``update(n)``
    """
    if not enabled or total <= 0:
        yield _NoBar()
        return
    from tqdm import tqdm

    bar = tqdm(total=total, desc=description, unit=unit, file=sys.stderr, mininterval=0.5, smoothing=0.1,
               dynamic_ncols=True)
    try:
        yield bar
    finally:
        bar.close()

"""Per-trial random streams that do not depend on the executor, the worker count or the order
in which trials run.

Every trial ``i`` of a study seeded with ``seed`` gets its own stream: the child ``i`` of
``numpy.random.SeedSequence(seed)``, i.e. ``SeedSequence(seed).spawn(n)[i]``, computed
directly from the index (``SeedSequence(seed, spawn_key=(i,))`` is the same object) so that
a study of a million trials does not spawn a million children up front. From that child:

- :func:`trial_seed` - the integer handed to ``run_trial(scenario, seed)`` (noise draws
  inside the trial: ``np.random.default_rng(seed)``);
- :func:`design_rng` - a generator for drawing the trial's *scenario* (e.g. the gimbal
  angles of a campaign trial), independent of the trial's own noise stream.

A rerun, a resumed run or a run on a cluster therefore draws exactly the same numbers for
trial ``i``.
"""

from __future__ import annotations

import numpy as np

from svgs_sim.base.errors import InputError
from svgs_sim.base.limits import MAX_SEED

#: Spawn-key suffixes of the two streams under a trial's SeedSequence child.
_TRIAL_STREAM, _DESIGN_STREAM = 0, 1


def check_seed(seed) -> int:
    """A study seed: an integer from 0 to :data:`svgs_sim.base.limits.MAX_SEED` (``InputError`` otherwise),
    the bound ``--seed`` takes."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or not 0 <= int(seed) <= MAX_SEED:
        raise InputError(f"seed: expected an integer from 0 to {MAX_SEED}, got {seed!r}")
    return int(seed)


def trial_sequence(seed: int, index: int) -> np.random.SeedSequence:
    """The SeedSequence of trial ``index``: ``SeedSequence(seed).spawn(index + 1)[index]``.

    Parameters
    ----------
    seed : int
        Study seed (non-negative).
    index : int
        Trial index (non-negative).
    """
    if isinstance(index, bool) or not isinstance(index, (int, np.integer)) or int(index) < 0:
        raise InputError(f"trial index: expected a non-negative integer, got {index!r}")
    return np.random.SeedSequence(check_seed(seed), spawn_key=(int(index),))


def trial_seed(seed: int, index: int) -> int:
    """The integer seed passed to ``run_trial(scenario, seed)`` for trial ``index``.

    Returns
    -------
    int
        A 63-bit non-negative integer (fits a signed 64-bit CSV/Parquet column).
    """
    ss = trial_sequence(seed, index).spawn(2)[_TRIAL_STREAM]
    return int(ss.generate_state(1, np.uint64)[0] >> np.uint64(1))


def design_rng(seed: int, index: int) -> np.random.Generator:
    """Generator for drawing trial ``index``'s scenario (independent of its noise stream)."""
    return np.random.default_rng(trial_sequence(seed, index).spawn(2)[_DESIGN_STREAM])


def study_rng(seed: int, stream: int) -> np.random.Generator:
    """A study-level generator (e.g. a calibration error drawn once per campaign).

    ``stream`` numbers these study-level draws; they never collide with trial streams
    (their spawn key has two elements ``(2**32 + stream, 0)``).
    """
    return np.random.default_rng(np.random.SeedSequence(check_seed(seed), spawn_key=(2**32 + int(stream), 0)))

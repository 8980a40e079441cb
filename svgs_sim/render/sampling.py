"""The samples-per-pixel rule and the one exit from Dr.Jit to numpy.

Samples per pixel
    Mitsuba's ``ldsampler`` (the SVGS and board renderers) renders a square power of two
    samples per pixel, at least 4 (it rounds 1 or 2 up to 4, 8 up to 16: checked with
    Mitsuba 3.6), so :func:`check_spp` rounds up to a power of four, at least 4, and the
    number recorded in the truth is the number rendered. The ToF renderer's own
    integrator (:mod:`svgs_sim.render.tof.camera`: an R2 sequence reduced with ``dr.block_sum``)
    needs only a power of two (``base=2``, at least 1).

Dr.Jit -> numpy
    :func:`to_numpy` is where every Dr.Jit array or tensor a renderer made becomes a numpy
    array (a copy, evaluated); :func:`film_to_numpy` is the same for a rendered film
    (channels averaged to one radiance value per pixel), and :func:`render_film` the one
    call of ``mi.render``. Renderers return numpy only.

Ctrl-C inside a render
    Mitsuba's ``mi.render`` runs its integrator inside ``dr.custom``, which turns any
    exception raised there into ``RuntimeError("drjit.custom(...): error while performing a
    custom differentiable operation")`` with the original as its cause. A Ctrl-C that lands in
    that Python frame would so end the command as an error (exit 1) instead of an interrupt
    (exit 130, rows kept): :func:`render_film` raises the ``KeyboardInterrupt`` itself.
"""

from __future__ import annotations

import numpy as np

from svgs_sim.base.errors import InputError, interrupt_in


def round_up_power(n: int, base: int = 4, minimum: int = 4) -> int:
    """Smallest ``base**k >= max(n, minimum)`` (``minimum`` itself a power of ``base``).

    Parameters
    ----------
    n : int
    base : int
        4 for ``ldsampler`` (square powers of two), 2 for the ToF integrator.
    minimum : int
        The smallest count returned (4 for ``ldsampler``, 1 for the ToF integrator).
    """
    k = int(minimum)
    while k < int(n):
        k *= int(base)
    return k


def check_spp(v, name: str = "spp", *, allow_zero: bool = False, base: int = 4) -> int:
    """A validated sample count, rounded up by :func:`round_up_power` (0 stays 0 when allowed).

    Parameters
    ----------
    v : int
        Samples per pixel (or per strategy) asked for.
    name : str
        The input's name, for the :class:`InputError` message.
    allow_zero : bool
        Accept 0 (e.g. "no background pass").
    base : {4, 2}
        4: ``ldsampler`` (power of four, at least 4); 2: the ToF integrator (power of two,
        at least 1).

    Raises
    ------
    InputError
        Not an integer, negative, or 0 when not allowed.
    """
    try:
        iv = int(v)
    except (TypeError, ValueError):
        raise InputError(f"{name}: expected a positive integer, got {v!r}") from None
    if iv != v or iv < (0 if allow_zero else 1):
        raise InputError(f"{name}: expected a {'non-negative' if allow_zero else 'positive'} integer, got {v!r}")
    if iv == 0:
        return 0
    return round_up_power(iv, base, 4 if base == 4 else 1)


def to_numpy(value, dtype=np.float64) -> np.ndarray:
    """A Dr.Jit array or tensor (or anything array-like) as a numpy array of ``dtype``.

    Parameters
    ----------
    value : drjit array, mitsuba.TensorXf, or array_like
    dtype : numpy dtype
        float64 by default (accumulation is done in double precision).

    Returns
    -------
    ndarray
        Same shape as ``value`` (flat for a 1-D Dr.Jit array).
    """
    return np.asarray(value, dtype=dtype)


def render_film(mi, scene, sensor, spp: int, seed: int) -> np.ndarray:
    """``mi.render(scene, sensor=sensor, spp=spp, seed=seed)`` as radiance per pixel.

    Parameters
    ----------
    mi : module
        The ``mitsuba`` module with its variant set.
    scene, sensor
        Mitsuba objects.
    spp : int
        Samples per pixel of this pass.
    seed : int
        The pass's sampler seed (uint32).

    Returns
    -------
    ndarray of float64, shape (h, w)
        As :func:`film_to_numpy`.

    Raises
    ------
    KeyboardInterrupt
        Ctrl-C (or SIGTERM's :class:`svgs_sim.cli.signals.Terminated`) during the render, also
        where Dr.Jit wrapped it in a ``RuntimeError``.
    """
    try:
        return film_to_numpy(mi.render(scene, sensor=sensor, spp=int(spp), seed=int(seed)))
    except RuntimeError as exc:
        interrupt = interrupt_in(exc)
        if interrupt is None:
            raise
        raise interrupt from None


def film_to_numpy(image) -> np.ndarray:
    """A rendered film (``mi.render`` output, shape (h, w) or (h, w, c)) as radiance per pixel.

    Returns
    -------
    ndarray of float64, shape (h, w)
        The channels' mean where the film has several (RGB variants), else the film.
    """
    a = to_numpy(image, np.float64)
    return a.mean(axis=2) if a.ndim == 3 else a

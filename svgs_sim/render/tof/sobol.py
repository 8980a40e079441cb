"""Owen-scrambled Sobol' points per pixel for the ToF integrator (Dr.Jit, with a numpy twin).

Why
    A marker of the ToF target spans a few pixels at range and the lens blurs it over more
    than a pixel, so a pixel's value is an integral over the film position (2D) and the
    aperture point (2D) whose integrand jumps at the marker's rim; near the camera the
    retroreflector's return also varies with the emitter chosen and the point on its disk
    (the observation angle). Drawing these seven dimensions from one Owen-scrambled Sobol'
    sequence per pixel stratifies them jointly (issue 23: the aperture drawn independently of
    the film was the dominant render noise at 5.7 m, the emitter choice at 0.7 m); the
    estimate stays unbiased (each point is uniform in the unit cube) and independent between
    pixels and seeds.

Construction (Burley 2020, "Practical Hash-based Owen Scrambling", JCGT 9(4))
    The sample index is shuffled by a nested uniform scramble (bit reversal, the Laine-Karras
    hash, bit reversal), then dimension ``d`` of the Sobol' point with that index is
    Owen-scrambled with the hash of ``seed`` and ``d``. Direction numbers: Joe and Kuo (2008),
    ``new-joe-kuo-6.21201``, dimensions 2-8 (dimension 1 is van der Corput); unscrambled, the
    points equal ``scipy.stats.qmc.Sobol(scramble=False)`` (which lists them in Gray-code
    order; checked in the tests). The first ``2**k`` indices of a seed are a scrambled
    ``(t, k, s)``-net however a render splits them into passes (the box's ``spp`` samples, then
    the rim pixels' further samples, continue one sequence).
"""

from __future__ import annotations

import numpy as np

#: Joe & Kuo new-joe-kuo-6.21201, dimensions 2..8: (degree s, coefficients a, initial m_1..m_s).
JOE_KUO = ((1, 0, (1,)), (2, 1, (1, 3)), (3, 1, (1, 3, 1)), (3, 2, (1, 1, 1)), (4, 1, (1, 1, 3, 3)),
           (4, 4, (1, 3, 5, 13)), (5, 2, (1, 1, 5, 5, 17)))
#: Dimensions available.
MAX_DIMS = len(JOE_KUO) + 1
#: Laine-Karras hash constants (Burley 2020, listing 1).
_LK = (0x6C50B47C, 0xB82F1E52, 0xC7AFE638, 0x8D22F6E6)
_M32 = 0xFFFFFFFF


def direction_numbers(n_dims: int = MAX_DIMS) -> np.ndarray:
    """Sobol' direction numbers as 0.32 fixed point.

    Parameters
    ----------
    n_dims : int
        1 .. :data:`MAX_DIMS`.

    Returns
    -------
    ndarray of uint32, shape (n_dims, 32)
        ``V[d, b]``: XOR it in when bit ``b`` of the index is set.
    """
    if not 1 <= int(n_dims) <= MAX_DIMS:
        raise ValueError(f"n_dims: expected 1..{MAX_DIMS}, got {n_dims!r}")
    V = np.zeros((int(n_dims), 32), np.uint64)
    V[0] = [1 << (31 - b) for b in range(32)]
    for d in range(1, int(n_dims)):
        s, a, m = JOE_KUO[d - 1]
        v = [m[i] << (31 - i) for i in range(s)] + [0] * (32 - s)
        for i in range(s, 32):
            x = v[i - s] ^ (v[i - s] >> s)
            for k in range(1, s):
                if (a >> (s - 1 - k)) & 1:
                    x ^= v[i - k]
            v[i] = x
        V[d] = v
    return V.astype(np.uint32)


_V = direction_numbers()


# ---------------------------------------------------------------------- numpy twin (tests, reference)
def _np_brev(x):
    x = np.asarray(x, np.uint64) & _M32
    out = np.zeros_like(x)
    for b in range(32):
        out |= ((x >> np.uint64(b)) & np.uint64(1)) << np.uint64(31 - b)
    return out


def _np_lk(x, s):
    x = (x + s) & _M32
    for c in _LK:
        x = (x ^ (x * np.uint64(c))) & _M32
    return x


def _np_nus(x, s):
    return _np_brev(_np_lk(_np_brev(x), s))


def _np_hash_combine(s, v):
    return (s ^ ((np.uint64(v) + (s << np.uint64(6)) + (s >> np.uint64(2))) & _M32)) & _M32


def sobol_owen_numpy(index, seed, dims) -> np.ndarray:
    """The points of :func:`sobol_owen` with numpy (reference for the tests).

    Parameters
    ----------
    index : array_like of int, shape (n,)
        Sample indices, ``0 <= index < 2**32``.
    seed : array_like of int, shape (n,) or scalar
        Scramble seeds (uint32).
    dims : sequence of int
        Dimensions, each in ``0 .. MAX_DIMS - 1``.

    Returns
    -------
    ndarray of float64, shape (n, len(dims))
        Points in [0, 1), each a multiple of ``2**-24`` (as the float32 ones of :func:`sobol_owen`).
    """
    j = np.asarray(index, np.uint64).ravel()
    s = np.broadcast_to(np.asarray(seed, np.uint64), j.shape) & _M32
    jj = _np_nus(j, s)
    out = np.empty((j.size, len(dims)))
    for c, d in enumerate(dims):
        x = np.zeros_like(jj)
        for b in range(32):
            x ^= np.where((jj >> np.uint64(b)) & np.uint64(1), np.uint64(_V[d, b]), np.uint64(0))
        x = _np_nus(x, _np_hash_combine(s, d))
        out[:, c] = (x >> np.uint64(8)).astype(np.float64) * 2.0**-24
    return out


# ---------------------------------------------------------------------- Dr.Jit
def _lk(x, s):
    x = x + s
    for c in _LK:
        x ^= x * c
    return x


def sobol_owen(mi, dr, index, seed, dims) -> list:
    """Owen-scrambled Sobol' points (Dr.Jit, one lane per sample).

    Parameters
    ----------
    mi, dr : modules
        ``mitsuba`` (a JIT variant set) and ``drjit``.
    index : mi.UInt32
        Sample index of each lane within its sequence (the pixel's sample number).
    seed : mi.UInt32
        Scramble seed of each lane's sequence (e.g. a hash of the pixel and the render seed).
    dims : sequence of int
        Dimensions, each in ``0 .. MAX_DIMS - 1``.

    Returns
    -------
    list of mi.Float
        One coordinate per entry of ``dims``, in [0, 1) (24-bit).
    """
    UInt32, Float = mi.UInt32, mi.Float
    jj = dr.brev(_lk(dr.brev(index), seed))
    out = []
    for d in dims:
        x = UInt32(0)
        for b in range(32):
            x ^= (UInt32(0) - ((jj >> b) & 1)) & int(_V[d, b])
        s_d = seed ^ (UInt32(int(d)) + (seed << 6) + (seed >> 2))
        x = dr.brev(_lk(dr.brev(x), s_d))
        out.append(Float(x >> 8) * (2.0**-24))
    return out


__all__ = ["JOE_KUO", "MAX_DIMS", "direction_numbers", "sobol_owen", "sobol_owen_numpy"]

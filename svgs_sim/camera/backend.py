"""Array backend of the camera model's heavy stages: the CPU (numpy, scipy, OpenCV; the
default) or a GPU through CuPy, behind one API.

The stages that go through it are the convolutions of the optics: the diffuse light with the
pixel-integrated PSF (:meth:`svgs_sim.camera.phone.psf.CorePSF.convolve`), the points' spectra on their
sub-pixel grids (:func:`svgs_sim.camera.phone.psf.splat_patches`) and the glare wings on their coarse
grid (:func:`svgs_sim.camera.phone.optics.wings`). Each takes and returns numpy arrays; a GPU backend moves
its inputs to the device and its results back, so the rest of the camera model does not change.
The sensor's noise draws stay on the CPU on every backend (their counter-based generator is
what makes a seed give the same numbers everywhere).

Backends (:data:`BACKENDS`, chosen by :func:`get_backend`, the ``SVGS_ARRAY_BACKEND``
environment variable or ``PhoneCamera(..., backend=)``):

- ``"cpu"``: OpenCV's ``filter2D`` for the diffuse light, scipy's pocketfft for the spectra.
- ``"cupy"``: the same convolutions by FFT in CuPy on the first GPU. When CuPy or a GPU is
  missing, the CPU backend is used and :func:`get_backend` says so once (a warning), never an
  abort.
- ``"numpy-fft"``: the GPU backend's code (FFT convolutions through the array module) run with
  numpy on the CPU, so that the path a GPU takes is tested on machines without one
  (``tests/test_array_backend.py``).
"""

from __future__ import annotations

import functools
import os
import warnings

import numpy as np

#: Backends of :func:`get_backend`.
BACKENDS = ("cpu", "cupy", "numpy-fft")
#: Environment variable naming the default backend.
ENV_BACKEND = "SVGS_ARRAY_BACKEND"


class Backend:
    """One array backend: ``xp`` (the array module), ``fft`` (its FFT module) and the
    convolutions of the camera model, numpy in and out.

    Attributes
    ----------
    name : str
        One of :data:`BACKENDS` (the one actually used).
    requested : str
        What was asked for.
    notice : str or None
        Why the requested backend is not the one used.
    """

    def __init__(self, name: str, xp, fft, *, requested: str | None = None, notice: str | None = None):
        self.name = name
        self.xp = xp
        self.fft = fft
        self.requested = requested or name
        self.notice = notice

    def __repr__(self) -> str:
        return f"Backend({self.name!r})"

    # ------------------------------------------------------------------ transfers
    def to_device(self, a):
        return a if self.xp is np else self.xp.asarray(a)

    def to_host(self, a) -> np.ndarray:
        return a if isinstance(a, np.ndarray) else self.xp.asnumpy(a)

    # ------------------------------------------------------------------ stages
    def filter_same(self, image: np.ndarray, kernel: np.ndarray) -> np.ndarray:
        """``image`` (H, W) correlated with an odd-sized ``kernel`` centred on its middle, zero
        outside the image (OpenCV's ``filter2D`` with ``BORDER_CONSTANT``): float32 (H, W)."""
        image = np.ascontiguousarray(image, np.float32)
        kernel = np.ascontiguousarray(kernel, np.float32)
        if self.name == "cpu":
            import cv2

            return cv2.filter2D(image, -1, kernel, borderType=cv2.BORDER_CONSTANT)
        xp, fft = self.xp, self.fft
        H, W = image.shape
        kh, kw = kernel.shape
        shape = (H + kh - 1, W + kw - 1)
        fs = (_fast_len(shape[0]), _fast_len(shape[1]))
        a = self.to_device(image.astype(np.float64))
        k = self.to_device(kernel[::-1, ::-1].astype(np.float64))  # correlation = convolution with the flip
        full = fft.irfft2(fft.rfft2(a, fs) * fft.rfft2(k, fs), fs)
        out = full[kh // 2:kh // 2 + H, kw // 2:kw // 2 + W]
        return self.to_host(out).astype(np.float32)

    def fft_convolve_full(self, a: np.ndarray, k: np.ndarray) -> np.ndarray:
        """Full 2-D linear convolution of ``a`` and ``k`` (float64, shape ``a + k - 1``)."""
        if self.name == "cpu":
            from scipy.signal import fftconvolve

            return fftconvolve(a, k, mode="full")
        fft = self.fft
        shape = (a.shape[0] + k.shape[0] - 1, a.shape[1] + k.shape[1] - 1)
        fs = (_fast_len(shape[0]), _fast_len(shape[1]))
        out = fft.irfft2(fft.rfft2(self.to_device(a), fs) * fft.rfft2(self.to_device(k), fs), fs)
        return self.to_host(out[:shape[0], :shape[1]])

    def fft_convolve_same(self, a: np.ndarray, k: np.ndarray) -> np.ndarray:
        """``scipy.signal.fftconvolve(a, k, mode="same")`` on this backend (float64)."""
        if self.name == "cpu":
            from scipy.signal import fftconvolve

            return fftconvolve(a, k, mode="same")
        full = self.fft_convolve_full(a, k)
        y0 = (k.shape[0] - 1) // 2
        x0 = (k.shape[1] - 1) // 2
        return np.ascontiguousarray(full[y0:y0 + a.shape[0], x0:x0 + a.shape[1]])


def _fast_len(n: int) -> int:
    import scipy.fft

    return scipy.fft.next_fast_len(int(n), real=True)


@functools.lru_cache(maxsize=None)
def _cpu() -> Backend:
    import scipy.fft

    return Backend("cpu", np, scipy.fft)


@functools.lru_cache(maxsize=None)
def _numpy_fft() -> Backend:
    return Backend("numpy-fft", np, np.fft)


@functools.lru_cache(maxsize=None)
def _cupy() -> Backend:
    try:
        import cupy
        import cupy.fft

        n = cupy.cuda.runtime.getDeviceCount()
        if n < 1:
            raise RuntimeError("no CUDA device")
        cupy.zeros(1).sum()  # initialise the device now, not in the middle of a frame
    except Exception as exc:  # noqa: BLE001 - any failure to start CuPy means: stay on the CPU
        notice = (f"array backend 'cupy' is not available ({type(exc).__name__}: {exc}); "
                  "the camera model runs on the CPU")
        warnings.warn(notice, RuntimeWarning, stacklevel=3)
        b = _cpu()
        return Backend(b.name, b.xp, b.fft, requested="cupy", notice=notice)
    return Backend("cupy", cupy, cupy.fft)


def get_backend(name: str | None = None) -> Backend:
    """The array backend ``name`` (default: ``$SVGS_ARRAY_BACKEND``, else ``"cpu"``).

    Raises
    ------
    ValueError
        An unknown name.
    """
    if isinstance(name, Backend):
        return name
    if name is None:
        name = os.environ.get(ENV_BACKEND, "").strip() or "cpu"
    name = str(name).strip().lower()
    if name not in BACKENDS:
        raise ValueError(f"array backend: expected one of {BACKENDS}, got {name!r} "
                         f"(argument or ${ENV_BACKEND})")
    return {"cpu": _cpu, "cupy": _cupy, "numpy-fft": _numpy_fft}[name]()

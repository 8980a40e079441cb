"""The SVGS app's settings and the consistency test of a solution.

The settings are the app's own (``assets/app/svgs-app.toml``), not the camera's: the
"specified brightness threshold value" of Becker, Howard & Rakoczy (2014) on the 8-bit image
the app received, the centroid rule, and the consistency test. Every command, study and
:func:`svgs_sim.svgs.pipeline.solve_image` takes them as their defaults.

Consistency
    A solution's whitened reprojection residual (:attr:`svgs_sim.svgs.solver.Solution.residual_rms_px`,
    ``sqrt(sum r^2 / n)`` over ``n`` targets) is compared with the centroid noise it should have:
    ``chi2 = n r_rms^2 / sigma^2`` with ``2n - 6`` degrees of freedom, ``sigma^2 = sigma_px^2 +
    sigma_sensor^2`` (the app's stated centroid accuracy and, where the caller knows it, the
    sensor's own Cramer-Rao bound). Below ``p = alpha`` the solution is ``inconsistent``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..base.errors import InputError, ProfileError, check_finite_positive
from ..base.profiles import cached, read_toml
from ..assets import ASSETS_DIR

#: The app's settings file.
APP_FILE = ASSETS_DIR / "app" / "svgs-app.toml"

#: Centroid rules of :func:`svgs_sim.svgs.detect.detect_blobs` (``"component"`` is kept as another name of
#: ``"weighted"``).
CENTROIDS = ("weighted", "binary", "window")


@dataclass(frozen=True)
class AppSettings:
    """The SVGS app's settings.

    Attributes
    ----------
    threshold_dn : float
        Default brightness threshold on an 8-bit image, DN (pixels strictly above are foreground).
    threshold_by_camera : dict
        Camera profile name -> threshold, DN (each phone's test set-up).
    threshold_range_dn : tuple of float
        Plausible range, DN.
    centroid : str
        Default centroid rule, one of :data:`CENTROIDS`.
    sigma_px : float
        The app's stated centroid accuracy, px (1-sigma per axis).
    alpha : float
        Consistency test level: a solution with ``p < alpha`` is ``inconsistent``.
    """

    threshold_dn: float
    threshold_by_camera: dict
    threshold_range_dn: tuple
    centroid: str
    sigma_px: float
    alpha: float

    def threshold_for(self, camera_key: str | None) -> float:
        """The app's threshold for a camera's test set-up, DN, by the camera profile's ``key``
        (:attr:`svgs_sim.base.profiles.Camera.key`); the default for a camera without one or
        one the settings do not list."""
        return float(self.threshold_by_camera.get(str(camera_key), self.threshold_dn))

    def threshold_source(self, camera_key: str | None) -> str:
        """Where :meth:`threshold_for` took its value: ``"by_camera[KEY]"`` or ``"default"``."""
        return f"by_camera[{camera_key}]" if camera_key in self.threshold_by_camera else "default"


def settings() -> AppSettings:
    """The app's settings from :data:`APP_FILE` (read once: the profiles' cache,
    :func:`svgs_sim.base.profiles.cached`).

    Raises
    ------
    InputError
        The file is missing or a value is out of range.
    """
    return cached("app", (str(APP_FILE),), (APP_FILE,), _read_settings)


def _read_settings() -> AppSettings:
    try:
        d = read_toml(APP_FILE, "app settings")
    except ProfileError as exc:
        raise InputError(f"app settings {APP_FILE.name}: cannot be read ({exc})") from None
    th, ce, co = d.get("threshold", {}), d.get("centroid", {}), d.get("consistency", {})
    try:
        s = AppSettings(float(th["default_dn"]), {k: float(v) for k, v in th.get("by_camera", {}).items()},
                        tuple(float(x) for x in th["range_dn"]), str(ce["default"]), float(co["sigma_px"]),
                        float(co["alpha"]))
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"app settings {APP_FILE.name}: missing or bad value ({exc!r}); needs threshold.default_dn, "
                         "threshold.range_dn, centroid.default, consistency.sigma_px and consistency.alpha") from None
    if len(s.threshold_range_dn) != 2 or not s.threshold_range_dn[0] < s.threshold_range_dn[1]:
        raise InputError(f"app settings {APP_FILE.name}: threshold.range_dn must be [low, high], got "
                         f"{list(s.threshold_range_dn)}")
    lo, hi = s.threshold_range_dn
    if s.centroid not in CENTROIDS:
        raise InputError(f"app settings {APP_FILE.name}: centroid.default must be one of {CENTROIDS}, got {s.centroid!r}")
    if not (s.sigma_px > 0 and 0 < s.alpha < 1):
        raise InputError(f"app settings {APP_FILE.name}: need sigma_px > 0 and 0 < alpha < 1")
    for nm, v in (("default_dn", s.threshold_dn), *s.threshold_by_camera.items()):
        if not lo <= v <= hi:
            raise InputError(f"app settings {APP_FILE.name}: threshold {nm} = {v} is outside its plausible range "
                             f"{lo:g}-{hi:g}")
    return s


@dataclass(frozen=True)
class Consistency:
    """The consistency statistic of a solution.

    Attributes
    ----------
    chi2 : float
        ``n r_rms^2 / sigma^2``.
    dof : int
        ``2n - 6``.
    p_value : float
        ``P(chi2_dof >= chi2)``: the probability of a residual at least this large from centroid
        noise of ``sigma_px`` alone.
    sigma_px : float
        The centroid noise tested against, px.
    alpha : float
        The test level.
    """

    chi2: float
    dof: int
    p_value: float
    sigma_px: float
    alpha: float

    @property
    def consistent(self) -> bool:
        """``p_value >= alpha`` (always True with no degree of freedom)."""
        return self.dof <= 0 or self.p_value >= self.alpha

    def to_json(self) -> dict:
        """The statistic as JSON fields (``chi2``, ``dof``, ``p_value``, ``consistency_sigma_px``,
        ``alpha``, ``consistent``)."""
        return {"chi2": float(self.chi2), "dof": int(self.dof), "p_value": float(self.p_value),
                "consistency_sigma_px": float(self.sigma_px), "alpha": float(self.alpha),
                "consistent": bool(self.consistent)}


def consistency(residual_rms_px: float, n_points: int, *, sigma_px: float | None = None,
                sensor_sigma_px: float | None = None, alpha: float | None = None) -> Consistency:
    """The chi-square consistency of a solution's residual.

    Parameters
    ----------
    residual_rms_px : float
        ``sqrt(sum of squared whitened residuals / n_points)``, px.
    n_points : int
        Targets in the solve (``2 n_points`` measurements, 6 unknowns).
    sigma_px : float, optional
        Stated centroid noise, px (default: the app's, :func:`settings`).
    sensor_sigma_px : float, optional
        The sensor's own centroid bound (the simulated sensor's CRLB), px, added in quadrature.
    alpha : float, optional
        Test level (default: the app's).

    Returns
    -------
    Consistency
    """
    from scipy.special import gammaincc

    app = settings()
    s = app.sigma_px if sigma_px is None else check_finite_positive(sigma_px, "consistency sigma_px")
    if sensor_sigma_px is not None and math.isfinite(float(sensor_sigma_px)):
        s = math.hypot(s, float(sensor_sigma_px))
    a = app.alpha if alpha is None else float(alpha)
    dof = 2 * int(n_points) - 6
    chi2 = int(n_points) * float(residual_rms_px) ** 2 / (s * s)
    p = float(gammaincc(dof / 2.0, chi2 / 2.0)) if dof > 0 else 1.0
    return Consistency(chi2, dof, p, s, a)


__all__ = ["AppSettings", "settings", "Consistency", "consistency", "CENTROIDS", "APP_FILE"]

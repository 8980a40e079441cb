"""Retroreflective sheeting as a Mitsuba BSDF, from its coefficient of retroreflection R_A.

The markers of the ToF target are made of "special reflective materials" whose return is far
above the background (Zhu et al. 2022, section 3; its reference [3] used retroreflectors).
Retroreflective sheeting is specified by its **coefficient of retroreflection**
(CIE 54.2, ASTM E808 / E810)::

    R_A(alpha, beta) = I / (E_perp A)        cd lx^-1 m^-2

``I`` the intensity returned towards the observer, ``E_perp`` the illuminance on a plane
perpendicular to the incident light at the sheet, ``A`` the sheet's area; ``alpha`` the
**observation angle** (between the illumination axis and the observation axis, seen from
the sheet) and ``beta`` the **entrance angle** (between the illumination axis and the sheet's
normal). For a spectrally flat return the photometric ratio equals the radiometric one, so
``R_A`` in cd/lx/m^2 is also W sr^-1 per (W m^-2 m^2), i.e. sr^-1 (ASSUMPTION at 850 nm:
the retroreflection of glass beads and cube-corner prisms is geometric, the white pigment
behind glass beads reflects well in the near infrared; no published R_A at 850 nm was found).

Radiometry
    The radiance the observer sees is ``L = I / (A cos theta_v) = R_A E_perp / cos theta_v``
    (``theta_v`` the angle of the observation direction from the normal), so the BRDF is
    ``f_r = L / (E_perp cos beta) = R_A / (cos theta_v cos beta)`` and Mitsuba's ``eval``
    (which returns ``f_r cos theta_o``, ``theta_o`` the light direction's angle) returns
    ``R_A(alpha, beta) / cos theta_v``. The sheet's diffuse (daytime) reflectance adds a
    Lambertian term ``rho_d / pi cos theta_o``.

Tables
    ``assets/materials/retroreflective-sheeting.toml``: R_A of white sheeting at tabulated
    observation and entrance angles, each with its source. Between nodes ``log R_A`` is
    linear in ``log alpha`` (a power law, the form of the tails of measured curves) and in
    ``beta``; below the first observation angle R_A is constant; beyond the last tabulated
    angle it continues on the last segment (ASSUMPTION: the ToF emitters sit 16 mm from the
    lens, so alpha runs from 0.16 deg at 5.7 m to 1.3 deg at 0.7 m, past the last node of some
    tables); beyond the last entrance angle R_A also falls linearly to 0 at 90 deg.

Sampling
    ``sample`` draws the cosine-weighted hemisphere with the diffuse weight only: the
    retroreflective lobe (a cone of about a degree around the incident direction) carries
    light back towards where it came from, so it matters for the emitter next to the lens
    (evaluated, never sampled, by :mod:`svgs_sim.render.tof.camera`) and not for the ambient or
    multipath estimates, which it would change by its hemispherical albedo (under 0.25).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from svgs_sim.assets import ASSETS_DIR
from svgs_sim.base.errors import InputError, ProfileError
from svgs_sim.base.profiles import cached, read_toml

SHEETING_FILE = ASSETS_DIR / "materials" / "retroreflective-sheeting.toml"
#: Name of the Mitsuba plugin registered by :func:`register_bsdf`.
PLUGIN = "retroreflective_sheeting"


def piecewise_log_linear(x, nodes, log_values, where):
    """Piecewise-linear interpolation of ``log_values`` over ``nodes``: constant below the first
    node, the last segment's slope beyond the last. Works on numpy arrays (``where=np.where``)
    and on Dr.Jit arrays (``where=dr.select``); ``log_values`` may be arrays of the same kind."""
    xs = [float(v) for v in nodes]
    ys = list(log_values)
    if len(xs) == 1:
        return ys[0] + 0.0 * x
    s = [(ys[k + 1] - ys[k]) / (xs[k + 1] - xs[k]) for k in range(len(xs) - 1)]
    y = ys[-2] + (x - xs[-2]) * s[-1]
    for k in range(len(xs) - 3, -1, -1):
        y = where(x < xs[k + 1], ys[k] + (x - xs[k]) * s[k], y)
    return where(x < xs[0], ys[0] + 0.0 * x, y)


@dataclass(frozen=True)
class SheetingTable:
    """R_A of one retroreflective sheeting (white).

    Attributes
    ----------
    name : str
    kind : str
        ``"glass-bead"`` or ``"microprismatic"``.
    standard : str
    observation_deg : ndarray, shape (n,)
    entrance_deg : ndarray, shape (m,)
        Magnitudes (the standards' -4 deg is 4 deg here: the sign names the sense of the tilt).
    ra_cd_lx_m2 : ndarray, shape (n, m)
    diffuse_albedo : float
        Lambertian (daytime) reflectance of the sheet.
    source : str
    note : str
    """

    name: str
    kind: str
    standard: str
    observation_deg: np.ndarray
    entrance_deg: np.ndarray
    ra_cd_lx_m2: np.ndarray
    diffuse_albedo: float
    source: str
    note: str = ""

    def ra(self, observation_deg, entrance_deg) -> np.ndarray:
        """R_A at the angles (numpy; shapes broadcast), cd/lx/m^2 (= sr^-1)."""
        a = np.abs(np.asarray(observation_deg, float))
        b = np.abs(np.asarray(entrance_deg, float))
        return _ra(a, b, self, np.where, np.log, np.exp)

    def to_json(self) -> dict:
        return {"name": self.name, "kind": self.kind, "standard": self.standard,
                "observation_deg": self.observation_deg.tolist(), "entrance_deg": self.entrance_deg.tolist(),
                "ra_cd_lx_m2": self.ra_cd_lx_m2.tolist(), "diffuse_albedo": self.diffuse_albedo,
                "source": self.source, "note": self.note}


def _ra(alpha_deg, beta_deg, tab: SheetingTable, where, log, exp):
    """R_A with numpy or Dr.Jit (``where``, ``log``, ``exp`` of that library)."""
    L = np.log(tab.ra_cd_lx_m2)
    la = log(where(alpha_deg > 1e-6, alpha_deg, 1e-6 + 0.0 * alpha_deg))  # log-log in alpha: a power law between nodes
    cols = [piecewise_log_linear(la, np.log(tab.observation_deg), [float(v) for v in L[:, j]], where)
            for j in range(L.shape[1])]
    logr = piecewise_log_linear(beta_deg, tab.entrance_deg, cols, where) if len(cols) > 1 else cols[0]
    r = exp(logr)
    b_last = float(tab.entrance_deg[-1])
    fall = where(beta_deg > b_last, (90.0 - beta_deg) / (90.0 - b_last), 1.0 + 0.0 * beta_deg)
    return r * where(fall > 0.0, fall, 0.0 * fall)


def _tables(path: str) -> dict:
    """The sheeting tables of the file ``path`` by name (read once: the profiles' cache)."""
    return cached("sheeting", (str(path),), (Path(path),), lambda: _read_tables(Path(path)))


def _read_tables(p: Path) -> dict:
    raw = read_toml(p, "sheeting table")
    out = {}
    for i, t in enumerate(raw.get("sheeting", [])):
        where = f"{p.name} [[sheeting]] {i} ({t.get('name', '?')})"
        try:
            obs = np.asarray(t["observation_deg"], float)
            ent = np.abs(np.asarray(t["entrance_deg"], float))
            ra = np.asarray(t["ra_cd_lx_m2"], float).reshape(obs.size, ent.size)
            tab = SheetingTable(name=str(t["name"]), kind=str(t["kind"]), standard=str(t["standard"]),
                                observation_deg=obs, entrance_deg=ent, ra_cd_lx_m2=ra,
                                diffuse_albedo=float(t["diffuse_albedo"]), source=str(t["source"]),
                                note=str(t.get("note", "")))
        except (KeyError, TypeError, ValueError) as exc:
            raise ProfileError(f"{where}: {exc}") from None
        if not (np.all(np.diff(obs) > 0) and np.all(np.diff(ent) > 0) and np.all(ra > 0) and 0 <= tab.diffuse_albedo <= 1):
            raise ProfileError(f"{where}: expected increasing angles, positive R_A and a diffuse albedo in [0, 1]")
        out[tab.name] = tab
    return out


def sheeting_names(path=SHEETING_FILE) -> list[str]:
    return list(_tables(str(path)))


def load_sheeting(name: str, path=SHEETING_FILE) -> SheetingTable:
    """The sheeting table called ``name``.

    Raises
    ------
    InputError
        Unknown name (the message lists the known ones).
    """
    tabs = _tables(str(path))
    if name not in tabs:
        raise InputError(f"sheeting {name!r}: unknown; known {sorted(tabs)}")
    return tabs[name]


def register_bsdf() -> None:
    """Register :data:`PLUGIN` with Mitsuba (idempotent; needs a variant set)."""
    import mitsuba as mi

    key = (PLUGIN, mi.variant())
    if key in _REGISTERED:
        return
    mi.register_bsdf(PLUGIN, lambda props: _make_bsdf_class()(props))
    _REGISTERED.add(key)


_REGISTERED: set = set()


@functools.lru_cache(maxsize=None)
def _make_bsdf_class_for(variant: str):
    import drjit as dr
    import mitsuba as mi

    class RetroreflectiveSheeting(mi.BSDF):
        """Mitsuba BSDF: Lambertian ``diffuse_albedo`` + the R_A lobe of a sheeting table.

        Properties: ``sheeting`` (table name), optional ``table_path``.
        """

        def __init__(self, props):
            mi.BSDF.__init__(self, props)
            path = props.get("table_path", str(SHEETING_FILE))
            self.table = load_sheeting(props.get("sheeting"), path)
            self.albedo = float(self.table.diffuse_albedo)
            self.m_flags = mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.FrontSide
            self.m_components = [mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.FrontSide,
                                 mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.FrontSide]

        def sample(self, ctx, si, sample1, sample2, active=True):
            ci = mi.Frame3f.cos_theta(si.wi)
            bs = mi.BSDFSample3f()
            bs.wo = mi.warp.square_to_cosine_hemisphere(sample2)
            bs.pdf = mi.warp.square_to_cosine_hemisphere_pdf(bs.wo)
            bs.eta = 1.0
            bs.sampled_type = mi.UInt32(+mi.BSDFFlags.DiffuseReflection)
            bs.sampled_component = mi.UInt32(0)
            ok = active & (ci > 0) & (bs.pdf > 0)
            return bs, dr.select(ok, mi.Spectrum(self.albedo), mi.Spectrum(0.0))

        def eval(self, ctx, si, wo, active=True):
            ci = mi.Frame3f.cos_theta(si.wi)
            co = mi.Frame3f.cos_theta(wo)
            # observation angle, precise at small angles: 2 asin(|wi - wo| / 2)
            chord = dr.norm(si.wi - wo)
            alpha = 2.0 * dr.asin(dr.minimum(0.5 * chord, 1.0)) * (180.0 / dr.pi)
            beta = dr.acos(dr.clip(co, -1.0, 1.0)) * (180.0 / dr.pi)
            ra = _ra(alpha, beta, self.table, dr.select, dr.log, dr.exp)
            v = self.albedo / dr.pi * co + ra / dr.maximum(ci, 1e-4)
            return dr.select(active & (ci > 0) & (co > 0), mi.Spectrum(v), mi.Spectrum(0.0))

        def pdf(self, ctx, si, wo, active=True):
            ok = active & (mi.Frame3f.cos_theta(si.wi) > 0) & (mi.Frame3f.cos_theta(wo) > 0)
            return dr.select(ok, mi.warp.square_to_cosine_hemisphere_pdf(wo), 0.0)

        def eval_pdf(self, ctx, si, wo, active=True):
            return self.eval(ctx, si, wo, active), self.pdf(ctx, si, wo, active)

        def traverse(self, callback):
            pass

        def to_string(self):
            return f"RetroreflectiveSheeting[{self.table.name}]"

    return RetroreflectiveSheeting


def _make_bsdf_class():
    import mitsuba as mi

    return _make_bsdf_class_for(mi.variant())


def bsdf_dict(sheeting: str) -> dict:
    """The Mitsuba dict of a sheet (checks the name first)."""
    load_sheeting(sheeting)
    return {"type": PLUGIN, "sheeting": sheeting}


__all__ = ["SheetingTable", "load_sheeting", "sheeting_names", "register_bsdf", "bsdf_dict", "piecewise_log_linear",
           "SHEETING_FILE", "PLUGIN"]

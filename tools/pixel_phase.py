"""Pixel-phase figure: a spot's centroid error versus where it falls inside a pixel (issue 11).

Where the PSF is undersampled (the Airy core of an f/2.2-2.4 lens is ~1 px across on 1.4 um
pixels) a windowed centroid is pulled towards the pixel centre: an S-curve ("pixel locking")
that is physics, not an artefact. This tool draws it for each camera profile:

- **GalSim**: the reference optical image (Airy (x) aberration Gaussian, pixel response),
  its 5 x 5 windowed centroid;
- **ours, mono**: the camera model's optical image of a point (Monte Carlo convolution,
  pixel integration), the same centroid: it must lie on GalSim's curve;
- **ours, colour**: the Bayer mosaic (each channel's Airy at its wavelength and response),
  white balance and bilinear demosaic to luminance (noise-free, linear): what the mosaic
  and the demosaic add;
- **SVGS, colour / mono**: the SVGS detector's centroid on the delivered 8-bit image
  (noise-free exposure, tone curve, peak near white as the phones expose the spots).

The spot moves along x at a fixed y phase of 0.25 px. Writes ``docs/figures/pixel-phase.png``
and ``docs/figures/pixel-phase.csv``; ``docs/pixel-phase.md`` quotes them.

Run: ``.venv/bin/python tools/pixel_phase.py`` (about a minute on 2 cores)
"""

from __future__ import annotations

import csv
import dataclasses
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

PHASES = np.arange(0.0, 1.0 + 1e-9, 1.0 / 16)
Y_PHASE = 0.25
HALF = 2
N_SAMPLES = 1 << 16


def _centroid(img, cu, cv, h=HALF):
    sub = img[cv - h:cv + h + 1, cu - h:cu + h + 1].astype(np.float64)
    v, u = np.mgrid[cv - h:cv + h + 1, cu - h:cu + h + 1]
    return np.array([(sub * u).sum() / sub.sum(), (sub * v).sum() / sub.sum()])


def curves(name: str) -> dict:
    import galsim

    from svgs_sim.camera.phone import Exposer, PhoneCamera
    from svgs_sim.camera.phone.cfa import luminance
    from svgs_sim.camera.rendered import PointFlux
    from svgs_sim.svgs.detect import detect_blobs
    from svgs_sim.base.profiles import Camera

    cam = Camera.load(name)
    base = PhoneCamera(cam)
    glare = dataclasses.replace(base.params.glare, veiling_fraction=0.0, ghosts=())
    phone = PhoneCamera(cam, dataclasses.replace(base.params, glare=glare))  # the core PSF alone
    psf = phone.core_psf()
    gs = galsim.Convolve(galsim.Airy(lam_over_diam=psf.lam_over_d_px), galsim.Gaussian(sigma=psf.aberration_sigma_px))
    sp = phone.params.sensor
    H, W = phone.shape
    u0, v0 = (W // 2) & ~1, (H // 2) & ~1  # a red pixel of the RGGB mosaic at phase 0
    t_s, iso = 1e-3, sp.base_iso
    out = {k: [] for k in ("galsim", "mono", "colour", "svgs_mono", "svgs_colour")}
    for k, ph in enumerate(PHASES):
        x, y = u0 + ph, v0 + Y_PHASE
        cu = int(np.floor(x + 0.5))  # the window is centred on the spot's pixel, as a detector's
        cv = int(np.floor(y + 0.5))
        g = gs.drawImage(nx=41, ny=41, scale=1.0, offset=(ph, Y_PHASE)).array
        out["galsim"].append(_centroid(g, 20 + cu - u0, 20 + cv - v0)[0] - 20 - ph)
        # a point bright enough to reach ~80 % of white in the brightest pixel (after the PSF)
        rate = 0.8 * sp.full_well_e / (sp.qe * t_s * 0.35)
        pts = PointFlux(np.full(N_SAMPLES, x), np.full(N_SAMPLES, y), np.full(N_SAMPLES, rate / N_SAMPLES))
        mono = phone.optics(np.zeros(phone.shape, np.float32), pts, seed=k, cfa=False)
        out["mono"].append(_centroid(mono, cu, cv)[0] - x)
        col = phone.optics(np.zeros(phone.shape, np.float32), pts, seed=k, cfa=True)
        gain = sp.gain_dn_per_e(iso)
        raw = np.clip(np.rint(col * sp.qe * t_s * gain + sp.black_level_dn), 0, sp.white_dn)
        lum = luminance(raw, phone.params.cfa, sp.black_level_dn, sp.white_dn)
        out["colour"].append(_centroid(lum, cu, cv)[0] - x)
        for key, stages in (("svgs_mono", ("glare", "adc", "tone")), ("svgs_colour", ("glare", "cfa", "adc", "tone"))):
            ex = Exposer(phone, np.zeros(phone.shape, np.float32), points=pts, stages=stages, optics_seed=k)
            img = ex.expose(seed=0, exposure_s=t_s, iso=iso).image
            b = detect_blobs(img[v0 - 20:v0 + 21, u0 - 20:u0 + 21], threshold=32)
            out[key].append(float(b.centroid_px[0, 0]) + u0 - 20 - x if len(b) else np.nan)
    return {k: np.asarray(v) for k, v in out.items()}


def main() -> int:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figdir = REPO / "docs" / "figures"
    figdir.mkdir(parents=True, exist_ok=True)
    rows = []
    fig, axes = plt.subplots(1, 2, figsize=(11, 4), sharey=True)
    for ax, name in zip(axes, ("galaxy-nexus", "htc-amaze-4g")):
        c = curves(name)
        style = {"galsim": ("k-", "GalSim (Airy x Gaussian x pixel)"), "mono": ("C0o", "ours, mono optical image"),
                 "colour": ("C3s-", "ours, Bayer + bilinear demosaic (luminance)"),
                 "svgs_mono": ("C0--", "SVGS detector, mono, 8-bit"), "svgs_colour": ("C3:", "SVGS detector, colour, 8-bit")}
        for k, (fmt, label) in style.items():
            ax.plot(PHASES, c[k], fmt, label=label, ms=4)
        ax.axhline(0, color="0.7", lw=0.5)
        ax.set_title(f"{name}: 5x5 windowed centroid, y phase {Y_PHASE} px")
        ax.set_xlabel("sub-pixel phase of the spot, x (px)")
        for i, ph in enumerate(PHASES):
            rows.append({"camera": name, "phase_px": float(ph), **{k: float(c[k][i]) for k in c}})
        amp = {k: float(np.nanmax(np.abs(c[k]))) for k in c}
        print(name, "max |centroid error| px:", {k: round(v, 4) for k, v in amp.items()},
              "mono vs GalSim max diff:", round(float(np.max(np.abs(c["mono"] - c["galsim"]))), 4))
    axes[0].set_ylabel("centroid error (px)")
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(figdir / "pixel-phase.png", dpi=120)
    with open(figdir / "pixel-phase.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    print(f"wrote {figdir / 'pixel-phase.png'} and {figdir / 'pixel-phase.csv'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

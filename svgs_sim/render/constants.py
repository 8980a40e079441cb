"""Renderer data and defaults - one home, units in the names.

The universal constants live in :mod:`svgs_sim.base.constants` (every layer needs them) and are
re-exported here for the renderer's modules.
"""

from __future__ import annotations

import numpy as np

from svgs_sim.base.constants import LUMINOUS_EFFICACY_MAX_LM_W, PLANCK_J_S, SPEED_OF_LIGHT_M_S  # noqa: F401 (re-exported)

#: CIE 1924 photopic luminous efficiency V(lambda), 380-780 nm in 10 nm steps
#: (CIE 018:2019 / ISO 23539:2005 tabulation, rounded as published).
CIE_V_WAVELENGTH_NM = np.arange(380.0, 781.0, 10.0)
CIE_V = np.array([
    0.000039, 0.000120, 0.000396, 0.001210, 0.004000, 0.011600, 0.023000, 0.038000, 0.060000,
    0.090980, 0.139020, 0.208020, 0.323000, 0.503000, 0.710000, 0.862000, 0.954000, 0.994950,
    0.995000, 0.952000, 0.870000, 0.757000, 0.631000, 0.503000, 0.381000, 0.265000, 0.175000,
    0.107000, 0.061000, 0.032000, 0.017000, 0.008210, 0.004102, 0.002091, 0.001047, 0.000520,
    0.000249, 0.000120, 0.000060, 0.000030, 0.000015,
])

#: N-BK7 Sellmeier coefficients (SCHOTT datasheet): n^2 - 1 = sum B_i l^2 / (l^2 - C_i), l in um.
NBK7_SELLMEIER_B = (1.03961212, 0.231792344, 1.01046945)
NBK7_SELLMEIER_C_UM2 = (0.00600069867, 0.0200179144, 103.560653)


def nbk7_index(wavelength_nm) -> np.ndarray:
    """Refractive index of SCHOTT N-BK7 (Sellmeier), e.g. 1.5168 at 587.6 nm."""
    l2 = (np.asarray(wavelength_nm, float) / 1000.0) ** 2
    n2 = 1.0 + sum(b * l2 / (l2 - c) for b, c in zip(NBK7_SELLMEIER_B, NBK7_SELLMEIER_C_UM2))
    return np.sqrt(n2)


# ------------------------------------------------------------------ render defaults
DEFAULT_SPP = 4  # full-frame samples per pixel (the background: dark, diffuse)
DEFAULT_ROI_SPP = 64  # samples per pixel inside the windows around the targets (guided method; their diffuse light is ~1e-6 of a spot)
DEFAULT_ROI_SPP_PATH = 4096  # the same for the brute-force method (the spots are path traced)
DEFAULT_ROI_SIZE_PX = 32  # side of the square window rendered around each spot
DEFAULT_SPOT_SAMPLES = 1 << 14  # guided samples per virtual source (svgs_sim.render.spots; tools/render_noise.py)
DEFAULT_SPOT_SAMPLER = "kronecker"  # placement of the guided samples: the 4-D R4 sequence (svgs_sim.render.spots)
DEFAULT_MAX_DEPTH = 12  # camera -> front face -> 3 TIR -> front face -> LED needs >= 7 (use more)
DEFAULT_MESH_SEGMENTS = 48  # rim segments per cube face (aperture area error ~1e-4)

"""Universal physical constants (SI, exact where the SI defines them) - one home for every layer.

The lowest layer holds them so that the ToF pixel (:mod:`svgs_sim.camera.amcw`), the renderers
(:mod:`render`) and the ToF algorithms can all import them; renderer data and defaults stay
in :mod:`svgs_sim.render.constants`.
"""

from __future__ import annotations

PLANCK_J_S = 6.62607015e-34  # exact (SI 2019)
SPEED_OF_LIGHT_M_S = 299_792_458.0  # exact
LUMINOUS_EFFICACY_MAX_LM_W = 683.002  # K_m, lm/W at 555 nm (SI definition of the candela)

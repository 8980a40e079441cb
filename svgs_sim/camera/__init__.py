"""Camera models, numpy only: what a sensor makes of the light the renderer delivers.

- :mod:`svgs_sim.camera.phone` - the phone camera: lens PSF (diffraction + aberration core, glare,
  ghosts), EMVA 1288 sensor with blooming, auto-exposure, tone curve, 8-bit, JPEG.
- :mod:`svgs_sim.camera.amcw` - the ToF camera's 4-tap AMCW pixel: rendered phasors -> noisy taps ->
  amplitude, depth and gray frames.

Layer: above :mod:`svgs` (profiles, errors), below :mod:`render`; never imports Mitsuba.
"""

"""svgs-sim: a physically-based optical sensor simulator for spacecraft proximity operations.

Subpackages, low to high (a package imports only those below it; ``docs/architecture.md``):

- :mod:`svgs_sim.assets` - package data: the app's settings, camera profiles, patterns, labs, the papers' tables
- :mod:`svgs_sim.base` - profiles and their schema, limits, errors, JSON encoding, physical constants
- :mod:`svgs_sim.svgs` - the SVGS sensor's algorithms (detect, identify, solve); runs on real photos
- :mod:`svgs_sim.tof`, :mod:`svgs_sim.calibration` - the ToF sensor's pipeline; camera calibration
- :mod:`svgs_sim.camera` - camera models (the phone, the ToF pixel), numpy only
- :mod:`svgs_sim.render` - the Mitsuba scenes (the only code that touches Mitsuba and Dr.Jit)
- :mod:`svgs_sim.sim` - the closed loop, trial kinds, approaches, the Basilisk module
- :mod:`svgs_sim.studies` - executors, resumable stores, campaign, sweeps, reports
- :mod:`svgs_sim.cli` - the ``svgs`` command

Importing ``svgs_sim`` imports none of them.
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("svgs-sim")
except PackageNotFoundError:  # a source tree on sys.path without an install
    __version__ = "0+unknown"

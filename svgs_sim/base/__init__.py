"""The base layer under every sensor package: camera and pattern profiles with their schema
(:mod:`~svgs_sim.base.profiles`, :mod:`~svgs_sim.base.profile_schema`), the physical bounds of every
input (:mod:`~svgs_sim.base.limits`), the errors (:mod:`~svgs_sim.base.errors`), JSON encoding
(:mod:`~svgs_sim.base.jsonable`) and physical constants (:mod:`~svgs_sim.base.constants`).

It imports nothing of the project but :mod:`svgs_sim.assets`.
"""

"""Simulation: scenarios, the closed loop and the trial kinds.

- :mod:`svgs_sim.sim.closed_loop` - Scenario -> rendered flux -> phone image -> SVGS solution -> errors.
- :mod:`svgs_sim.sim.trials` - trial kinds (what one trial of a study computes): the registry and the
  geometric kind; :mod:`svgs_sim.sim.render_trial` - the rendered (Mitsuba + phone) kind.
- :mod:`svgs_sim.sim.boards` - rendered calibration board sets (Mitsuba + phone camera).
- :mod:`svgs_sim.sim.tof_closed_loop` - the ToF closed loop (scenario -> render -> AMCW frames -> pose -> errors);
  :mod:`svgs_sim.sim.tof_stability` - the ToF paper's stability runs re-enacted; :mod:`svgs_sim.sim.tof_trial` - the
  ``tof`` trial kind of the ToF study.

Layer: above :mod:`render`, :mod:`camera`, :mod:`calibration`, :mod:`tof` and :mod:`svgs`;
below :mod:`studies` and :mod:`cli`. Mitsuba is reached only through :mod:`render`.
"""

"""``python -m svgs_sim.studies.campaign rebuild DIR [DIR ...]`` (:func:`svgs_sim.studies.campaign.run.main`)."""

from .run import main

if __name__ == "__main__":  # importing it (the API reference's autosummary) runs nothing
    raise SystemExit(main())

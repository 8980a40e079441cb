"""``python -m studies.campaign rebuild DIR [DIR ...]`` (:func:`studies.campaign.run.main`)."""

from .run import main

raise SystemExit(main())

"""Result objects. Failure is a value: a falsy :class:`Failure` carries a reason code."""

from __future__ import annotations

from dataclasses import dataclass, field

from .frames import state_dict

#: Machine-readable failure reasons and what they mean.
REASONS = {
    "no_blobs": "no bright blob passed the threshold and the size/shape gates",
    "too_few_blobs": "fewer blobs than targets were found",
    "merged_spots": "the target spots merged into fewer, larger blobs",
    "no_consistent_set": "no subset of the blobs matches the target pattern geometrically",
    "inconsistent": "a pose was solved, but its residual is improbable for the centroid noise the sensor should have (chi-square test, svgs_sim.svgs.app)",
    "diverged": "the least-squares iteration diverged or did not converge",
    "behind_camera": "the solution puts the target behind the camera",
    "behind_target": "the only pose that fits views the target from behind, where its reflectors return no light",
    "degenerate": "the measurements do not constrain the pose",
    "no_board": "no calibration board was found in the image",
    "too_few_corners": "too few board corners or circles were found in the image",
    "unreadable": "the image file could not be read (missing, empty, corrupt, or not an image)",
}


class Solved:
    """Mixin of a successful estimate: truthy, ``ok`` True, no ``reason``, and the paper's
    state as named values from ``self.state`` (shape (6,): m and rad).

    The pose results of both sensors (:class:`svgs_sim.svgs.solver.Solution`,
    :class:`svgs_sim.tof.pipeline.TofSolution`) are ``Solved``; a failure is a falsy :class:`Failure`.
    """

    ok = True
    reason = None

    def __bool__(self) -> bool:
        return True

    @property
    def state_dict(self) -> dict:
        """The state keyed by :data:`svgs_sim.svgs.frames.STATE_KEYS` (m and deg)."""

        return state_dict(self.state)


@dataclass
class Failure:
    """A failed estimation: falsy, with a machine-readable ``reason`` and a ``message``.

    Attributes
    ----------
    reason : str
        One of :data:`REASONS`.
    message : str
        A sentence for people.
    details : dict
        Anything that helps diagnose (blob counts, residuals...), JSON-serialisable.
    """

    reason: str
    message: str
    details: dict = field(default_factory=dict)

    ok = False

    def __bool__(self) -> bool:
        return False

    def to_json(self) -> dict:
        return {"ok": False, "reason": self.reason, "message": self.message, **self.details}

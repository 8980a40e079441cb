"""What a phone's camera carries from one frame of its stream to the next: the auto-exposure's
state (:class:`ExposureStream`), and one renderer whose scene is built once and whose lens is
refocused every frame, optionally rendering the next frame in a background thread
(:class:`RenderStream`); each frame's seeds (:func:`frame_seeds`)."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np

from svgs_sim.base.profiles import Camera, Pattern
from svgs_sim.render.api import Renderer

#: The phone's preview stream rate when the exposure allows it, frames/s: its auto-exposure loop
#: steps once per stream frame, whether or not the sensor processes that frame (ASSUMPTION:
#: Android phones of 2011 streamed preview at up to 30 frames/s, and at 1/exposure when longer).
STREAM_FPS = 30.0
#: Most auto-exposure steps between two measurements (the loop has long settled by then).
MAX_AE_STEPS = 200


def frame_seeds(seed: int, k: int) -> tuple[int, int, int]:
    """Frame ``k``'s seeds ``(render, noise, motion)`` of a stream seeded ``seed``: drawn from
    ``numpy.random.SeedSequence([seed, k])``."""
    s = np.random.SeedSequence([int(seed), int(k)]).generate_state(3, dtype=np.uint32)
    return int(s[0]), int(s[1]), int(s[2])


def ae_steps(dt_s: float, exposure_s: float) -> int:
    """Auto-exposure steps the phone's stream makes in ``dt_s`` (s) at ``exposure_s`` (s): one per
    stream frame (``max(1 / STREAM_FPS, exposure_s)``), at least 1, at most :data:`MAX_AE_STEPS`."""
    period = max(1.0 / STREAM_FPS, float(exposure_s))
    return int(np.clip(np.floor(float(dt_s) / period + 1e-9), 1, MAX_AE_STEPS))


class ExposureStream:
    """The phone's auto-exposure across the frames of a stream.

    Parameters
    ----------
    phone : svgs_sim.camera.phone.PhoneCamera
        The phone (its ``params.exposure`` and ``params.sensor``).
    frame_rate_hz : float or None
        The rate the sensor takes its frames at: the loop steps ``period / max(1/STREAM_FPS,
        exposure)`` times between frames. None: free-running, the steps counted from the times of
        consecutive frames.
    """

    def __init__(self, phone, frame_rate_hz: float | None):
        self.phone = phone
        self.frame_rate_hz = frame_rate_hz
        self.settings = None  # (exposure_s, iso) for the next frame; None: converge on it
        self._meter = None  # (t_s, exposure_s, iso, meter) of the last frame, free-running mode

    @property
    def auto(self) -> bool:
        """The phone exposes automatically (else its manual exposure is fixed)."""
        return self.phone.params.exposure.mode == "auto"

    @property
    def next_settings(self):
        """(exposure_s, iso) the next frame will use, or None before the first frame of an
        auto-exposing phone (it then converges on that frame's scene)."""
        p = self.phone.params.exposure
        if p.mode == "manual":
            return (p.exposure_s, p.iso)
        return self.settings

    def restore(self, next_exposure_s: float | None, next_iso: float | None) -> None:
        """Continue with stored settings for the next frame (None: converge on it)."""
        self.settings = None if next_exposure_s is None else (float(next_exposure_s), float(next_iso))
        self._meter = None

    def advance(self, meter, exposure_s: float, iso: float, steps: int) -> tuple[float, float]:
        """The settings after ``steps`` of the loop from ``(exposure_s, iso)`` on ``meter``'s scene
        (:func:`svgs_sim.camera.phone.isp.stream_exposure`)."""
        from svgs_sim.camera.phone.isp import stream_exposure

        p = self.phone.params
        return stream_exposure(exposure_s, iso, meter.level, p.sensor, p.exposure, steps)

    def catch_up(self, t_s: float) -> None:
        """Free-running: the steps the stream made since the last frame, before the frame at ``t_s``."""
        if self.auto and self._meter is not None:
            t_prev, e_prev, iso_prev, meter = self._meter
            self.settings = self.advance(meter, e_prev, iso_prev, ae_steps(max(t_s - t_prev, 0.0), e_prev))
            self._meter = None

    def after_frame(self, t_s: float, settings: tuple, meter) -> None:
        """The loop runs on after the frame at ``t_s`` exposed with ``settings`` on ``meter``'s
        scene: to the next frame with a frame rate, one step otherwise (the rest at the next
        frame, :meth:`catch_up`)."""
        if not self.auto:
            return
        steps = ae_steps(1.0 / self.frame_rate_hz, settings[0]) if self.frame_rate_hz else 1
        self.settings = self.advance(meter, settings[0], settings[1], steps)
        self._meter = None if self.frame_rate_hz else (t_s, settings[0], settings[1], meter)


class RenderStream:
    """One renderer for the frames of a stream: the scene built once, the lens refocused on the
    target every frame (as the phones' autofocus); optionally the next frame rendered in a
    background thread while the phone model works on this one.

    Parameters
    ----------
    camera : svgs.Camera
    pattern : svgs.Pattern
    seed : int
        The stream's seed (frame ``k`` renders with :func:`frame_seeds` ``(seed, k)[0]``).
    spp, roi_spp : int, optional
        Render quality (:class:`svgs_sim.render.api.Renderer`).
    scene_options : dict, optional
        The scene around the target (:class:`svgs_sim.render.geometry.SceneOptions` fields: the
        body, the sun, the Earth); a frame's own natural light (``light`` of :meth:`render_now`)
        replaces the sun's and the Earth's fields.
    """

    def __init__(self, camera: Camera, pattern: Pattern, seed: int, *, spp: int | None = None,
                 roi_spp: int | None = None, scene_options: dict | None = None):
        self.camera = camera
        self.pattern = pattern
        self.seed = int(seed)
        self._options = {**(scene_options or {}), "focus_distance_m": 1.0}  # refocused every frame
        self._quality = {k: int(v) for k, v in (("spp", spp), ("roi_spp", roi_spp)) if v is not None}
        self._renderer = None
        self._pool = None  # the background render thread
        self._pending = None  # ((frame, R bytes, t bytes), future) of the render in flight

    def renderer(self):
        """The :class:`svgs_sim.render.api.Renderer` (made on first use)."""
        if self._renderer is None:

            self._renderer = Renderer(self.camera, self.pattern, scene_options=self._options, **self._quality)
        return self._renderer

    @property
    def running(self) -> bool:
        """The background render thread is up."""
        return self._pool is not None

    def render_now(self, k: int, R, t, light: dict | None = None):
        """Frame ``k`` at ``(R, t)`` rendered in this thread, focused at ``|t|``; ``light``: the
        frame's natural light (:meth:`svgs_sim.sim.scene.Scene.natural_light`), None: the stream's."""
        r = self.renderer()
        r.set_focus_distance(float(np.linalg.norm(t)))
        if light is not None:
            r.set_natural_light(**light)
        return r.render(R, t, seed=frame_seeds(self.seed, k)[0])

    @staticmethod
    def _key(k: int, R, t, light: dict | None) -> tuple:
        return (int(k), np.asarray(R, float).tobytes(), np.asarray(t, float).tobytes(), repr(light))

    def start(self, k: int, R, t, light: dict | None = None) -> None:
        """Render frame ``k`` at ``(R, t)`` in the background thread (one at a time)."""

        self.drop()
        if self._pool is None:
            self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="svgs-render")
        self._pending = (self._key(k, R, t, light), self._pool.submit(self.render_now, k, R, t, light))

    def take(self, k: int, R, t, light: dict | None = None):
        """Frame ``k``'s render: the background one if it is that frame's, else rendered now."""
        if self._pending is not None:
            key, fut = self._pending
            self._pending = None
            res = fut.result()  # wait for it (and the renderer) in any case; errors surface here
            if key == self._key(k, R, t, light):
                return res
        return self.render_now(k, R, t, light)

    def drop(self) -> None:
        """Wait for a background render and discard it."""
        if self._pending is not None:
            _, fut = self._pending
            self._pending = None
            fut.result()

    def close(self) -> None:
        """Stop the background render thread (a later :meth:`start` starts it again)."""
        self.drop()
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None

"""One guided window's observation and plan: the one place an :class:`Observation` is built from a capture.

:func:`observe_window` turns a source, the sampler's settings (a :class:`~spikeview.guided.config.GuidedConfig`:
window Δτ, η, temporal radius, device) and a centre tick, with an optional region of interest, into the
window's :class:`~spikeview.guided.observation.Observation` and its :class:`~spikeview.guided.plan.Plan`.
The guided sequence (:func:`spikeview.guided.video.reconstruct_sequence`) calls it for every window; the
front ends (the CLI, the app's jobs, the benchmark, the Dask chunks) reach it through
:func:`spikeview.pipeline.plan_window`, which adds the recipe, the sequence's state and the knob status.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from spikeview.errors import ParameterError
from spikeview.guided.config import GuidedConfig
from spikeview.guided.observation import Observation


@dataclass
class Window:
    """A planned window.

    Attributes:
        whole: the whole frame's observation (its counts, pooling, previous window).
        obs: the observation the sampler runs on: ``whole`` cropped to the region of interest, if any.
        plan: the plan of ``obs`` under the settings it was observed with.
    """

    whole: Observation
    obs: Observation
    plan: Any


def crop_to_roi(obs: Observation, roi: tuple[int, int, int, int]) -> Observation:
    """The observation (and its previous and own windows) on ``roi = (x, y, w, h)``, origin on even pixels.

    Raises:
        ParameterError: a region smaller than 8×8 pixels.
    """
    from spikeview.cfa import crop_roi

    y, (y0, x0) = crop_roi(obs.y, roi)
    if min(y.shape) < 8:
        raise ParameterError("The region of interest is too small for a guided reconstruction: draw one of at least 8x8 pixels.")
    y1, x1 = y0 + y.shape[0], x0 + y.shape[1]
    out = obs.crop(y0, y1, x0, x1)
    if obs.previous is not None:
        out.previous = obs.previous.crop(y0, y1, x0, x1)
    if obs.own is not None:
        out.own = obs.own.crop(y0, y1, x0, x1)
    return out


def same_window(obs: Observation, center: int, p: GuidedConfig, alpha: np.ndarray | None) -> bool:
    """Whether ``obs`` is what :meth:`Observation.from_source` builds for ``center`` at these settings
    (no previous window: the first frame of a sequence has none)."""
    pooling = obs.pooling
    same_alpha = (obs.alpha is None) if alpha is None or obs.cfa is None else (
        obs.alpha is not None and np.array_equal(obs.alpha, np.asarray(alpha, dtype=np.float64).reshape(-1)))
    return (obs.center == int(center) and obs.window == p.window and obs.eta == p.eta and obs.previous is None
            and pooling is not None and pooling.radius == p.temporal_radius and same_alpha)


def observe_window(source: Any, centre: int, params: GuidedConfig, alpha: np.ndarray | None, *,
                   roi: tuple[int, int, int, int] | None = None, previous: bool = False, cache: Any = None,
                   plan: bool = True, reuse: Observation | None = None) -> Window:
    """The window of ``source`` centred on ``centre`` under ``params`` (see the module docstring).

    Args:
        alpha: the sequence's gains α (``None``: no colour cast).
        roi: ``(x, y, w, h)``: plan and sample this region only (``Window.whole`` keeps the frame).
        previous: also read the window before (the plan's reuse test in a sequence).
        cache: a :class:`~spikeview.guided.temporal.WindowCache` shared by a sequence's windows.
        plan: make the plan (False: ``Window.plan`` is None).
        reuse: a whole-frame observation an earlier call returned (``Window.whole``) for this source: used instead of
            counting and pooling again when it is the one these settings build (:func:`same_window`; the app's
            knob changes on an ROI re-plan and re-sample, they do not re-pool the 1000² frame).
    """
    h, w = int(source.height), int(source.width)
    if min(h, w) < 2:
        raise ParameterError(f"the capture's frames are {w}x{h} pixels: a guided reconstruction needs at least 2x2; "
                             "use --method tfp (or tfi) for it.")
    if reuse is not None and not previous and reuse.y.shape == (h, w) and same_window(reuse, centre, params, alpha):
        whole = reuse  # built (and corrected) by an earlier call with these settings
    else:
        whole = Observation.from_source(source, int(centre), params.window, alpha=alpha, eta=params.eta,
                                        radius=params.temporal_radius, previous=previous, cache=cache, device=params.device)
        from spikeview.classical.calibration import correct_observation

        correct_observation(source, whole)  # the camera profile's rate correction, as the classical frames get it
    obs = whole if roi is None else crop_to_roi(whole, roi)
    if not plan:
        return Window(whole, obs, None)
    from spikeview.guided.plan import make_plan

    return Window(whole, obs, make_plan(obs, params))

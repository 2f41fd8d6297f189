"""Which of the researcher's knobs act on a window, and why a knob does not.

:func:`knob_status` answers, for the plan of a window and the settings, whether changing each of the
guided sampler's knobs (by dotted recipe path: ``guided.s``, ``guided.k``, ``guided.levels``,
``guided.t_start``, ``guided.lam``) can change the result. ``None`` means it acts; a sentence says
why it does not. The CLI prints that sentence for a flag the user gave; the app disables the
control with the sentence as its tooltip. The rules follow the sampler exactly:

* nothing acts when the plan skips diffusion (the window gets the baseline or TFP);
* ``s``: DPS step size, or under HQS the weight of the data step; inert only without data steps;
* ``k``: only when Q is in the forward model (the plan's ``quantise``);
* ``levels``: only when the frame allows at least one band-pass level;
* ``t_start``: with ``top_up`` (the default) the sampler adds only the noise missing to reach
  ``t_start``; when the start estimate's own noise already exceeds it in every channel, ``t_start``
  has no effect;
* ``lam``: HQS only;
* ``temporal_radius``: only when the capture holds a whole window beside this one (it acts on the
  fallback's input too, so also when the plan skips diffusion).
* ``chroma``: on every colour frame (diffused or not); never on a gray one.
"""

from __future__ import annotations

import numpy as np

from spikeview.guided.config import GuidedConfig
from spikeview.guided.plan import Plan

#: the knobs reported, by recipe path
KNOBS = ("guided.s", "guided.k", "guided.levels", "guided.t_start", "guided.lam", "guided.temporal_radius",
         "guided.chroma")


def temporal_status(plan: Plan) -> str | None:
    """Why ``guided.temporal_radius`` cannot act on this window (no whole neighbouring window in the
    capture), or None."""
    pool = getattr(plan, "pooling", None)
    if pool is None or pool.offsets:
        return None
    return (f"the capture holds no whole {pool.window}-tick window beside this one ({pool.reason}), so there is no "
            "neighbour to borrow spikes from")


def chroma_status(plan: Plan) -> str | None:
    """Why ``guided.chroma`` cannot act on this window (a gray frame), or None."""
    return None if plan.mosaic else "the frame is gray (monochrome, or M off): it has no colour to smooth"


def knob_status(cfg: GuidedConfig, plan: Plan) -> dict[str, str | None]:
    """``{path: None (acts) or the reason it does not}`` for every entry of :data:`KNOBS`."""
    out: dict[str, str | None] = {k: None for k in KNOBS}
    if not plan.diffusion:
        why = f"the plan skips diffusion for this window ({plan.reasons.get('diffusion', '')})"
        out = {k: why for k in KNOBS}
        out["guided.temporal_radius"] = temporal_status(plan)  # pooling changes the fallback's input too
        out["guided.chroma"] = chroma_status(plan)
        return out
    out["guided.temporal_radius"] = temporal_status(plan)
    out["guided.chroma"] = chroma_status(plan)
    if cfg.guidance == "hqs" and cfg.data_steps == 0:
        out["guided.s"] = "HQS takes no data step here (data_steps = 0), so there is nothing for s to weigh"
    if not plan.quantise:
        out["guided.k"] = f"soft quantisation Q is off ({plan.reasons.get('quantise', '')}); turn Q on to use k"
    if plan.levels == 0 and cfg.levels > 0:
        out["guided.levels"] = f"the frame is too small for a pyramid ({plan.reasons.get('levels', '')})"
    if cfg.guidance != "hqs" or cfg.prior == "sd":
        out["guided.lam"] = "λ weighs the HQS data step; the guidance is DPS"
    if cfg.top_up and cfg.prior != "sd" and not cfg.warm_start:
        sigma_obs = np.asarray(plan.sigma, dtype=np.float64) * cfg.sigma_scale
        if sigma_obs.size and float(sigma_obs.min()) >= cfg.t_start:
            out["guided.t_start"] = (f"the start estimate's own noise ({255 * float(sigma_obs.min()):.1f}/255 or more per channel) "
                                     f"already exceeds t_s = {255 * cfg.t_start:.1f}/255, so the sampler starts at that noise; "
                                     "raise t_s above it")
    return out

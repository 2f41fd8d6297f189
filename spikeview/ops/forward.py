"""The SpikeDiff forward model ``A = Q ∘ C ∘ M`` and its multiscale data loss."""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import nn

from spikeview.errors import ParameterError
from spikeview.ops._checks import check_cfa, check_image, check_positive_int
from spikeview.ops.cast import ColourCast, colour_cast_inverse, estimate_alpha
from spikeview.ops.mosaic import Mosaic, demosaic_bilinear
from spikeview.ops.noise import binomial_vst, effective_sigma
from spikeview.ops.pyramid import multiscale_loss
from spikeview.ops.quantise import SoftQuantise


class ForwardModel(nn.Module):
    """``A(X) = Q(C · M · X)``: the camera seen by the guidance (monochrome: ``A = Q``).

    Each stage can be switched off for ablations (METHOD.md): ``cast=False`` drops C, ``k=None``
    drops Q, ``dense_grad=False`` uses the exact mosaic gradient, ``bands=1`` a single-scale loss.
    The caller clamps ``X`` to [0, 1] before calling (METHOD.md, numerical care); nothing is
    clamped here, so gradients are not cut.

    Args:
        cfa: Bayer pattern of the observation's top-left 2×2, or ``None`` for monochrome.
        window: Δτ, the TFP window in ticks (quantisation bands ``0, 1/Δτ, …, 1``).
        alpha: ``(3,)`` gray-world factors of the sequence (see :meth:`from_observation`);
            ``None`` means ``(1, 1, 1)`` (C is then a plain gain ``η``).
        eta: range parameter ``η`` of the cast.
        k: sharpness of Q (the sampler passes ``GuidedConfig.k``, the one default), or ``None`` (default) for no Q.
        dense_grad: bilinear-spread gradient of M (SpikeDiff) instead of the exact one.
        cast: apply C (ignored for monochrome).
        bands: bands of the Laplacian pyramid in :meth:`loss` (1 = single scale, ``guided.levels = 0``, the
            sampler's default; the sampler passes ``levels + 1``).
        weights: per-band weights of the loss (finest first); default all 1.
        norm: ``"l2"`` (non-squared, DPS reference) or ``"l2sq"``.
        vst: compare :func:`~spikeview.ops.noise.binomial_vst` of both sides, so the residual is
            in units of the (≈ unit) noise standard deviation.
        quantise_window: the ticks whose count Q models (default ``window``); k is scaled by ``quantise_window / window``.

    Shape:
        ``(N, 3, H, W)`` (mono ``(N, 1, H, W)``) in [0, 1] → ``(N, 1, H, W)`` in [0, 1] (with Q).
    """

    def __init__(
        self,
        cfa: str | None,
        window: int = 10,
        alpha: torch.Tensor | Sequence[float] | None = None,
        eta: float = 1.0,
        k: float | None = None,
        dense_grad: bool = True,
        cast: bool = True,
        bands: int = 1,
        weights: Sequence[float] | None = None,
        norm: str = "l2",
        vst: bool = False,
        quantise_window: int | None = None,
    ):
        super().__init__()
        self.cfa = check_cfa(cfa, allow_mono=True)
        self.window = check_positive_int(window, "window")
        self.mosaic = Mosaic(self.cfa, dense_grad) if self.cfa is not None else None
        self.cast = ColourCast((1.0, 1.0, 1.0) if alpha is None else alpha, eta) if (cast and self.cfa is not None) else None
        # Q's grid: the window's 1/Δτ, or a pooled observation's 1/Δτ_eff with k scaled to it (the same rounding shape
        # within each finer step; spikeview.guided.observation.Observation.quantise_window)
        qw = self.window if quantise_window is None else check_positive_int(quantise_window, "quantise_window")
        self.quantise = SoftQuantise(qw, k * qw / self.window) if k is not None else None
        if isinstance(bands, bool) or not isinstance(bands, int) or bands < 1:
            raise ParameterError(f"bands must be an integer >= 1, got {bands!r}; use 1 for a single-scale loss.")
        if norm not in ("l2", "l2sq"):
            raise ParameterError(f"norm must be 'l2' or 'l2sq', got {norm!r}.")
        self.bands = bands
        self.weights = None if weights is None else tuple(float(w) for w in weights)
        self.norm = norm
        self.vst = bool(vst)
        self.eta = float(eta)

    @classmethod
    def from_observation(cls, y: torch.Tensor, cfa: str | None, window: int = 10, **kwargs) -> ForwardModel:
        """Build the model with α estimated (gray-world) from the whole observed sequence ``y``.

        Args:
            y: ``(N, 1, H, W)`` mosaicked TFP frames of one sequence.
            cfa: Bayer pattern, or ``None`` for monochrome.
            window: Δτ in ticks.
            **kwargs: the other constructor arguments.
        """
        alpha = estimate_alpha(y, cfa) if check_cfa(cfa, allow_mono=True) is not None else None
        return cls(cfa, window, alpha=alpha, **kwargs)

    @property
    def channels(self) -> int:
        """Channels of X: 3 for a Bayer CFA, 1 for monochrome."""
        return 1 if self.cfa is None else 3

    @property
    def alpha(self) -> torch.Tensor | None:
        """The α buffer of C, or ``None`` when C is off."""
        return None if self.cast is None else self.cast.alpha

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``A(x)``: ``(N, C, H, W)`` scene → ``(N, 1, H, W)`` predicted TFP."""
        check_image(x, self.channels)
        out = x
        if self.cfa is not None:
            if self.cast is not None:
                out = self.cast(out)
            assert self.mosaic is not None
            out = self.mosaic(out)
        if self.quantise is not None:
            out = self.quantise(out)
        return out

    def stages(self, x: torch.Tensor) -> dict[str, torch.Tensor]:
        """The intermediate images of :meth:`forward`, stage by stage (for the app's degradation preview).

        Returns:
            ``{"x": x, "mx": M x, "cmx": M C x (= M x without C), "a": A(x)}``; for monochrome
            ``mx = cmx = x``. ``a`` equals ``cmx`` when Q is off. All ``(N, 1, H, W)`` but ``x``.
        """
        check_image(x, self.channels)
        if self.cfa is None:
            mx = cmx = x
        else:
            assert self.mosaic is not None
            mx = self.mosaic(x)
            cmx = self.mosaic(self.cast(x)) if self.cast is not None else mx
        a = self.quantise(cmx) if self.quantise is not None else cmx
        return {"x": x, "mx": mx, "cmx": cmx, "a": a}

    def loss(self, x: torch.Tensor, y_obs: torch.Tensor, reduction: str = "sum") -> torch.Tensor:
        """Multiscale data loss ``Σ_l w_l ‖P_l(T(A(x))) − P_l(T(y_obs))‖`` (``T`` = VST or identity).

        Args:
            x: ``(N, C, H, W)`` scene estimate (e.g. clamped X̂₀), requires grad for guidance.
            y_obs: ``(N, 1, H, W)`` observed TFP.
            reduction: ``"sum"``, ``"mean"`` or ``"none"`` (see :func:`~spikeview.ops.pyramid.multiscale_loss`).

        Returns:
            Scalar (or ``(N,)``) loss.
        """
        pred = self.forward(x)
        check_image(y_obs, 1, "y_obs")
        if y_obs.shape != pred.shape:
            raise ParameterError(f"y_obs must have shape {tuple(pred.shape)} (that of A(x)), got {tuple(y_obs.shape)}.")
        if self.vst:
            pred, y_obs = binomial_vst(pred, self.window), binomial_vst(y_obs, self.window)
        return multiscale_loss(pred, y_obs, self.bands, self.weights, self.norm, reduction)

    def initial_estimate(self, y: torch.Tensor) -> torch.Tensor:
        """``Y₀``: bilinear-demosaicked, colour-corrected TFP (``(N, 1, H, W)`` → ``(N, C, H, W)``, unclipped).

        ``Y₀_c = (α_c / η) · demosaic_bilinear(y)_c``; with C off ``Y₀ = demosaic_bilinear(y)``;
        monochrome returns ``y`` itself. The sampler clamps it to [0, 1] where needed.
        """
        check_image(y, 1, "y")
        if self.cfa is None:
            return y
        rgb = demosaic_bilinear(y, self.cfa)
        return rgb if self.cast is None else colour_cast_inverse(rgb, self.cast.alpha, self.cast.eta)

    def effective_sigma(self, y: torch.Tensor, prior: float = 0.5, per_pixel: bool = False) -> torch.Tensor:
        """Noise level of :meth:`initial_estimate` per frame and channel (see :func:`~spikeview.ops.noise.effective_sigma`)."""
        if self.cfa is None:
            return effective_sigma(y, None, self.window, prior=prior, per_pixel=per_pixel)
        if self.cast is None:
            return effective_sigma(y, self.cfa, self.window, alpha=(1.0, 1.0, 1.0), eta=1.0, prior=prior, per_pixel=per_pixel)
        return effective_sigma(y, self.cfa, self.window, self.cast.alpha, self.cast.eta, prior, per_pixel)

    def extra_repr(self) -> str:
        return f"cfa={self.cfa!r}, window={self.window}, bands={self.bands}, norm={self.norm!r}, vst={self.vst}"

"""Parameters of the guided reconstruction (SpikeDiff), as a TOML-saveable :class:`Config`.

One :class:`GuidedConfig` holds everything that decides a guided result: the sampler (steps, start
noise, guidance rule and its strength), the forward model (soft-quantisation sharpness ``k``,
pyramid levels, colour-cast range ``eta``), the observation (window ``window`` in ticks) and the
overrides of the scene plan (:mod:`spikeview.guided.plan`). ``GuidedConfig.save(path)`` writes TOML
and ``GuidedConfig.load(path)`` reads it back unchanged; every output of the guided sampler can carry
the config that made it.

Naming: ``eta`` is the colour-cast range parameter η of METHOD.md (the forward model scales channel
c by ``eta / alpha_c``; the CLI's ``--eta``), **not** DDIM's stochasticity, which is ``zeta`` here
(DiffPIR's name for the mix of predicted and fresh noise when re-noising).

Defaults were tuned on simulated 10-tick windows (realistic noise, known calibration) of the
tuning scenes of ``spikeview/bench/data.py`` and checked on held-out scenes
(``benchmarks/results/guided.md``): HQS in DPIR form (no re-noising), 6 steps from 50/255 to
5/255, λ = 2, prior told 2 × the data-derived noise (re-tuned on the user's path — gray-world α,
white point at 0.9, noise model at the local mean rate — on the tuning scenes only: 1.5 → 2 gained
+0.19 dB mean at 128×128, most on the low-key scene), signal-dependent noise weights, the
dense-gradient mosaic, per-step self-ensemble, a Malvar-2004 start estimate Y₀ (sharper than
bilinear: +0.2 dB on tuning and held-out scenes at 256×256, and with it λ = 2 beats 1.5 by a further
+0.15 dB). Q is decided by the plan: on for DPS, and for HQS at low rates (below 1.1 spikes
per photosite per window, where the counts are small integers: with k = 20 it gained up to
+0.16 dB and +0.04–0.08 SSIM on the tuning scenes there, and lost 0.2–0.3 dB at higher rates).
The pyramid stays **off** (2 levels lost 1.4–2.0 dB on the tuning scenes except the low-key one,
+0.2 dB); it stays available (``levels``).
"""

from __future__ import annotations

import dataclasses
import math

from spikeview.config import Config, check_range, param
from spikeview.errors import ParameterError

PRIORS = ("ffdnet", "sd")
GUIDANCES = ("dps", "hqs")
DIFFUSION_MODES = ("auto", "always", "never")
FALLBACKS = ("baseline", "tfp")
#: ``guided.precision``: the prior's arithmetic (:mod:`spikeview.guided.precision` and the recipe use this list)
PRECISIONS = ("auto", "float32", "float32-fast", "bfloat16-mixed")
DEMOSAICS = ("auto", "bilinear", "malvar2004", "menon2007")

#: the FFDNet prior was trained for noise levels up to about 75/255 (METHOD.md)
SIGMA_MAX = 75.0 / 255.0


def _check_range(name: str, value: float, lo: float, hi: float, *, lo_open: bool = False) -> None:
    check_range(f"guided.{name}", value, lo, hi, lo_open=lo_open)


def _check_choice(name: str, value: str, choices: tuple[str, ...]) -> None:
    if value not in choices:
        raise ParameterError(f"guided.{name} = {value!r} is not valid: use one of {', '.join(choices)}.")


@dataclasses.dataclass
class GuidedConfig(Config):
    """Settings of one guided reconstruction (see the module docstring for the file format).

    Attributes:
        guidance: ``"hqs"`` (DiffPIR/HQS: data steps on x̂₀, one prior call per step, no backprop
            through the prior; the default, fast on CPU) or ``"dps"`` (gradient of the non-squared
            residual norm through the prior, one forward+backward per step).
        prior: ``"ffdnet"`` (embedded pixel-space denoiser) or ``"sd"`` (a Stable-Diffusion-family
            latent model in diffusers format from ``model_path``; optional extra).
        model_path: weights directory for ``prior="sd"`` (or a FFDNet ``.pth`` replacing the
            packaged weights); ``None`` uses the packaged FFDNet weights.
        steps: number of sampler steps (prior calls) from the start noise level down to 0, >= 1.
        t_start: start noise level σ_ts **as a fraction of 1** (pixel values in [0, 1]), in
            ``[0, 75/255]``. The first prior call sees ``Z = Y₀ + σ_add·z`` and is told the total
            noise ``sqrt(σ_obs² + σ_add²)``, where σ_obs is the data-derived noise of Y₀ and
            ``σ_add = t_start`` (or, with ``top_up=True``, ``sqrt(max(t_start² - σ_obs², 0))`` so
            that the total is ``max(t_start, σ_obs)``). ``t_start = 0`` starts from Y₀ itself.
        top_up: add only the noise missing to reach ``t_start`` (see ``t_start``).
        sigma_end: the last non-zero noise level of the schedule, in ``(0, t_start]``.
        s: weight of the data against the prior, >= 0: the DPS step size (the gradient of
            ‖P(Y) − P(A(x̂₀))‖ with respect to x_t is scaled by ``s``), or under HQS the fraction of
            the data step taken (``x̂₀ + s·(prox(x̂₀) − x̂₀)``; 1 = the full step, 0 = prior only).
        lam: HQS data weight λ: ρ_t = λ·σ_n²/σ_t² weighs the prior against the data, > 0.
        data_steps: HQS preconditioned gradient steps on x̂₀ per sampler step (>= 0; 0 = no data
            step, i.e. unguided; the first step is the closed-form proximal point when the
            forward model is linear and single-scale).
        zeta: re-noising mix in [0, 1]: 0 = deterministic (DDIM/DPIR: predicted noise only),
            1 = fresh noise only (DiffPIR's ζ).
        renoise: HQS only: re-noise x̂₀ to σ_{t-1} between steps (DiffPIR); ``False`` hands the
            data-corrected x̂₀ itself to the next prior call, told σ_{t-1} (DPIR).
        noise_weights: weigh photosites by their modelled inverse variance (signal-dependent TFP
            noise); ``False`` weighs them equally (same mean noise level).
        k: soft-quantisation sharpness of Q (tanh slope, >= 0; the paper found 50 best; in the HQS data
            step here k = 20 beat 50 by 1.3–1.6 dB on the tuning scenes; ``k = 0`` is a flat
            staircase that gives no gradient, use ``quantise=False`` for no Q).
        quantise: include Q in the forward model; ``None`` (default) lets the plan decide
            (:func:`spikeview.guided.plan.make_plan`: on for DPS, off for HQS, with the reason).
        levels: band-pass levels L of the Laplacian pyramid of the multiscale loss (the pyramid has
            ``L + 1`` bands: L differences ``X_l − U(D(X_l))`` and the coarse residual; 0 = plain
            single-scale residual). Capped by the frame size by the plan (``str(plan)`` says so).
        dense_gradient: use the bilinear dense-gradient variant of the mosaic M in guidance.
        eta: colour-cast range parameter η (> 0): the corrected image is ``Y · α / η`` (2.0, as
            :class:`~spikeview.classical.reconstruct.ClassicalConfig`, puts each channel's mean at 0.5).
        alpha: fixed gains ``[α_R, α_G, α_B]`` (a calibration); ``None`` = gray-world estimate once
            per sequence (:func:`spikeview.classical.colour_cast.estimate_alpha`).
        alpha_max_windows: windows sampled from a long stream for that estimate.
        window: TFP window Δτ in ticks (>= 1; SpikeDiff uses 10).
        demosaic: demosaicking of the TFP start estimate Y₀: ``"auto"`` (the plan's choice with its
            reason, :func:`spikeview.guided.plan.choose_demosaic`), ``"bilinear"``, ``"malvar2004"``
            or ``"menon2007"``.
        sigma_scale: factor on the data-derived noise level handed to the prior (1 = as derived;
            FFDNet wants more than the RMS noise because demosaicking makes it correlated).
        self_ensemble: rotate/flip the input of each prior call (a different one of the 8 dihedral
            transforms per step), which averages the prior's artefacts out at no cost.
        chains: independent runs (different start noise and transform order) averaged into the
            result (an estimate of the posterior mean; costs ``chains`` × the time).
        seed: seed of the sampler's torch.Generator (results are deterministic for a seed).
        warm_start: in video, start each window from the previous result re-noised to t_start.
        use_mosaic, use_cast: plan overrides (``None`` = let the plan decide): force the mosaic M /
            the colour cast C on or off.
        levels_cap: plan override: ``False`` raises an error when ``levels`` exceeds what the frame
            size allows instead of capping it.
        diffusion: ``"auto"`` (the plan decides whether the window needs the sampler at all),
            ``"always"`` or ``"never"`` (always fall back).
        fallback: what a window that needs no diffusion gets: ``"baseline"`` (one prior pass) or
            ``"tfp"`` (demosaicked, colour-corrected TFP); ``None`` = the plan picks by noise.
        noise_target: noise level (σ of the corrected TFP estimate, fraction of 1) at or below which
            the plan skips diffusion (see :mod:`spikeview.guided.plan`).
        cast_tolerance: relative deviation of the colour-cast gains from neutral below which C is
            dropped (0.05 = 5 %).
        reuse: let the plan reuse the previous result when the window did not change (``None`` =
            on for video, decided by a count test).
        reuse_alpha: significance level of that count test (smaller = reuse more often).
        temporal_radius: neighbouring windows on each side whose photons the observation may
            borrow, aligned and weighted per photosite by how well they match
            (:mod:`spikeview.guided.temporal`); 0 = the window alone (the paper).
        balance: the sequence's gains are gray-world's or the camera profile's: where the plan turns Q on or a
            profile corrected the rates, the frame's channel means are kept at the data's
            (:mod:`spikeview.guided.balance`); set by the pipeline (:func:`spikeview.pipeline.sampler_params`),
            never written in a preset.
        chroma: colour frames only: σ in pixels of the luma-guided chroma smoothing applied to every
            frame the guided sequence yields (:mod:`spikeview.guided.chroma`); 0 = off.
        precision: arithmetic of the FFDNet prior (:mod:`spikeview.guided.precision`): ``"auto"``
            (the fastest path within 0.1 dB / 0.005 SSIM of float32 on the bench, for this CPU: bfloat16 only
            where a probe measures it faster), ``"float32"`` (the reference pixels), ``"float32-fast"`` (NNPACK's fast
            float32 convolution) or ``"bfloat16-mixed"`` (bfloat16 layers, bias-corrected, on high-noise steps).
        tile: per-tile plan and step-synchronous sampling (:mod:`spikeview.guided.tiles`): a frame
            larger than this is cut into tiles of about this many pixels (>= 64), each skipped,
            shortened or fully sampled by its own noise (128, the default: a 1000×1000 frame in 64
            tiles; a frame whose tiles all need the full ladder gives the untiled pixels); 0 = the
            whole frame at once.
        device: where the whole guided path runs (:mod:`spikeview.guided.device`): ``"auto"`` (the
            first CUDA GPU torch sees, else the CPU), ``"cpu"``, ``"cuda"``, ``"cuda:N"``.
        dtype: the precision of the sd prior (``float16``/``bfloat16`` need CUDA).
    """

    TABLE = "guided"

    guidance: str = param("hqs", label="Guidance rule", choices=("hqs", "dps"),
                          help="How the data steers each step: hqs (a data step on the clean estimate, fast) or dps "
                               "(gradient through the prior).")
    prior: str = param("ffdnet", label="Prior", choices=PRIORS,
                       help="Natural-image prior: ffdnet (embedded) or sd (a local Stable Diffusion 2.x model, optional extra).")
    model_path: str | None = param(None, flag="--model", label="Model weights",
                                   help="Weights folder for --prior sd (or an FFDNet .pth replacing the packaged weights); "
                                        "empty = packaged FFDNet.")
    steps: int = param(6, label="Steps", lo=1, hi=1000, step=1, help="Number of sampler steps (prior calls) per window.")
    t_start: float = param(50.0 / 255.0, label="Start noise t_s", unit="of full scale", lo=0.0, hi=SIGMA_MAX, step=1.0 / 255.0,
                           help="Start noise level t_s as a fraction of full scale (0.196 = 50/255; FFDNet is trained up "
                                "to 75/255 = 0.294).")
    top_up: bool = True
    sigma_end: float = 5.0 / 255.0
    s: float = param(1.0, label="Guidance weight s", lo=0.0, hi=10.0, step=0.05,
                     help="Weight of the data against the prior: the DPS step size, or under HQS the fraction of the data "
                          "step taken (1 = full, 0 = none).")
    lam: float = param(2.0, label="HQS λ", lo=0.0, lo_open=True, hi=100.0, step=0.1,
                       help="HQS prior weight λ in ρ_t = λσ_n²/σ_t² (larger trusts the prior more).")
    data_steps: int = 1
    zeta: float = 0.0
    renoise: bool = False
    noise_weights: bool = True
    k: float = param(20.0, label="Quantiser sharpness k", lo=0.0, hi=1000.0, step=1.0,
                     help="Sharpness k of the soft quantiser Q (20 measured best here; the paper's 50 washes a 1000² frame out); acts only when Q is on.")
    quantise: bool | None = param(None, label="Soft quantisation Q",
                                  help="Model the TFP's quantisation to multiples of 1/Δτ in the forward model (unset: the "
                                       "plan decides).")
    levels: int = param(0, label="Pyramid levels L", lo=0, hi=6, step=1,
                        help="Band-pass levels L of the multiscale Laplacian loss (0 = plain residual; capped by the frame size).")
    dense_gradient: bool = True
    eta: float = 2.0
    alpha: list[float] | None = None
    alpha_max_windows: int = 64
    window: int = 10
    demosaic: str = "auto"
    sigma_scale: float = param(2.0, label="Prior noise scale", lo=0.0, lo_open=True, hi=10.0, step=0.05,
                               help="Factor on the data-derived noise level handed to the prior (1 = as measured).")
    self_ensemble: bool = True
    chains: int = 1
    seed: int = param(0, label="Seed", lo=0, hi=2**31 - 1, step=1, help="Random seed (same seed and machine: same result).")
    warm_start: bool = param(False, label="Warm start",
                             help="Start each window of a sequence from the previous result re-noised to t_s (faster, may "
                                  "smear motion).")
    use_mosaic: bool | None = None
    use_cast: bool | None = None
    levels_cap: bool = True
    diffusion: str = "auto"
    fallback: str | None = None
    noise_target: float = 4.0 / 255.0
    cast_tolerance: float = 0.05
    reuse: bool | None = None
    reuse_alpha: float = 1e-3
    precision: str = param("auto", label="Prior precision", choices=PRECISIONS,
                           help="Arithmetic of the FFDNet prior: auto (the fastest path within 0.1 dB / 0.005 SSIM of "
                                "float32 on the bench, for this CPU: bfloat16 only where measured faster), float32 (the reference pixels), "
                                "float32-fast (NNPACK's fast float32 convolution) or bfloat16-mixed (bfloat16 on high-noise "
                                "steps).")
    tile: int = param(128, label="Tile size", unit="px", lo=0, hi=8192, step=64,
                      help="Per-tile plan: split frames larger than this into tiles of about this many pixels, each "
                           "skipped, shortened or fully sampled by its own noise; tiles step together, so there are no "
                           "seams (0 = the whole frame at once).")
    temporal_radius: int = param(3, label="Temporal radius", unit="windows", lo=0, hi=8, step=1,
                                 help="Neighbouring windows on each side whose spikes a guided frame may borrow, aligned and "
                                      "used only where they match (0 = the window alone).")
    chroma: float = param(2.0, label="Chroma smoothing", unit="px", lo=0.0, hi=8.0, step=0.5,
                          help="Colour frames: σ in pixels over which the colour (not the brightness) is smoothed, guided "
                               "by the luma so that colour stays inside its edges; removes the blotchy colour noise the "
                               "prior leaves (0 = off).")
    device: str = param("auto", key="", label="Device",
                        help="Where the guided reconstruction runs (prior, data term, tiles, temporal alignment): auto (the "
                             "first CUDA GPU torch sees, else the CPU), cpu, cuda or cuda:N; the app runs on auto (no control).")
    dtype: str = "float32"
    balance: bool = False

    def __post_init__(self) -> None:
        self.check_params()  # the declared ranges and choices (the ones the CLI and the app show)
        _check_choice("diffusion", self.diffusion, DIFFUSION_MODES)
        _check_choice("demosaic", self.demosaic, DEMOSAICS)
        if self.fallback is not None:
            _check_choice("fallback", self.fallback, FALLBACKS)
        for name in ("steps", "window", "levels", "data_steps", "seed", "alpha_max_windows", "chains", "temporal_radius", "tile"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int):
                raise ParameterError(f"guided.{name} = {v!r} must be a whole number.")
        from spikeview.classical.config import check_gains

        self.alpha = check_gains("guided.alpha", self.alpha)
        if not 1 <= self.chains <= 16:
            raise ParameterError(f"guided.chains = {self.chains} is out of range: use 1 to 16 chains.")
        if self.alpha_max_windows < 1:
            raise ParameterError(f"guided.alpha_max_windows = {self.alpha_max_windows} is out of range: use at least 1.")
        if self.tile != 0 and self.tile < 64:
            raise ParameterError(f"guided.tile = {self.tile} is out of range: use 0 (whole frame) or tiles of at least 64 pixels.")
        if self.window < 1:
            raise ParameterError(f"guided.window = {self.window} is out of range: use a window of at least 1 tick.")
        if self.data_steps < 0:
            raise ParameterError(f"guided.data_steps = {self.data_steps} is out of range: use 0 or more.")
        _check_range("sigma_end", self.sigma_end, 0.0, SIGMA_MAX + 1e-9, lo_open=True)
        _check_range("zeta", self.zeta, 0.0, 1.0)
        _check_range("eta", self.eta, 0.0, math.inf, lo_open=True)
        _check_range("noise_target", self.noise_target, 0.0, 1.0)
        _check_range("cast_tolerance", self.cast_tolerance, 0.0, math.inf)
        _check_range("reuse_alpha", self.reuse_alpha, 0.0, 1.0, lo_open=True)
        _check_choice("dtype", self.dtype, ("float32", "float16", "bfloat16"))
        from spikeview.guided.device import check_device_name

        self.device = check_device_name(self.device)

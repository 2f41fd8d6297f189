"""White balance: the colour-cast gains α of a sequence by gray-world or by estimators that do not assume a gray average.

Every estimator here returns the illuminant ``e`` (the raw RGB rate of a neutral surface, up to scale) of a
**sequence** (one estimate per sequence, so colours stay stable from frame to frame) and the gains are
``α_c ∝ 1 / e_c``, scaled so that ``Σ_c α_c · mean_c = 3`` (the overall level gray-world gives: the exposure is set
afterwards by the white point). The estimators see the sequence image: the mean rate of each 2×2 Bayer cell's R, G
(one green: every channel's noise alike) and B over the sampled windows, binned to at most :data:`MAX_CELLS` cells a
side (:func:`spikeview.classical.colour_cast.sequence_images`; no demosaicking). All but gray-world see it after a
3×3 median: a hot pixel would otherwise be the brightest patch and the strongest edge of the frame.

* ``gray-world`` — the mean of each channel (the paper's rule): right when the scene averages to gray.
* ``shades-of-gray`` — the Minkowski ``p = 6`` mean of each channel (Finlayson & Trezzi 2004).
* ``gray-edge`` — the Minkowski ``p = 6`` mean of the gradient magnitude of each channel after a Gaussian of σ = 1 cell
  (van de Weijer, Gevers & Gijsenij 2007, first order); ``gray-edge-2`` uses the second derivatives. Edges
  average to gray far more often than surfaces do: a colourful scene's large coloured areas weigh in only at their
  borders.
* ``white-patch`` — the mean of the brightest 1 % of the cells that are not saturated (bright pixels; brightness
  is the sum of the channels each divided by its mean, so that no channel's response favours its colour).
* ``combined`` — the geometric mean of the gray-edge, white-patch and shades-of-gray illuminants (each of unit
  length): three different assumptions, so one scene rarely fools all three the same way.
* ``auto`` — the camera profile's colour response (``profile``) when a profile with one is attached; else gray-world
  when it agrees with ``combined`` within :data:`AGREE_DEG` degrees (the scene averages to gray) or when their
  disagreement is within twice the estimators' own uncertainty (the angle between ``combined`` on the even and on the
  odd sampled windows: a featureless or fast-changing scene's edges and highlights are noise); else the scene is
  colourful and ``combined`` is taken, **pulled toward the typical spike-camera response** (:func:`toward_typical`):
  a colourful scene's edges and highlights are often coloured too (orange fur, a blue sky), and no estimator that sees
  only the capture can tell that from the sensor (below), so the camera's nominal response is the prior that breaks
  the tie. Below :data:`MIN_SPIKES` spikes per photosite (a dark scene) the rates hold the sensor's dark rate, the
  same in every channel, which pulls the mean toward gray while the edges and highlights do not see it: the test
  compares them after taking the dark rate (:func:`dark_level`) off the mean, within :data:`DARK_AGREE_DEG` (edges
  are noisier in the dark); gray-world's gains themselves stay those of the whole mean, dark rate included (they
  keep a dark gray scene gray). A dark colourful scene then gets ``combined`` pulled toward the typical response,
  its σ widened by its own noise (half the distance between the estimates of the even and the odd windows);
  gray-world had turned dark colourful scenes 16–35° off. The choice, its reason and how far the prior moved it are
  one sentence. (The thresholds were set on simulated scenes: ``benchmarks/bench_colour.py``.)
* ``typical`` — the typical response alone (:data:`spikeview.cfa.TYPICAL_RESPONSE`), whatever the scene.
* ``profile`` — the colour response measured by ``spikeview calibrate`` from a flat capture
  (:mod:`spikeview.classical.calibration`): the only choice that is right for a scene that is itself tinted.

No estimator that sees only the capture can tell a tinted scene from a tinted sensor: every one of them is
equivariant to per-channel gains (``est(D·I) = D·est(I)``), so a scene whose colours are all shifted by ``D``
(a green-dominated crop, a scene under a coloured light) is corrected as if ``D`` were the sensor's. Only a
reference measured with a known neutral (the calibration's flat capture) separates the two, or knowledge of the
camera: ``auto``'s prior is what a camera's automatic white balance does with its sensor's known daylight response
(Bayesian colour constancy: Brainard & Freeman 1997, Gehler et al. 2008). Its cost is a sensor unlike the typical
one: a colourful scene's estimate is pulled toward the wrong response (``benchmarks/results/colour.md`` measures
both); ``spikeview calibrate`` removes the question.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from spikeview.cfa import CHANNEL_INDEX, TYPICAL_RESPONSE, site_offsets
from spikeview.errors import ParameterError

#: the estimators (``auto`` takes gray-world, or combined pulled toward the typical response; ``profile`` needs a
#: camera profile)
ESTIMATORS = ("gray-world", "gray-edge", "gray-edge-2", "shades-of-gray", "white-patch", "combined")
CHOICES = ("auto",) + ESTIMATORS + ("typical", "profile")
#: Minkowski norm of shades-of-gray and gray-edge
MINKOWSKI_P = 6.0
#: Gaussian σ (in 2×2 cells) before the derivatives of gray-edge
EDGE_SIGMA = 1.0
#: fraction of the cells white-patch averages
BRIGHT_FRACTION = 0.01
#: auto: gray-world is kept when it and ``combined`` agree within this angle (degrees)
AGREE_DEG = 3.0
#: auto: ... or when their disagreement is within this many times ``combined``'s split-half uncertainty
NOISE_FACTOR = 2.0
#: auto: below this many spikes per photosite on average in the sampled windows (a dark scene, whose rates hold the
#: sensor's dark rate) the agreement test is made on the mean less the dark rate, ...
MIN_SPIKES = 5.0
#: ... there the mean less the dark rate (:func:`dark_level`) is compared with the edges and highlights, which are
#: noisier in the dark: gray-world is kept within this angle (twice :data:`AGREE_DEG`)
DARK_AGREE_DEG = 6.0
#: :func:`dark_level`: blocks of this many cells a side, and the percentile of their mean rates taken
DARK_BLOCK = 8
DARK_PERCENTILE = 2.0
#: auto's prior on the illuminant (log R/G, log B/G of :data:`~spikeview.cfa.TYPICAL_RESPONSE`): a Gaussian of this
#: σ (log units: 12 %, the spread of sensors' daylight responses) ...
PRIOR_SIGMA = 0.12
#: ... with this weight; :data:`NEUTRAL_WEIGHT` on a Gaussian of the same σ around a neutral response (R = G = B);
#: the rest a broad Gaussian of σ :data:`PRIOR_BROAD` (a sensor unlike either: an estimate far from both and sure of
#: itself is then kept)
PRIOR_WEIGHT = 0.72
#: files made from display-referred RGB frames (the ecosystem's simulators, spike streams converted from video) have no
#: cast at all: with the typical response alone, their estimates (1.5-5° off neutral on an independent simulator of
#: that kind) were pulled 34-47 % of the way to it, 5.5° off. The two are 17° apart, so an estimate is told to one or
#: the other by which it lies nearer (posterior weights), and one between them moves little
NEUTRAL_WEIGHT = 0.2
PRIOR_BROAD = 1.0
#: σ (log units) of combined's error on colourful scenes (the spread of its error on those of
#: ``benchmarks/bench_colour.py``: 2–23°)
COMBINED_SIGMA = 0.25


#: fixed gains R,G,B must lie within this factor of each other (no sensor's channels differ more; beyond it the white
#: point the gains imply leaves every output's range)
GAIN_SPREAD = 1000.0


def parse_white_balance(text: str, name: str = "--white-balance") -> str | list[float]:
    """``text`` as a method name of :data:`CHOICES` or as three fixed gains ``R,G,B`` (finite, positive).

    Raises:
        ParameterError: neither (one sentence naming ``name`` and the choices).
    """
    t = str(text).strip().lower()
    if t in CHOICES:
        return t
    parts = [p for p in t.replace(";", ",").split(",")]
    if len(parts) == 3:
        try:
            gains = [float(p) for p in parts]
        except ValueError:
            gains = []
        if len(gains) == 3 and all(np.isfinite(g) and g > 0 for g in gains):
            if max(gains) > GAIN_SPREAD * min(gains):
                raise ParameterError(f"{name} {text!r}: the three gains lie {max(gains) / min(gains):.3g}x apart; give "
                                     f"gains within {GAIN_SPREAD:g}x of each other (e.g. 1.6,1,2.1).")
            return gains
    raise ParameterError(f"{name} {text!r} is not one of {', '.join(CHOICES)} nor three positive gains R,G,B "
                         "(e.g. 1.6,1,2.1).")


def cells_rgb(rates: np.ndarray, cfa: str) -> np.ndarray:
    """``(H, W)`` mosaicked rates → ``(H//2, W//2, 3)`` float64: each 2×2 cell's R, G (the one on R's row) and B.

    One photosite per channel, so that every channel's noise is alike (a mean of the two greens would halve G's noise
    variance, and the edge and highlight estimators would take the noise for colour).
    """
    h, w = (rates.shape[0] // 2) * 2, (rates.shape[1] // 2) * 2
    r = np.asarray(rates, dtype=np.float64)[:h, :w]
    out = np.zeros((h // 2, w // 2, 3))
    for name, (py, px) in site_offsets(cfa).items():
        if name != "Gb":
            out[..., CHANNEL_INDEX[name[0]]] = r[py::2, px::2]
    return out


#: the estimators see the sequence image binned so that its longer side is at most this many cells
MAX_CELLS = 256


def binned(img: np.ndarray, max_side: int = MAX_CELLS) -> np.ndarray:
    """``img`` ``(h, w, 3)`` averaged over ``k×k`` blocks, the smallest ``k`` that makes its longer side ≤ ``max_side``."""
    k = -(-max(img.shape[:2]) // max_side)
    if k <= 1:
        return img
    h, w = img.shape[0] // k * k, img.shape[1] // k * k
    return img[:h, :w].reshape(h // k, k, w // k, k, 3).mean(axis=(1, 3))


def _blur(img: np.ndarray, sigma: float) -> np.ndarray:
    """Separable Gaussian of ``(h, w, 3)`` with reflected borders."""
    rad = max(1, int(np.ceil(3 * sigma)))
    k = np.exp(-0.5 * (np.arange(-rad, rad + 1) / sigma) ** 2)
    k /= k.sum()
    out = img
    for axis in (0, 1):
        pad = [(0, 0)] * img.ndim
        pad[axis] = (rad, rad)
        p = np.pad(out, pad, mode="reflect") if out.shape[axis] > rad else np.pad(out, pad, mode="edge")
        acc = np.zeros_like(out)
        for i, kv in enumerate(k):
            acc += kv * np.take(p, np.arange(i, i + out.shape[axis]), axis=axis)
        out = acc
    return out


def median3(img: np.ndarray) -> np.ndarray:
    """3×3 median of each channel of ``(h, w, 3)`` (edges replicated): isolated outliers (hot pixels) removed."""
    h, w = img.shape[:2]
    p = np.pad(img, ((1, 1), (1, 1), (0, 0)), mode="edge")
    return np.median(np.stack([p[i:i + h, j:j + w] for i in range(3) for j in range(3)]), axis=0)


def _minkowski(v: np.ndarray, p: float) -> np.ndarray:
    v = np.abs(v.reshape(-1, v.shape[-1]))
    scale = v.max(axis=0)
    scale[scale <= 0] = 1.0
    return scale * np.mean((v / scale) ** p, axis=0) ** (1.0 / p)


def illuminant(img: np.ndarray, method: str, saturated: float = 0.95) -> np.ndarray:
    """The illuminant ``e`` (3,) of a sequence image ``img`` ``(h, w, 3)`` (mean rates) by ``method`` (:data:`ESTIMATORS`).

    ``saturated``: cells with a channel at or above this rate (spikes per tick) are left out of white-patch (a
    clipped channel has no colour). May hold zeros (a channel without spikes): the caller fills those in.
    """
    img = np.asarray(img, dtype=np.float64)
    if method == "gray-world":
        return img.reshape(-1, 3).mean(axis=0)
    if method == "typical":
        return np.array(TYPICAL_RESPONSE, dtype=np.float64)
    if method != "combined" and min(img.shape[:2]) >= 3:
        img = median3(img)  # hot pixels: an isolated bright cell would be the brightest patch and the strongest edge
    if method == "shades-of-gray":
        return _minkowski(img, MINKOWSKI_P)
    if method in ("gray-edge", "gray-edge-2"):
        if min(img.shape[:2]) < 4:  # too small for derivatives
            return img.reshape(-1, 3).mean(axis=0)
        b = _blur(img, EDGE_SIGMA)
        gy, gx = np.gradient(b, axis=(0, 1))
        if method == "gray-edge":
            mag = np.sqrt(gx * gx + gy * gy)
        else:
            gyy = np.gradient(gy, axis=0)
            gxx = np.gradient(gx, axis=1)
            gxy = np.gradient(gx, axis=0)
            mag = np.sqrt(gxx * gxx + gyy * gyy + 2 * gxy * gxy)
        return _minkowski(mag[1:-1, 1:-1], MINKOWSKI_P)
    if method == "combined":
        parts = [illuminant(img, m, saturated) for m in ("gray-edge", "white-patch", "shades-of-gray")]
        parts = [p / n for p in parts if (n := float(np.linalg.norm(p))) > 0 and np.isfinite(n)]
        if not parts:
            return img.reshape(-1, 3).mean(axis=0)
        return np.exp(np.mean([np.log(np.maximum(p, 1e-12)) for p in parts], axis=0))
    if method == "white-patch":
        flat = img.reshape(-1, 3)
        ok = flat.max(axis=1) < saturated
        pool = flat[ok] if ok.sum() >= 16 else flat
        m = pool.mean(axis=0)
        s = (pool / np.where(m > 0, m, 1.0)).sum(axis=1)  # brightness relative to each channel's mean: no channel favoured
        n = max(1, int(round(BRIGHT_FRACTION * s.size)))
        return pool[np.argsort(s)[-n:]].mean(axis=0)
    raise ParameterError(f"unknown white-balance estimator {method!r}; use one of {', '.join(ESTIMATORS)}.")


def channel_floors(img: np.ndarray) -> np.ndarray:
    """Each channel's floor in a sequence image ``(h, w, 3)`` (spikes per tick): the :data:`DARK_PERCENTILE` th
    percentile of the mean rates of :data:`DARK_BLOCK` × :data:`DARK_BLOCK`-cell blocks; float64 ``(3,)``, zeros for an
    empty image."""
    img = np.asarray(img, dtype=np.float64)
    k = min(DARK_BLOCK, img.shape[0], img.shape[1])
    if k < 1:
        return np.zeros(3)
    h, w = img.shape[0] // k * k, img.shape[1] // k * k
    blocks = img[:h, :w].reshape(h // k, k, w // k, k, 3).mean(axis=(1, 3)).reshape(-1, 3)
    return np.percentile(blocks, DARK_PERCENTILE, axis=0)


def dark_level(img: np.ndarray) -> float:
    """The sensor's dark rate as seen in a sequence image ``(h, w, 3)`` (spikes per tick): the lowest of the
    :func:`channel_floors`.

    A photosite fires at its dark rate where the scene is black; the dark rate is the same in every channel (the
    colour filter does not see it), so the darkest blocks of the least sensitive channel measure it. A scene with no
    black anywhere gives more than the dark rate (its darkest patch's rate). 0 for an image too small for one block.
    """
    return float(channel_floors(img).min())


def angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    """Angle in degrees between two RGB vectors (0 when either is zero)."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    na, nb = float(np.linalg.norm(a)), float(np.linalg.norm(b))
    if na <= 0 or nb <= 0:
        return 0.0
    return float(np.degrees(np.arccos(np.clip(a @ b / (na * nb), -1.0, 1.0))))


def toward_typical(e: np.ndarray, sigma: float) -> tuple[np.ndarray, float]:
    """An illuminant estimate ``e`` (3,) of error σ ``sigma`` (log units) combined with the typical response.

    In log chromaticity (log R/G, log B/G) the prior is a mixture: weight :data:`PRIOR_WEIGHT` on a Gaussian of σ
    :data:`PRIOR_SIGMA` around :data:`~spikeview.cfa.TYPICAL_RESPONSE`, :data:`NEUTRAL_WEIGHT` on one of the same σ
    around a neutral response (R = G = B: files made from display-referred RGB), the rest on a broad one (σ
    :data:`PRIOR_BROAD`) around the typical response. The result is the posterior mean: for each component, the
    precision-weighted mean of ``e`` and its centre, times the probability of that component given ``e``. So an
    estimate near the typical response moves most of the way to it, one near neutral toward neutral, and one far off
    both (a sensor unlike either, if the estimator is right) is mostly kept.

    Returns:
        the illuminant (float64 (3,), G = 1) and the prior's share of it (0–1). ``e`` with a channel that is not
        positive is returned unchanged, with share 0.
    """
    e = np.asarray(e, dtype=np.float64).reshape(3)
    if not (np.isfinite(e).all() and (e > 0).all()):
        return e, 0.0
    d = np.log(e[[0, 2]] / e[1])
    p = np.log(np.asarray(TYPICAL_RESPONSE, dtype=np.float64)[[0, 2]])
    s2d, s2p = float(sigma) ** 2, PRIOR_SIGMA ** 2

    def evidence(centre: np.ndarray, s2: float) -> float:  # the 2-D Gaussian density of d − centre, variance s2 per axis
        return float(np.exp(-0.5 * float(np.sum((d - centre) ** 2)) / s2) / (2 * np.pi * s2))

    neutral = np.zeros(2)
    near = PRIOR_WEIGHT * evidence(p, s2d + s2p)
    flat = NEUTRAL_WEIGHT * evidence(neutral, s2d + s2p)
    far = (1 - PRIOR_WEIGHT - NEUTRAL_WEIGHT) * evidence(p, s2d + PRIOR_BROAD ** 2)
    total = near + flat + far
    if total <= 0:
        return e / e[1], 0.0
    # the posterior mean: each component moves d toward its centre by its own precision weight, weighted by how
    # well it explains d (the broad one too, by little: a sensor unlike either is mostly kept)
    lam, lam_b = s2d / (s2d + s2p), s2d / (s2d + PRIOR_BROAD ** 2)
    u = d + (lam * near * (p - d) + lam * flat * (neutral - d) + lam_b * far * (p - d)) / total
    return np.array([np.exp(u[0]), 1.0, np.exp(u[1])]), float(lam * (near + flat) / total)


def _typical_text() -> str:
    r, g, b = TYPICAL_RESPONSE
    return f"R {r:g} / G {g:g} / B {b:g}"


@dataclass
class WhiteBalance:
    """A sequence's white balance: which estimator gave the gains and why.

    Attributes:
        method: the estimator used (:data:`ESTIMATORS`, ``"profile"`` or ``"fixed"``).
        illuminant: ``(3,)`` raw R, G, B rate of a neutral surface (up to scale), or ``None`` for fixed gains.
        reason: one sentence (the plan and the CLI print it).
    """

    method: str
    illuminant: np.ndarray | None
    reason: str


def gains_from_illuminant(e: np.ndarray, means: np.ndarray) -> np.ndarray:
    """Gains ``α_c ∝ 1/e_c`` scaled so that ``Σ α_c · mean_c = 3`` (gray-world's level); float64 (3,).

    A channel whose illuminant is zero or not finite gets the mean gain of the others (as gray-world does).
    """
    e = np.asarray(e, dtype=np.float64).reshape(3)
    ok = np.isfinite(e) & (e > 0)
    a = np.ones(3)
    a[ok] = 1.0 / e[ok]
    if not ok.all():
        a[~ok] = a[ok].mean() if ok.any() else 1.0
    level = float(a @ np.asarray(means, dtype=np.float64))
    return a * (3.0 / level) if level > 0 and np.isfinite(level) else a


def choose(img: np.ndarray, method: str, halves: tuple[np.ndarray, np.ndarray] | None = None,
           ticks: int | None = None) -> WhiteBalance:
    """The white balance of a sequence image by ``method`` (an estimator or ``auto``), with its reason.

    ``halves``: the sequence image of the even and of the odd sampled windows (``auto``'s uncertainty; ``None``: no
    uncertainty is known, 0). ``ticks``: how many ticks ``img`` averages (``auto``'s spike count; ``None``: not
    checked).
    """
    if method != "auto":
        why = f"white balance {method} (as asked)" if method != "typical" else (
            f"white balance typical: the typical spike-camera response ({_typical_text()}), as asked")
        return WhiteBalance(method, illuminant(img, method), why)
    gw = illuminant(img, "gray-world")
    dark = None
    if ticks is not None:
        spikes = float(np.asarray(img, dtype=np.float64).mean()) * ticks
        if spikes < MIN_SPIKES:
            dark = spikes
    co = illuminant(img, "combined")
    ok = gw > 0
    d = angle_deg(co[ok] / gw[ok], np.ones(int(ok.sum()))) if ok.sum() >= 2 else 0.0
    u, sigma = 0.0, COMBINED_SIGMA
    if halves is not None:
        a, b = (illuminant(h, "combined") for h in halves)
        okh = (a > 0) & (b > 0)
        u = angle_deg(a[okh] / b[okh], np.ones(int(okh.sum()))) if okh.sum() >= 2 else 0.0
        if okh.all():  # combined's own noise, in log chromaticity: half the distance between the halves' estimates
            split = np.log(a[[0, 2]] / a[1]) - np.log(b[[0, 2]] / b[1])
            sigma = float(np.hypot(COMBINED_SIGMA, np.linalg.norm(split) / 2))
    if dark is not None:
        # a dark scene: its mean holds the sensor's dark rate, the same in every channel, which pulls gray-world
        # toward neutral while the edges and highlights do not see it; the test compares them without it
        floor = dark_level(img)
        lifted = gw - floor
        okd = lifted > 0
        dd = angle_deg(co[okd] / lifted[okd], np.ones(int(okd.sum()))) if okd.sum() >= 2 else 0.0
        if dd <= DARK_AGREE_DEG or dd <= NOISE_FACTOR * u:
            return WhiteBalance("gray-world", gw, f"white balance auto → gray-world: a dark scene ({dark:.1f} spikes "
                                                 f"per photosite) whose mean, less the dark rate {floor:.2g} spikes "
                                                 f"per tick, agrees with its edges and highlights within {dd:.1f}° "
                                                 f"(≤ {DARK_AGREE_DEG:g}°, or twice their noise {u:.1f}°)")
        e, w = toward_typical(co, sigma)
        return WhiteBalance("combined+typical", e, f"white balance auto → combined (gray-edge, white-patch, "
                                                   f"shades-of-gray), {_pulled(co, e, w)}: a dark scene ({dark:.1f} "
                                                   f"spikes per photosite) whose mean, less the dark rate {floor:.2g} "
                                                   f"spikes per tick, is {dd:.1f}° off its edges and highlights "
                                                   f"(> {DARK_AGREE_DEG:g}°, noise {u:.1f}°), a colourful scene")
    if d <= AGREE_DEG:
        return WhiteBalance("gray-world", gw, f"white balance auto → gray-world: edges, highlights and the scene's mean "
                                             f"agree within {d:.1f}° (≤ {AGREE_DEG:g}°), the scene averages to gray")
    if d <= NOISE_FACTOR * u:
        return WhiteBalance("gray-world", gw, f"white balance auto → gray-world: edges and highlights are {d:.1f}° off "
                                             f"the scene's mean, but they vary by {u:.1f}° between halves of the "
                                             "sequence (too noisy to trust)")
    e, w = toward_typical(co, COMBINED_SIGMA)
    return WhiteBalance("combined+typical", e, f"white balance auto → combined (gray-edge, white-patch, "
                                               f"shades-of-gray), {_pulled(co, e, w)}: the scene's mean is {d:.1f}° "
                                               f"off its edges and highlights (> {AGREE_DEG:g}°, uncertainty "
                                               f"{u:.1f}°), a colourful scene")


def _pulled(e: np.ndarray, post: np.ndarray, w: float) -> str:
    """How far :func:`toward_typical` moved estimate ``e`` to ``post``, in words: toward the centre it came nearer to
    (the typical response or a neutral one), and the prior's share ``w``."""
    typ = np.asarray(TYPICAL_RESPONSE, dtype=np.float64)
    closer_typ = angle_deg(e, typ) - angle_deg(post, typ)
    closer_neutral = angle_deg(e, np.ones(3)) - angle_deg(post, np.ones(3))
    moved = angle_deg(e, post)
    if max(closer_typ, closer_neutral) <= 0:
        return f"moved {moved:.1f}° by the prior on spike cameras' responses (its share {w:.0%})"
    if closer_neutral > closer_typ:
        toward = "a neutral response (R = G = B, as files made from display-referred RGB frames have)"
    else:
        toward = f"the typical spike-camera response ({_typical_text()})"
    return f"pulled {moved:.1f}° toward {toward} (the prior's share {w:.0%})"

"""The guided colour frame keeps the colour balance its gains decided (gray-world or a camera profile).

Q rounds each photosite's rate to its window's count levels in the **raw** domain, and its soft floor (Q(0) ≈ 0.12 of a
level at k = 20) crushes a rate of a fraction of one spike a window towards 0. At a low rate the less sensitive Bayer
channels (R, B) hold the smallest counts and are crushed most, so after the colour cast's gains a gray scene comes out
green: a gray `camera` scene (the simulator's sensor, R 0.6 / G 1 / B 0.5) at 0.02 spikes per tick was 14.5° off, at
0.05 7.7°,
where the TFP frame with the same gains is 3.5° and 3.2° off (``benchmarks/results/colour.md``, section 6).

Where the sequence's white balance is gray-world (its gains are gray-world's, whether chosen by ``auto``, asked for,
or recorded in a preset) and the plan turned Q on, :func:`keep_balance` scales the finished frame's R and B so that
each channel's mean over the frame equals the data's: the mean of the window's corrected rates ``y · α_c / η`` over
that channel's photosites (an unbiased count mean), with G, and so the exposure, unchanged. The same where a camera
profile corrected the rates and its colour response gave the gains: there Q is off, but the frame is clipped at 0
while a dark-subtracted rate is noise around 0 in a dark area, which lifts each channel's black by its own noise
(with the profile, WB on the colour bench: coffee 0.6° → 0.2°, coffee*green 1.1° → 0.4°, the bench's hubble 1.4° →
0.6°, astronaut_dark 1.2° → 0.6°; ``colour.md`` section 6). Pixels at the top of the range (≥ :data:`CLIPPED` in any
channel) are left out of both means; a channel whose photosites hold fewer than :data:`MIN_SPIKES` spikes (a small
region of interest in a dark capture) leaves the frame as it is, and the gains are kept within
[1/:data:`MAX_GAIN`, :data:`MAX_GAIN`].

Not for the other white balances: where a blind estimator other than gray-world gave the gains (a colourful scene)
the sampler's colour was measured closer to the truth than the data's (``colour.md`` section 6); fixed gains are
left as the sampler makes them.
"""

from __future__ import annotations

import numpy as np

from spikeview.guided.observation import Observation

#: pixels with a channel at or above this value (the sampler's frame is in [0, 1]) are left out of the means
CLIPPED = 0.98
#: each channel's photosites must hold at least this many spikes (its mean then moves by ≤ 5 % from shot noise; the
#: bench's 128² coffee_dark holds 906 in its B photosites, and its white balance with a profile went 3.0° → 1.2°)
MIN_SPIKES = 400.0
#: the gains stay within [1/MAX_GAIN, MAX_GAIN]
MAX_GAIN = 4.0


def balance_gains(x: np.ndarray, obs: Observation) -> np.ndarray | None:
    """``(3,)`` gains (G = 1) that give frame ``x`` ``(H, W, 3)`` the channel means of observation ``obs``, or ``None``
    (monochrome, no gains α, too few spikes, nothing unclipped)."""
    if obs.cfa is None or obs.alpha is None or x.ndim != 3 or x.shape[:2] != obs.shape:
        return None
    cm = obs.channel_map()
    corrected = obs.y.astype(np.float64) / obs.gains()[cm]
    spikes = obs.y.astype(np.float64) * obs.effective_window
    ok = (x < CLIPPED).all(axis=-1)
    g = np.ones(3)
    for c in (0, 1, 2):
        sites = (cm == c) & ok
        if not sites.any() or float(spikes[sites].sum()) < MIN_SPIKES:
            return None
        out = float(x[..., c][sites].mean())
        if not out > 0:
            return None
        g[c] = float(corrected[sites].mean()) / out
    if not (np.isfinite(g).all() and g[1] > 0):
        return None
    return np.clip(g / g[1], 1.0 / MAX_GAIN, MAX_GAIN)


def keep_balance(x: np.ndarray, obs: Observation) -> np.ndarray:
    """``x`` with :func:`balance_gains` applied (clipped to [0, 1]), or ``x`` itself where there are none."""
    g = balance_gains(x, obs)
    if g is None:
        return x
    return np.clip(x * g.astype(np.float32), 0.0, 1.0).astype(np.float32, copy=False)

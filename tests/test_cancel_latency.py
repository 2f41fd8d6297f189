"""Cancel at full resolution (issue 15, item 3): a set cancel flag stops a running prior pass within
one layer of one strip (a 1000×1000 FFDNet pass is seconds, a layer of a strip a tenth of that), the
guided sampler raises the same :class:`~spikeview.errors.Cancelled` it raises between steps, and a
tiled run reports the whole frame filling in. Monochrome and Bayer (RGGB) alike.

No wall-clock assertions: the flag is set from another thread at a known point of the pass (a hook
on the strip/layer loop hands over to the test thread and waits until the flag is set), and the
tests count the strips and layers that ran after it.
"""

from __future__ import annotations

import threading

import numpy as np
import pytest
import torch

from spikeview.errors import Cancelled, cancel_scope, check_cancelled
from spikeview.guided import tiles
from spikeview.guided.config import GuidedConfig
from spikeview.guided.observation import Observation
from spikeview.guided.priors import ffdnet
from spikeview.guided.priors.ffdnet import FFDNetDenoiser
from spikeview.guided.sampler import GuidedSampler
from spikeview.io.source import ArraySource

GAINS = np.array([1.0, 1.0, 1.0])
STRIP = 16  # half-resolution rows per strip in these tests (the library's 256 needs a 1000-row frame)
COLOR = pytest.mark.parametrize("color", [True, False], ids=["bayer", "mono"])


def _net(color: bool) -> FFDNetDenoiser:
    return FFDNetDenoiser(color=color, pretrained=False, generator=torch.Generator().manual_seed(3))


def _obs(shape: tuple[int, int], cfa: str | None, rate: float = 0.3, ticks: int = 40) -> Observation:
    rng = np.random.default_rng(0)
    src = ArraySource(rng.random((ticks,) + shape) < rate, cfa=cfa)
    return Observation.from_source(src, ticks // 2, 10, alpha=GAINS if cfa else None, eta=2.0, radius=0)


class _Trap:
    """Counts the strips and layers a pass runs; at strip ``strip`` (0-based), layer ``layer`` (``None``:
    once the strip is done), it hands over to another thread, which sets the cancel flag, and goes on
    only once the flag is set."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch, flag: threading.Event, strip: int, layer: int | None):
        self.flag, self.strip, self.layer = flag, strip, layer
        self.strips: list[int] = []  # layers fetched per strip
        self.layers_after_flag = 0
        self.reached, self.go = threading.Event(), threading.Event()
        body = FFDNetDenoiser._body
        trap = self

        class Layers(list):
            def __iter__(self):
                for i, item in enumerate(list.__iter__(self)):
                    if trap.flag.is_set():
                        trap.layers_after_flag += 1
                    trap.strips[-1] += 1
                    if len(trap.strips) - 1 == trap.strip and i == trap.layer:
                        trap.hand_over()
                    yield item

        def counting_body(feats, layers, inplace, fast=False, scratch=None):
            self.strips.append(0)
            out = body(feats, Layers(layers), inplace, fast, scratch)
            if len(self.strips) - 1 == self.strip and self.layer is None:
                self.hand_over()
            return out

        monkeypatch.setattr(FFDNetDenoiser, "_body", staticmethod(counting_body))
        monkeypatch.setattr(ffdnet, "STRIP_ROWS", STRIP)
        monkeypatch.setattr(ffdnet, "STRIP_BYTES", 0)  # strips of STRIP_ROWS rows, whatever their bytes

    def hand_over(self) -> None:
        self.reached.set()
        assert self.go.wait(30), "the test thread did not set the flag"

    def set_flag_from_another_thread(self) -> threading.Thread:
        def setter():
            if self.reached.wait(60):
                self.flag.set()
            self.go.set()

        th = threading.Thread(target=setter, name="canceller")
        th.start()
        return th


def _run_in_scope(fn, flag):
    with cancel_scope(flag):
        return fn()


def _cancel_a_four_strip_pass(monkeypatch, color, match, strip, layer):
    """Run one prior pass over 4 strips while another thread sets the flag at (``strip``, ``layer``);
    the pass must raise ``Cancelled`` (message matching ``match``). Returns the trap (what ran)."""
    net = _net(color)
    x = torch.rand(1, net.channels, 8 * STRIP, 40, generator=torch.Generator().manual_seed(1))  # 4 strips
    flag = threading.Event()
    trap = _Trap(monkeypatch, flag, strip=strip, layer=layer)
    th = trap.set_flag_from_another_thread()
    with pytest.raises(Cancelled, match=match):
        _run_in_scope(lambda: net(x, 20 / 255), flag)
    th.join()
    return net, trap


@COLOR
def test_prior_pass_stops_between_strips(monkeypatch, color):
    net, trap = _cancel_a_four_strip_pass(monkeypatch, color, "between the strips", strip=0, layer=None)
    assert trap.strips == [net.n_layers] and trap.layers_after_flag == 0  # strip 2 never started


@COLOR
@pytest.mark.parametrize("layer", [0, 5], ids=["first-layer", "mid-strip"])
def test_prior_pass_stops_within_one_layer_of_the_strip_it_is_in(monkeypatch, color, layer):
    _, trap = _cancel_a_four_strip_pass(monkeypatch, color, "inside a prior pass", strip=1, layer=layer)
    # the flag was set while layer `layer` of strip 2 was being fetched: no layer was fetched after it,
    # and the fetched one stopped at the check before its convolution; nothing of strips 3 and 4 ran
    assert len(trap.strips) == 2 and trap.strips[1] == layer + 1
    assert trap.layers_after_flag == 0


@COLOR
def test_an_unset_flag_changes_no_number(monkeypatch, color):
    monkeypatch.setattr(ffdnet, "STRIP_ROWS", STRIP)
    monkeypatch.setattr(ffdnet, "STRIP_BYTES", 0)  # strips of STRIP_ROWS rows, whatever their bytes
    net = _net(color)
    x = torch.rand(1, net.channels, 8 * STRIP + 2, 42, generator=torch.Generator().manual_seed(2))
    with torch.no_grad():
        plain = net(x, 15 / 255)
        scoped = _run_in_scope(lambda: net(x, 15 / 255), threading.Event())
    assert torch.equal(plain, scoped)
    check_cancelled("outside any scope")  # a no-op outside a job


@COLOR
def test_sampler_cancel_inside_the_first_prior_pass(monkeypatch, color):
    """The guided sampler's Cancel reaches into the prior: it stops inside step 1 (no step finished,
    no preview sent), with the sampler's own exception."""
    obs = _obs((8 * STRIP, 48), "RGGB" if color else None)
    flag = threading.Event()
    trap = _Trap(monkeypatch, flag, strip=1, layer=3)
    smp = GuidedSampler(prior=_net(color))
    previews: list[int] = []
    th = trap.set_flag_from_another_thread()
    with pytest.raises(Cancelled):
        smp.run(obs, GuidedConfig(precision="float32", steps=4), callback=lambda s, n, im: previews.append(s), cancel=flag)
    th.join()
    assert smp.info.steps == 0 and previews == []
    assert len(trap.strips) == 2 and trap.strips[1] == 4 and trap.layers_after_flag == 0
    # the flag is per job: after it, an uncancelled run of the same sampler runs to the end
    out = smp.run(obs, GuidedConfig(precision="float32", steps=1))
    assert np.isfinite(out).all() and smp.info.steps == 1


@COLOR
def test_tiled_run_reports_the_whole_frame_every_step_and_cancels_between_steps(color, monkeypatch):
    monkeypatch.setattr(tiles, "MAX_AREA", 4096)  # several rectangles
    monkeypatch.setattr(tiles.TileMap, "pays", lambda self: True)  # all tiles full: tiled on purpose
    obs = _obs((64, 160), "RGGB" if color else None)
    smp = GuidedSampler(prior=_net(color))
    p = GuidedConfig(precision="float32", steps=2, tile=64)
    frames: list[tuple[int, np.ndarray]] = []
    out = smp.run(obs, p, callback=lambda s, n, im: frames.append((s, np.array(im, copy=True))))
    shape = obs.shape + ((3,) if color else ())
    assert smp.info.mode == "tiled" and out.shape == shape
    assert len(tiles.tile_spans(64, 64)) * len(tiles.tile_spans(160, 64)) >= 3
    # step-synchronous tiles: every step's preview is the whole frame (every tile stepped once more)
    assert [s for s, _ in frames] == [1, 2] and all(im.shape == shape for _, im in frames)
    assert all(int(((im.mean(axis=-1) if im.ndim == 3 else im).sum(axis=0) > 0).sum()) == shape[1] for _, im in frames)
    np.testing.assert_array_equal(frames[-1][1], out)
    # callbacks change no pixel
    np.testing.assert_array_equal(smp.run(obs, p), out)
    # a flag set after step 1: step 2 never starts
    flag = threading.Event()
    steps_seen: list[int] = []

    def cb(step, _n, _im):
        steps_seen.append(step)
        if step == 1:
            flag.set()

    with pytest.raises(Cancelled, match="at step 2 of 2"):
        smp.run(obs, p, callback=cb, cancel=flag)
    assert steps_seen == [1]

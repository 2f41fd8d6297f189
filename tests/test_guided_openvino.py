"""OpenVINO's float32 backend of the FFDNet prior (issue 15, the optional extra ``openvino``): it gives
torch's float32 numbers (RGB and gray), serves only ``bfloat16-mixed``'s float32 steps, falls back to
torch where it is missing or broken, stops on Cancel inside a pass, and the plan and the output's
metadata name it (Bayer and monochrome alike)."""

from __future__ import annotations

import os
import sys
import threading

import numpy as np
import pytest
import torch

from spikeview.errors import Cancelled, cancel_scope
from spikeview.guided import precision as prec
from spikeview.guided.config import GuidedConfig
from spikeview.guided.observation import Observation
from spikeview.guided.plan import make_plan
from spikeview.guided.priors import ffdnet, ov_backend
from spikeview.guided.priors.ffdnet import FFDNetDenoiser
from spikeview.guided.sampler import GuidedSampler
from test_guided_helpers import make_source

COLOR = pytest.mark.parametrize("color", [True, False], ids=["rgb", "gray"])
CFA = pytest.mark.parametrize("cfa", ["RGGB", None], ids=["bayer", "mono"])
#: OpenVINO's float32 against torch's: measured identical (the same oneDNN kernels); allowed: float32 rounding
TOL = 1e-5


def needs_openvino():
    pytest.importorskip("openvino", reason="the optional extra openvino is not installed (pip install spikeview[openvino])")
    # installed: it must work here (a broken backend fails, not skips)
    assert ov_backend.available(), "openvino imports but the FFDNet stack does not compile or gives other numbers"


def _net(color: bool) -> FFDNetDenoiser:
    return FFDNetDenoiser(color=color, pretrained=False, generator=torch.Generator().manual_seed(3))


class _Spy:
    """Counts the OpenVINO passes (so a silent fallback to torch cannot pass for the backend)."""

    def __init__(self, monkeypatch):
        self.calls = 0
        real = ov_backend.OVStack.run

        def run(stack, feats):
            self.calls += 1
            return real(stack, feats)

        monkeypatch.setattr(ov_backend.OVStack, "run", run)


@pytest.fixture(autouse=True)
def _every_size(monkeypatch):
    """These tests use small frames: let OpenVINO serve every size (the size rule has its own test)."""
    monkeypatch.setattr(ffdnet, "OV_MIN_LAYER_BYTES", 0)
    monkeypatch.setattr(ffdnet, "STRIP_BYTES", 0)  # the strips follow STRIP_ROWS here


def test_small_volumes_stay_in_torch(monkeypatch):
    """OpenVINO only where a layer's output outgrows the allocator's reuse (its gain there is page faults)."""
    needs_openvino()
    net = _net(True)
    spy = _Spy(monkeypatch)
    small, big = torch.rand(1, 3, 16, 16), torch.rand(1, 3, 40, 40)
    # the rule, scaled down: a 20×20×96 float32 layer output is 153,600 bytes
    monkeypatch.setattr(ffdnet, "OV_MIN_LAYER_BYTES", 8 * 8 * 96 * 4)
    with torch.no_grad():
        a = net(small, 0.1, "float32-openvino")
        assert spy.calls == 0
        b = net(big, 0.1, "float32-openvino")
        assert spy.calls == 1
        assert (a - net(small, 0.1, "float32")).abs().max() <= TOL and (b - net(big, 0.1, "float32")).abs().max() <= TOL
    # the real rule: a 256² frame's layers stay in torch, a 1000² frame's strips go to OpenVINO
    monkeypatch.setattr(ffdnet, "OV_MIN_LAYER_BYTES", 32 << 20)
    assert 1 * 128 * 128 * 96 * 4 <= ffdnet.OV_MIN_LAYER_BYTES < 1 * (ffdnet.STRIP_ROWS + 2 * net.n_layers) * 500 * 96 * 4


def _no_openvino(monkeypatch):
    monkeypatch.setattr(ov_backend, "available", lambda: False)


@COLOR
def test_backend_gives_torch_float32_numbers(color, monkeypatch):
    needs_openvino()
    net = _net(color)
    spy = _Spy(monkeypatch)
    g = torch.Generator().manual_seed(4)
    x = torch.rand(1, net.channels, 37, 52, generator=g)  # odd height: padded and cropped as torch does
    sig = torch.full((1, net.channels, 37, 52), 20 / 255) * (0.5 + torch.rand(1, 1, 37, 52, generator=g))  # a map
    with torch.no_grad():
        ref = net(x, sig, "float32")
        got = net(x, sig, "float32-openvino")
        # strips (3-row strips with a halo of one row per layer) and a batch of 2, against torch's whole volume
        xb = torch.rand(2, net.channels, 2 * (3 * 4 + 2 * net.n_layers) + 6, 30, generator=g)
        ref_b = net(xb, 15 / 255, "float32")
        monkeypatch.setattr(ffdnet, "STRIP_ROWS", 3)
        got_b = net(xb, 15 / 255, "float32-openvino")
    assert spy.calls >= 1 + 2  # the whole volume once, then several strips
    assert got.shape == ref.shape and (got - ref).abs().max() <= TOL
    assert got_b.shape == ref_b.shape and (got_b - ref_b).abs().max() <= TOL
    # a real pass, not the identity: the stack changed the image
    assert (got - x).abs().max() > 1e-3


@COLOR
def test_backend_is_not_used_with_autograd_or_float64(color, monkeypatch):
    needs_openvino()
    net = _net(color)
    spy = _Spy(monkeypatch)
    x = torch.rand(1, net.channels, 16, 16, requires_grad=True)
    y = net(x, 0.1, "float32-openvino")
    y.sum().backward()  # gradients still reach the image: the torch path ran
    assert x.grad is not None and spy.calls == 0
    with torch.no_grad():
        d = net(x.detach().double(), 0.1, "float32-openvino")
    assert d.dtype == torch.float64 and spy.calls == 0


def test_falls_back_to_torch_without_openvino(monkeypatch):
    _no_openvino(monkeypatch)
    spy = _Spy(monkeypatch)
    net = _net(True)
    x = torch.rand(1, 3, 20, 24, generator=torch.Generator().manual_seed(5))
    with torch.no_grad():
        assert torch.equal(net(x, 0.1, "float32-openvino"), net(x, 0.1, "float32"))
    assert spy.calls == 0
    sig = np.geomspace(50, 5, 6) / 255
    assert prec.float_backend() == "torch"
    assert prec.step_precisions("bfloat16-mixed", sig) == ["bfloat16-all"] * 3 + ["float32"] * 3
    assert "float32 below (torch oneDNN)" in prec.resolve_precision("bfloat16-mixed")[1]


def test_the_probe_says_no_when_openvino_is_missing_or_broken(monkeypatch):
    monkeypatch.setitem(sys.modules, "openvino", None)  # "import openvino" raises ImportError
    assert ov_backend.version.__wrapped__() == ""
    monkeypatch.setattr(ov_backend, "version", lambda: "")
    assert ov_backend._probe.__wrapped__() is False

    def broken(self, *a, **k):
        raise RuntimeError("no CPU plugin")

    monkeypatch.setattr(ov_backend, "version", lambda: "9.9.9")
    monkeypatch.setattr(ov_backend.OVStack, "__init__", broken)
    assert ov_backend._probe.__wrapped__() is False


def test_float32_stays_torch(monkeypatch):
    """``--precision float32`` is the reference pixels: its steps never go through OpenVINO."""
    assert prec.step_precisions("float32", np.geomspace(50, 5, 6) / 255) == ["float32"] * 6
    assert prec.at_precision(_net(False), "float32").__class__ is FFDNetDenoiser


def test_cancel_inside_an_openvino_pass(monkeypatch):
    needs_openvino()
    monkeypatch.setattr(ov_backend, "POLL_MS", 1)
    net = _net(True)
    stack = ov_backend.stack_for(net)
    feats = torch.rand(1, 15, 200, 200)
    flag = threading.Event()
    flag.set()
    with cancel_scope(flag), pytest.raises(Cancelled, match="OpenVINO"):
        stack.run(feats)
    # the request is usable again afterwards, with the right numbers
    small = feats[:, :, :20, :20]
    with torch.no_grad():
        ref = net._body(small.contiguous(), net._layers(torch.float32, "float32", torch.contiguous_format), inplace=False)
    assert (stack.run(small) - ref).abs().max() <= TOL


@CFA
def test_plan_and_metadata_name_the_backend(cfa, tmp_path, monkeypatch):
    from spikeview.export import read_export_metadata
    from spikeview.io.source import ArraySource
    from spikeview.pipeline import write_sequence
    from spikeview.recipe import Recipe

    src = make_source("texture", 24, 24, ticks=40, cfa=cfa)
    obs = Observation.from_source(src, 20, 10, alpha=np.array([1.6, 1.0, 2.0]) if cfa else None, eta=2.0, radius=0)
    label = prec.backend_label()
    assert label == (f"OpenVINO {ov_backend.version()} from ~600×600, torch below" if ov_backend.available() else "torch oneDNN")
    plan = make_plan(obs, GuidedConfig(precision="bfloat16-mixed"))
    assert f"float32 below ({label})" in plan.reasons["precision"] and label in str(plan)
    # the output's metadata records the plan's precision row, backend included
    rates = np.full((32, 32), 0.4)
    arr = ArraySource(np.random.default_rng(0).random((40,) + rates.shape) < rates, cfa=cfa)
    recipe = Recipe().with_values({"run.method": "guided", "guided.steps": 1, "guided.precision": "bfloat16-mixed",
                                   "guided.temporal_radius": 0, "guided.tile": 0})
    write_sequence(arr, recipe, [20], tmp_path / "f.npy")
    assert f"float32 below ({label})" in read_export_metadata(tmp_path / "f.npy")["plan"]["precision"]
    # without OpenVINO the same row names torch
    _no_openvino(monkeypatch)
    plan = make_plan(obs, GuidedConfig(precision="bfloat16-mixed"))
    assert "float32 below (torch oneDNN)" in plan.reasons["precision"]


@CFA
def test_sampler_frame_is_the_torch_frame(cfa, monkeypatch):
    """The default policy's frame with OpenVINO on its float32 steps = the frame with torch there."""
    needs_openvino()
    src = make_source("texture", 24, 24, ticks=40, cfa=cfa)
    obs = Observation.from_source(src, 20, 10, alpha=np.array([1.6, 1.0, 2.0]) if cfa else None, eta=2.0, radius=0)
    net = _net(cfa is not None)
    cfg = GuidedConfig(precision="bfloat16-mixed", steps=4, t_start=60 / 255, diffusion="always")
    spy = _Spy(monkeypatch)
    smp = GuidedSampler(prior=net)
    with_ov = smp.run(obs, cfg)
    assert spy.calls > 0 and smp.info.precision == "bfloat16-mixed"
    _no_openvino(monkeypatch)
    calls = spy.calls
    with_torch = GuidedSampler(prior=net).run(obs, cfg)
    assert spy.calls == calls
    assert np.abs(with_ov - with_torch).max() <= 1e-4


@CFA
def test_a_failure_during_a_run_falls_back_to_torch(cfa, monkeypatch):
    """OpenVINO failing inside a pass (out of memory, an unusual CPU…) costs time, never the run: that pass
    and every later one run in torch (the same numbers), with one warning; the plan then names torch."""
    needs_openvino()
    monkeypatch.setattr(ov_backend, "_gave_up", None)
    net = _net(cfa is not None)
    x = torch.rand(1, net.channels, 24, 20, generator=torch.Generator().manual_seed(6))

    def broken(stack, feats):
        raise RuntimeError("std::bad_alloc")

    monkeypatch.setattr(ov_backend.OVStack, "run", broken)
    with torch.no_grad():
        ref = net(x, 0.1, "float32")
        with pytest.warns(ov_backend.OpenVINOFallbackWarning, match="bad_alloc"):
            got = net(x, 0.1, "float32-openvino")
        assert (got - ref).abs().max() <= TOL
        assert not ov_backend.available() and ov_backend.stack_for(net) is None
        assert (net(x, 0.1, "float32-openvino") - ref).abs().max() <= TOL  # no second warning (-W error)
    assert prec.float_backend() == "torch"


def test_openvino_strips_are_sized_by_bytes(monkeypatch):
    """OpenVINO reuses its buffers, so its strips are as tall as STRIP_BYTES allows (fewer halos to
    recompute): a whole 1000² frame in one call, a wide one in strips; the numbers do not change."""
    needs_openvino()
    net = _net(False)
    spy = _Spy(monkeypatch)
    x = torch.rand(1, 1, 2 * 40, 24, generator=torch.Generator().manual_seed(8))  # 40 feature rows of 12 columns
    monkeypatch.setattr(ffdnet, "STRIP_ROWS", 1)
    row = 12 * int(net.weight[0].shape[0]) * 4
    with torch.no_grad():
        ref = net(x, 0.1, "float32")
        monkeypatch.setattr(ffdnet, "STRIP_BYTES", (5 + 2 * net.n_layers) * row)  # strips of 5 rows: 8 calls
        a = net(x, 0.1, "float32-openvino")
        assert spy.calls == 8
        monkeypatch.setattr(ffdnet, "STRIP_BYTES", 1 << 30)  # the whole volume: 1 call
        b = net(x, 0.1, "float32-openvino")
        assert spy.calls == 9
    assert (a - ref).abs().max() <= TOL and (b - ref).abs().max() <= TOL
    # the real rule: a 1000² RGB frame (500 feature columns) in one volume, a 2000² one in ~256-row strips
    monkeypatch.undo()
    rgb = 96 * 4
    assert ffdnet.STRIP_BYTES // (500 * rgb) - 2 * 12 >= 500 - 2 * 12
    assert ffdnet.STRIP_BYTES // (1000 * rgb) - 2 * 12 <= 300


def test_openvino_is_imported_without_its_network_telemetry():
    """``import openvino`` imports its model converter, whose telemetry sends an event over the network (and printed
    a child process's traceback on Ctrl-C): spikeview's import leaves the telemetry package out, the converter's own
    no-op stub in its place. In a fresh process, as the CLI starts."""
    import subprocess

    pytest.importorskip("openvino", reason="the optional extra openvino is not installed")

    code = ("import sys; from spikeview.guided.priors import ov_backend as o; assert o.version(); o.available(); "
            "print(sorted(m for m in sys.modules if 'telemetry' in m))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300,
                         env={**os.environ, "CI": ""})
    assert out.returncode == 0, out.stderr
    assert "openvino_telemetry" not in out.stdout and "telemetry_stub" in out.stdout, out.stdout

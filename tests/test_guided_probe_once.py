"""OpenVINO's one-time probe runs once when two threads ask at once (the app's preload and its worker),
and a guided run whose weights are missing says so in one sentence."""

from __future__ import annotations

import numpy as np


def test_probe_runs_once_when_two_threads_ask(monkeypatch):
    import threading

    from spikeview.guided.priors import ov_backend

    calls = []
    gate = threading.Event()

    def slow_probe():
        calls.append(1)
        gate.wait(2)
        return False

    cache = {}

    def cached():
        if "v" not in cache:
            cache["v"] = slow_probe()
        return cache["v"]

    monkeypatch.setattr(ov_backend, "_probe", cached)
    t = threading.Thread(target=ov_backend.available)
    t.start()
    while not calls:
        pass
    u = threading.Thread(target=ov_backend.available)
    u.start()
    gate.set()
    t.join(5)
    u.join(5)
    assert calls == [1]


def test_missing_weights_still_get_the_runs_sentence(tmp_path, capsys):
    from spikeview.cli.main import main

    src = tmp_path / "cap.npy"
    np.save(src, (np.random.default_rng(0).random((40, 16, 16)) < 0.3).astype(np.uint8))
    out = tmp_path / "g.exr"
    rc = main(["reconstruct", str(src), "--cfa", "RGGB", "--method", "guided", "--at", "20", "--model",
               str(tmp_path / "nosuch.pth"), "--out", str(out)])
    err = capsys.readouterr().err
    assert rc == 1 and "nosuch.pth" in err and "Traceback" not in err and "this is a bug" not in err, err
    assert not out.exists()

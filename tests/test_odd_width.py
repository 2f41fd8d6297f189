"""An odd width under a colour filter is said wherever the capture comes from (issue 29): `simulate` wrote one
without a word, and reading it back through its own sidecar (trusted: no rate check) said nothing."""

from __future__ import annotations

import numpy as np
import pytest

from spikeview.cli.main import main


@pytest.mark.parametrize("cfa", ["RGGB", "none"])
def test_simulate_and_reading_back_warn_of_an_odd_width_with_a_colour_filter(tmp_path, capsys, cfa):
    from spikeview.io import open_source
    from spikeview.sim import SimConfig, StaticScene, simulate_to_file

    img = np.random.default_rng(0).random((64, 63, 3)).astype(np.float32)
    np.save(tmp_path / "img.npy", img)
    out = tmp_path / "odd.dat"
    # the CLI's simulate of an image file of odd width (63 x 64: whole bytes per frame)
    simulate_to_file(StaticScene(img, srgb=False), SimConfig(n_ticks=16, cfa=cfa, seed=0), out)
    with open_source(str(out)) as src:
        warned = [w for w in src.info.warnings if "odd width (63)" in w]
    assert bool(warned) == (cfa != "none")
    assert main(["info", str(out)]) == 0
    said = capsys.readouterr().out
    assert ("odd width (63)" in said) == (cfa != "none")


def test_the_simulate_command_says_it(tmp_path, capsys):
    pytest.importorskip("OpenImageIO")
    import OpenImageIO as oiio

    png = tmp_path / "img.png"
    a = (np.random.default_rng(0).random((64, 63, 3)) * 255).astype(np.uint8)
    o = oiio.ImageOutput.create(str(png))
    o.open(str(png), oiio.ImageSpec(63, 64, 3, "uint8"))
    o.write_image(a)
    o.close()
    assert main(["simulate", str(png), "--ticks", "16", "--out", str(tmp_path / "odd.dat")]) == 0
    err = capsys.readouterr().err
    assert "warning: a colour filter (RGGB) with an odd width (63)" in err
    assert main(["simulate", str(png), "--ticks", "16", "--cfa", "none", "--out", str(tmp_path / "mono.dat")]) == 0
    assert "odd width" not in capsys.readouterr().err

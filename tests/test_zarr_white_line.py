"""A ``.zarr`` run and its ``spikeview export`` print the same white-point line as the plain file run
(value and unit), monochrome and Bayer."""

from __future__ import annotations

import re

import numpy as np
import pytest

pytest.importorskip("zarr")

from spikeview.cli.main import main  # noqa: E402
from spikeview.io.plain import write_plain  # noqa: E402

LINE = re.compile(r"^white point (\S+) \(([^;]+); ([^)]+)\): EXR keeps values above it", re.M)


@pytest.mark.parametrize("cfa", ["none", "RGGB"])
def test_zarr_and_export_print_the_white_point_of_the_plain_run(tmp_path, capsys, cfa):
    rng = np.random.default_rng(3)
    ramp = np.linspace(0.05, 0.9, 16, dtype=np.float32)[None, None, :]
    write_plain(tmp_path / "c.dat", (rng.random((60, 16, 16)) < ramp).astype(np.uint8))
    common = [str(tmp_path / "c.dat"), "--width", "16", "--height", "16", "--cfa", cfa, "--range", "10:50:10"]

    assert main(["reconstruct", *common, "--out", str(tmp_path / "ref.npy")]) == 0
    plain = LINE.findall(capsys.readouterr().err)
    assert len(plain) == 1
    unit = "spikes per tick" if cfa == "none" else "Y·α/η, rates corrected for the colour cast"
    assert plain[0][1] == unit

    assert main(["reconstruct", *common, "--out", str(tmp_path / "s.zarr")]) == 0
    zarr_lines = LINE.findall(capsys.readouterr().err)
    assert zarr_lines == [plain[0]]  # same value, unit and origin

    assert main(["export", str(tmp_path / "s.zarr"), "--out", str(tmp_path / "e.npy")]) == 0
    exported = LINE.findall(capsys.readouterr().err)
    assert exported == [(plain[0][0], unit, "recorded in s.zarr")]
    np.testing.assert_array_equal(np.load(tmp_path / "e.npy"), np.load(tmp_path / "ref.npy"))

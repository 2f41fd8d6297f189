"""The registry of ``spikeview`` sub-commands.

Each entry names its one-line help and the module that implements it. A command module holds
``add_args(parser)`` and ``run(args) -> int``, optionally ``GEOMETRY = True`` (it reads a spike file:
the geometry flags are added) and an ``EPILOG`` (examples under ``--help``). Command modules import
what they share from :mod:`spikeview.cli._common`, never from each other, and heavy modules only
inside ``run``. A new command is a module and a line here.
"""

from __future__ import annotations

from typing import NamedTuple


class Command(NamedTuple):
    help: str
    module: str


COMMANDS: dict[str, Command] = {
    "app": Command("open the desktop app (the default when no command is given)", "spikeview.cli.app"),
    "info": Command("describe a spike file: format, geometry, duration, per-channel firing rates", "spikeview.cli.info"),
    "simulate": Command("simulate a chromatic spike capture (with ground truth) from a video, images or the demo scene",
                        "spikeview.cli.simulate"),
    "reconstruct": Command("reconstruct frames from spikes and export them (.npy, .exr, .png, .mp4)",
                           "spikeview.cli.reconstruct"),
    "export": Command("export a .zarr store of a long capture to .mp4, .npy, .exr or .png", "spikeview.cli.export_cmd"),
    "calibrate": Command("measure a camera profile (dark rate, hot pixels, flat field, colour response) from dark and "
                         "flat captures, for --camera", "spikeview.cli.calibrate"),
    "bench": Command("error against run time of TFP, TFI, the strong baseline and the guided sampler "
                     "(PSNR/SSIM vs. ground truth)", "spikeview.cli.bench"),
}

"""spikeview: viewer, simulator and zero-shot guided reconstruction for chromatic spike cameras.

Conventions used throughout the package (see ``../shared/DOMAIN.md``):

* A spike stream is a binary array ``S[t, y, x]`` of shape ``(T, H, W)``, ``t`` in *ticks*
  (one readout, 50 µs at the default 20 kHz), rows top-to-bottom **after** orientation flips.
* A CFA is named by its explicit top-left 2×2 in reading order after the flips (``"RGGB"``:
  R at (0, 0), G at (0, 1), G at (1, 0), B at (1, 1)); ``None`` means monochrome.
* Reconstructed frames are float32 in ``[0, 1]``, ``(H, W, 3)`` for colour or ``(H, W)`` for mono.

Heavy dependencies (torch, Qt, OpenImageIO, PyAV) are imported lazily by the modules that need them.
"""

__version__ = "0.1.0"

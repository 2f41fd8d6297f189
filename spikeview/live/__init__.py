"""Live capture: USB and simulated cameras, the ring buffer between acquisition and display, recording.

Quick start::

    from spikeview.live import CameraConfig, UsbCamera, SimCamera

    cam = UsbCamera(CameraConfig(vid=0x1234, pid=0x5678)).start()   # or SimCamera.demo().start()
    cam.start_recording("capture.dat")        # plain .dat + sidecar, written by its own thread
    frames = cam.latest(41)                   # the newest 41 ticks, (41, H, W) uint8 0/1
    print(cam.status, cam.status_message)     # a LiveStatus and one sentence (with the fix)
    cam.close()                               # stops, finalises the recording, releases the device

* :mod:`spikeview.live.source` — :class:`LiveSource` (a growing :class:`~spikeview.io.source.SpikeSource`),
  :class:`LiveStatus`;
* :mod:`spikeview.live.usb` — :class:`UsbCamera`, :class:`CameraConfig`, :func:`list_usb_devices`;
* :mod:`spikeview.live.simcam` — :class:`SimCamera` (a simulated scene or a spike file, paced);
* :mod:`spikeview.live.ring` — :class:`FrameRing`;
* :mod:`spikeview.live.recorder` — :class:`Recorder`;
* :mod:`spikeview.live.decode` — stream decoders, ROI/decimation (:class:`FrameShaper`);
* :mod:`spikeview.live.mockusb` — :class:`MockBackend`, a scripted pyusb backend for tests and demos.

Names are imported lazily (pyusb and the simulator load on first use). Nothing here imports Qt.
"""

from __future__ import annotations

from spikeview._lazy import lazy_exports

_EXPORTS = {  # name → module, imported on first use
    **dict.fromkeys(["LiveSource", "LiveStatus", "close_all"], "spikeview.live.source"),
    **dict.fromkeys(["FrameRing", "RingOverrun"], "spikeview.live.ring"),
    **dict.fromkeys(["Recorder", "RecordingSummary"], "spikeview.live.recorder"),
    **dict.fromkeys(["FrameShaper", "Raw1MStream", "PlainStream", "raw1m_to_packed"], "spikeview.live.decode"),
    **dict.fromkeys(["CameraConfig", "UsbCamera", "UsbDeviceInfo", "list_usb_devices", "udev_rule"], "spikeview.live.usb"),
    **dict.fromkeys(["SimCamera"], "spikeview.live.simcam"),
    **dict.fromkeys(["MockBackend", "Fault"], "spikeview.live.mockusb"),
}

__all__ = list(_EXPORTS)


__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())

"""The app's state and actions without Qt: what the desktop app shows and does, testable headless.

* :mod:`spikeview.session.model` — the session (capture, tick, parameters, marks, ROI, undo) and its events;
* :mod:`spikeview.session.core` — the app's adapters over the library (stream frames, display mapping, rates);
* :mod:`spikeview.session.jobs` — the background jobs as plain functions (previews, the guided run, export);
* :mod:`spikeview.session.presets` — the session's recipe and presets.

:mod:`spikeview.gui` (the only Qt user) is a view of this package: its workers run these jobs and its panels show
and change the session. Nothing here imports Qt or :mod:`spikeview.gui` (tests/test_architecture.py).
"""

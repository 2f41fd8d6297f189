"""The spikeview desktop app (PySide6 + pyqtgraph): the only package that imports Qt.

* :mod:`spikeview.gui.model` — the plain-Python session model (no Qt; tests drive it headless);
* :mod:`spikeview.gui.core`, :mod:`spikeview.gui.jobs`, :mod:`spikeview.gui.presets` — Qt-free adapters
  over the core packages and the background jobs;
* :mod:`spikeview.gui.workers`, :mod:`spikeview.gui.controller` — QThread workers and the glue that
  schedules jobs from model events;
* :mod:`spikeview.gui.panels`, :mod:`spikeview.gui.main_window`, :mod:`spikeview.gui.app` — the views.

Nothing is imported here, so ``import spikeview.gui.model`` stays free of Qt.
"""

"""The spikeview desktop app (PySide6 + pyqtgraph): the only package that imports Qt.

* :mod:`spikeview.session` (a package of its own, no Qt) holds the app's state and actions: the session model,
  the adapters over the library, the background jobs and the presets; this package is their view;
* :mod:`spikeview.gui.workers`, :mod:`spikeview.gui.controller` — QThread workers and the glue that
  schedules jobs from model events;
* :mod:`spikeview.gui.panels`, :mod:`spikeview.gui.main_window`, :mod:`spikeview.gui.app` — the views.

Nothing is imported here.
"""

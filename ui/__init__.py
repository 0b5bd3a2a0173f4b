"""The qrfield bench app (PySide6 + pyqtgraph). Talks to :mod:`qrfield` only through its public API."""

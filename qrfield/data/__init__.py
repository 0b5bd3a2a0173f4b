"""Data files shipped with qrfield, read through :mod:`importlib.resources`: the default simulation
study (``study-default.toml``) and its rotation combinations (``combinations-default.csv``)."""

"""Subcommands of ``qrfield``, discovered by :mod:`qrfield.cli` (one module each)."""

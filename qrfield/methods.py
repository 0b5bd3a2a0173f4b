"""The pose methods: one registry for every place that names them (CLI choices, sessions, the app).

docs/conventions.md: the thesis' numerical positioning model (``numerical``) and OpenCV's closed-form
IPPE_SQUARE (``ippe``), run alone or side by side (``both``: the
numerical model first, so it gives the status). Light on purpose (no numpy, no OpenCV): argparse
choices are built from it before any command runs; :func:`settings_class` imports the solvers only
when called.
"""

from __future__ import annotations

#: The pose methods, in the order they run side by side (the first gives a frame's status).
METHODS = ("numerical", "ippe")
#: The ``--method`` value that runs every method side by side.
BOTH = "both"
#: ``--method`` values: one method, or both side by side.
METHOD_CHOICES = (*METHODS, BOTH)


def methods_from_choice(choice: str) -> tuple[str, ...]:
    """("numerical",), ("ippe",) or both for ``--method numerical|ippe|both``; ValueError otherwise."""
    if choice == BOTH:
        return METHODS
    if choice in METHODS:
        return (choice,)
    raise ValueError(f"method {choice!r} is not one of {', '.join(METHOD_CHOICES)}")


def settings_class(method: str) -> type:
    """The settings dataclass of a method (NumericalSettings or IppeSettings); SolverError otherwise."""
    from qrfield.solvers.result import SolverError

    if method == "numerical":
        from qrfield.solvers.numerical import NumericalSettings

        return NumericalSettings
    if method == "ippe":
        from qrfield.solvers.ippe import IppeSettings

        return IppeSettings
    raise SolverError(f"unknown solver method {method!r}; choose one of {', '.join(METHODS)}")


def settings_classes() -> dict[str, type]:
    """Every method's settings dataclass, in METHODS order."""
    return {method: settings_class(method) for method in METHODS}

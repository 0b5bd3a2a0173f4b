"""The pose methods' names: one list for every place that names them (CLI choices, sessions, the app).

docs/conventions.md: the thesis' numerical positioning model (``numerical``) and OpenCV's closed-form
IPPE_SQUARE (``ippe``), run alone or side by side (``both``: the numerical model first, so it gives
the status). Light on purpose (no numpy, no OpenCV, no solvers): argparse choices are built from it
before any command runs. What each method is (its settings, its solvers) is bound to its name in
:mod:`qrfield.solvers.registry`.
"""

from __future__ import annotations

#: The names of the pose methods.
NUMERICAL, IPPE = "numerical", "ippe"
#: The pose methods, in the order they run side by side (the first gives a frame's status).
METHODS = (NUMERICAL, IPPE)
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

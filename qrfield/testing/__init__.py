"""Independent truth for the tests and the benchmarks: views and corners whose truth does not come
from the code under test (the hard set's rasteriser and moving sequences, the pose view sets, seeded
corner noise of a known covariance, real chessboard squares against the whole board).

Both the benchmarks (``qrfield/benchmarks/``) and ``tests/`` import these; a benchmark never imports
from ``tests/``, and a test never from ``qrfield/benchmarks/``.
"""

"""The live stream: each frame's pose decided with the frames before it (docs/conventions.md).

- :mod:`.settings`: :class:`StreamSettings` (``continuity``, ``filter_s``), section ``stream`` of
  the run configuration;
- :mod:`.continuity`: branch continuity, an ambiguous frame's flip resolved by the recent history;
- :mod:`.crosscheck`: the numerical model's std raised to what the corners' best fit allows;
- :mod:`.kalman`: the optional random-walk filter on position and rotation;
- :mod:`.poses`: a pose's covariance as a stream works with it, and a result moved to a new pose;
- :mod:`.stage`: :class:`StreamStage`, both after each frame's solve (``qrfield.pipeline.Pipeline``).
"""

from qrfield.stream.continuity import BY_FRAME, BY_HISTORY
from qrfield.stream.settings import StreamSettings
from qrfield.stream.stage import StreamMark, StreamStage

__all__ = ["BY_FRAME", "BY_HISTORY", "StreamMark", "StreamSettings", "StreamStage"]

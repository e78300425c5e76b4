"""Perception of the NAO paper, section 3: image → neighbours (pure: numpy, scipy, OpenCV).

Public API: :class:`~agent.core.perception.detector.Detector` / ``Detection``,
:class:`~agent.core.perception.camera.CameraModel` (``pixel_bearing``, ``sweep_yaws``),
:func:`~agent.core.perception.localise.to_fixed_frame`, ``merge_sightings``,
``cluster_sightings`` and :class:`~agent.core.perception.compass.VisualCompass` /
``CompassResult``. The M-base and D-base ship in ``agent/core/perception/data`` and are
rebuilt by ``python -m tools.build_mbase`` and ``python -m tools.calibrate_dbase``.
"""

from agent.core.nao import (
    SIGHT_MAX as SIGHT_MAX,  # the range of sight (one home: agent/core/nao.py)
)
from agent.core.nao import SIGHT_MIN as SIGHT_MIN

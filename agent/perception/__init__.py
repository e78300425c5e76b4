"""Perception of the NAO paper, section 3: image → neighbours (pure: numpy, scipy, OpenCV).

Public API: :class:`~agent.perception.detector.Detector` / ``Detection``,
:class:`~agent.perception.camera.CameraModel` (``pixel_bearing``, ``sweep_yaws``),
:func:`~agent.perception.localise.to_fixed_frame`, ``merge_sightings``,
``cluster_sightings`` and :class:`~agent.perception.compass.VisualCompass` /
``CompassResult``. The M-base and D-base ship in ``agent/perception/data`` and are
rebuilt by ``python -m tools.build_mbase`` and ``python -m tools.calibrate_dbase``.
"""

from agent.nao import SIGHT_MAX as SIGHT_MAX  # the range of sight (one home: agent/nao.py)
from agent.nao import SIGHT_MIN as SIGHT_MIN

"""Perception of the NAO paper, section 3: image → neighbours (pure: numpy, scipy, OpenCV).

Public API: :class:`~agent.perception.detector.Detector` / ``Detection``,
:class:`~agent.perception.camera.CameraModel` (``pixel_bearing``, ``sweep_yaws``),
:func:`~agent.perception.localise.to_fixed_frame`, ``merge_sightings``,
``cluster_sightings`` and :class:`~agent.perception.compass.VisualCompass` /
``CompassResult``. The M-base and D-base ship in ``agent/perception/data`` and are
rebuilt by ``python -m tools.build_mbase`` and ``python -m tools.calibrate_dbase``.
"""

#: The range of sight (m, optical centre to body centre): recognition, the D-base (eq. 6
#: with the pixel-rim offset) and the bearing model are calibrated and measured from 0.5 m
#: to 3.0 m (``python -m tools.eval_perception --max-distance 3.0``; the paper: 0.5-1.45 m).
SIGHT_MIN = 0.5
SIGHT_MAX = 3.0

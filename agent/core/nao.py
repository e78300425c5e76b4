"""Facts of the NAO robot (H25 V4–V6) that the agent and the simulated world share.

docs/design.md §4 and the NAO paper (§3, Fig. 1; §5.2.2): the forehead ("top") camera, the
head-yaw range and the walking speeds; and the static obstacles of the arena (§5.1.2),
whose colour and size the world draws and the obstacle detector looks for. This module is the one home of these numbers:
the agent imports it directly, ``sim/`` imports it through :mod:`agent.wire`
(``from agent.wire import nao``), which is the only agent module ``sim/`` may import.
Standard library only, so both sides can import it without pulling anything else in.

The NAOqi identifiers at the end are those of the NAOqi API documentation
(ALVideoDevice camera indices, resolutions and colour spaces; the joint name of the
head yaw; the default port of a robot's qi service directory).
"""

from __future__ import annotations

import math

# ------------------------------------------------------------------ head
#: HeadYaw joint range (NAO H25: ±119.5°), rad, + to the robot's left.
HEAD_YAW_LIMIT = math.radians(119.5)
#: Head yaw speed as a fraction of the joint's maximum when the agent turns its head.
HEAD_SPEED_FRACTION = 0.3

# ------------------------------------------------------------------ forehead camera
CAMERA_WIDTH = 640  # px (VGA)
CAMERA_HEIGHT = 480  # px
CAMERA_HFOV = math.radians(60.9)  # horizontal field of view
CAMERA_VFOV = math.radians(47.6)  # vertical field of view (square pixels: 2·atan(240/fx))
CAMERA_HEIGHT_M = 0.50  # m above the floor, robot standing
CAMERA_PITCH_DOWN = math.radians(1.2)  # optical axis below the horizontal
CAMERA_FORWARD = 0.062  # m, optical centre ahead of the head-yaw axis
#: The range of sight (m, optical centre to body centre): recognition, the D-base (eq. 6
#: with the pixel-rim offset) and the bearing model are calibrated and measured from 0.5 m
#: to 3.0 m (``python -m tools.eval_perception --max-distance 3.0``; the paper: 0.5-1.45 m).
SIGHT_MIN = 0.5
SIGHT_MAX = 3.0
NECK_FORWARD = 0.0  # m, head-yaw axis ahead of the body centre

# ------------------------------------------------------------------ walking
WALK_SPEED = 0.095  # m/s forwards (NAO default gait)
BACK_SPEED = 0.06  # m/s backwards
MAX_SEGMENT = 0.2  # m: the paper walks straight segments of at most 20 cm (§4.2)

# ------------------------------------------------------------------ obstacles (§5.1.2)
#: Static obstacles are upright cylinders of one distinctive colour: a saturated rose
#: (RGB 1.0, 0.0, 0.5 -> HSV hue 330°, OpenCV H 165, S 255). It is neither the NAO
#: orange (OpenCV H 2-10) nor in the room textures' palette (saturated hues only in
#: H 22-160; reds and pinks beyond are kept pale, S <= 90), and shading scales all
#: channels alike, so hue and saturation survive the lighting.
OBSTACLE_RGBA = (1.0, 0.0, 0.5, 1.0)
#: OpenCV HSV range of obstacle pixels (the detector's threshold; textures avoid it).
OBSTACLE_HSV_LO = (158, 150, 30)
OBSTACLE_HSV_HI = (172, 255, 255)
#: Cylinder radius (m): a NAO's footprint (the paper regards obstacles as robots).
OBSTACLE_RADIUS = 0.15
OBSTACLE_HEIGHT = 0.6  # m, taller than the camera (0.5 m): the top is seen from below

# ------------------------------------------------------------------ NAOqi
#: s: how far a NAO's clock (``ALMotion.getTime``) may be from its fleet's when the robots
#: synchronise their clocks by NTP on one LAN (a few ms in practice; a safe bound). It
#: bounds the times of a record's stances and sightings (docs/design.md §9 "Masks seen
#: mid-turn"); a simulated body has the world's one clock (0).
NTP_CLOCK_ERROR = 0.05
NAOQI_PORT = 9559  # a NAO's qi service directory: tcp://nao.local:9559
HEAD_YAW_JOINT = "HeadYaw"
TOP_CAMERA = 0  # ALVideoDevice camera index of the forehead camera
RESOLUTION_VGA = 2  # ALVideoDevice kVGA: 640x480
COLORSPACE_BGR = 13  # ALVideoDevice kBGRColorSpace: 3 bytes per pixel, OpenCV order
POSTURE_STAND_INIT = "StandInit"

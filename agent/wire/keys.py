"""Key expressions of the bus (docs/design.md §3 table): who publishes and serves what."""

from __future__ import annotations

import re

from agent.wire.fields import ProtocolError, _check_id, _short

# --------------------------------------------------------------------------- keys

KEY_ALIVE_PREFIX = "nao/alive"
KEY_ALIVE_ALL = "nao/alive/*"
KEY_RECORD_ALL = "nao/*/record"
KEY_DIGEST_ALL = "nao/*/digest"
KEY_STATUS_ALL = "nao/*/status"
#: Every agent's record-set queryable (for agents restarted after a crash): the agreed records by
#: digest.
KEY_RECORDS_ALL = "nao/*/records"
#: Every agent's camera frames for viewers (``--publish-camera``).
KEY_CAMERA_FEED_ALL = "nao/*/camera"
#: The operator's reshape command (:class:`~agent.wire.messages.ReshapeMsg`): signed by the
#: ``operator`` identity alone, heard by every robot (docs/formation.md "Reshaping").
KEY_RESHAPE = "fleet/reshape"
KEY_WORLD_REGISTER = "world/register"
#: The world's scenario (render workers build their copy of the room from it).
KEY_WORLD_SCENARIO = "world/scenario"
#: Every robot's forehead camera: served by the world, or by render workers (processes of their own,
#: for large fleets).
KEY_CAMERA_ALL = "world/robot/*/camera"
KEY_WORLD_CLOCK = "world/clock"
KEY_WORLD_TRUTH_POSES = "world/truth/poses"
KEY_WORLD_TRUTH_CONTACTS = "world/truth/contacts"
KEY_WORLD_TRUTH_ALL = "world/truth/**"


def key_alive(robot_id: int) -> str:
    return f"{KEY_ALIVE_PREFIX}/{_check_id(robot_id)}"


def key_record(robot_id: int) -> str:
    return f"nao/{_check_id(robot_id)}/record"


def key_digest(robot_id: int) -> str:
    return f"nao/{_check_id(robot_id)}/digest"


def key_status(robot_id: int) -> str:
    return f"nao/{_check_id(robot_id)}/status"


def key_records(robot_id: int) -> str:
    return f"nao/{_check_id(robot_id)}/records"


def key_camera_feed(robot_id: int) -> str:
    """Robot ``robot_id``'s camera frames for viewers (:class:`~agent.wire.CameraMsg`); not
    to be confused with :func:`key_camera`, the world's camera queryable."""
    return f"nao/{_check_id(robot_id)}/camera"


def key_camera(robot_id: int) -> str:
    return f"world/robot/{_check_id(robot_id)}/camera"


def key_walk(robot_id: int) -> str:
    return f"world/robot/{_check_id(robot_id)}/walk"


def key_turn(robot_id: int) -> str:
    return f"world/robot/{_check_id(robot_id)}/turn"


def id_from_key(key: str) -> int:
    """The robot id in ``nao/{id}/...``, ``nao/alive/{id}`` or ``world/robot/{id}/...``."""
    if not isinstance(key, str) or len(key) > 256:
        raise ProtocolError(f"key {_short(key)} is not a key expression of at most 256 characters")
    parts = key.split("/")
    if len(parts) >= 3 and parts[0] == "nao" and parts[1] == "alive":
        raw = parts[2]
    elif len(parts) >= 2 and parts[0] == "nao":
        raw = parts[1]
    elif len(parts) >= 3 and parts[0] == "world" and parts[1] == "robot":
        raw = parts[2]
    else:
        raise ProtocolError(f"key {_short(key)} names no robot")
    if not _ID_TEXT.fullmatch(raw):
        raise ProtocolError(
            f"key {_short(key)}: robot id {_short(raw)} is not a non-negative integer "
            "in ASCII digits without leading zeros"
        )
    return _check_id(int(raw))


#: A robot id in a key: ASCII digits, no sign, no leading zero (one spelling per robot).
_ID_TEXT = re.compile(r"0|[1-9][0-9]{0,4}", re.ASCII)

"""How a camera reply carries its picture (agent/wire/picture.py): both encodings give back
the very pixels, and every way a picture can fail to match its stated size is refused."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from agent.wire import CameraReply, ProtocolError, decode, encode
from agent.wire.picture import DEFAULT_ENCODING, ENCODINGS, picture_data, picture_of


def test_bgr8_is_the_pixels_row_after_row() -> None:
    img = np.arange(2 * 3 * 3, dtype=np.uint8).reshape(2, 3, 3)
    data = picture_data(img, "bgr8")
    assert data == bytes(range(18))
    assert DEFAULT_ENCODING == "bgr8" and ENCODINGS == ("bgr8", "png")


@settings(max_examples=25, deadline=None)
@given(
    img=arrays(np.uint8, st.tuples(st.integers(1, 12), st.integers(1, 12), st.just(3))),
    encoding=st.sampled_from(ENCODINGS),
)
def test_either_encoding_gives_back_the_same_pixels(img: np.ndarray, encoding: str) -> None:
    h, w = img.shape[:2]
    got = picture_of(encoding, w, h, picture_data(img, encoding))
    assert got.dtype == np.uint8 and np.array_equal(got, img)
    got[0, 0, 0] ^= 1  # a decoded picture is the receiver's own to draw on


def test_a_non_contiguous_picture_is_encoded_as_its_pixels() -> None:
    img = np.arange(4 * 6 * 3, dtype=np.uint8).reshape(4, 6, 3)[:, ::2]
    assert np.array_equal(picture_of("bgr8", 3, 4, picture_data(img, "bgr8")), img)


def test_a_reply_carries_a_picture_through_the_codec() -> None:
    img = np.full((4, 6, 3), 200, np.uint8)
    rep = CameraReply(
        robot_id=2, yaw=0.1, t_sim=1.0, width=6, height=4, encoding="bgr8",
        data=picture_data(img, "bgr8"),
    )  # fmt: skip
    back = decode(encode(rep), expect=CameraReply)
    assert np.array_equal(picture_of(back.encoding, back.width, back.height, back.data), img)


def test_a_reply_with_another_encoding_is_refused_by_the_schema() -> None:
    with pytest.raises(ProtocolError, match="encoding: 'jpeg' is not one of bgr8, png"):
        CameraReply(robot_id=2, yaw=0.1, t_sim=1.0, width=1, height=1, encoding="jpeg", data=b"")


@pytest.mark.parametrize(
    ("encoding", "data", "match"),
    [
        ("bgr8", bytes(6 * 4 * 3 - 1), "not 6 x 4 x 3"),
        ("bgr8", bytes(6 * 4 * 3 + 3), "not 6 x 4 x 3"),
        ("png", b"\x89PNG\r\n\x1a\n broken", "without a PNG header"),
        ("png", b"GIF89a" + bytes(30), "without a PNG header"),
        ("png", picture_data(np.zeros((4, 6, 3), np.uint8), "png")[:40], "not a 6 x 4 picture"),
        ("png", picture_data(np.zeros((5, 6, 3), np.uint8), "png"), "not a 6 x 4 picture"),
        ("jpeg", bytes(72), "not one of"),
    ],
    ids=[
        "bgr8-short",
        "bgr8-long",
        "png-broken",
        "not-png",
        "png-cut",
        "png-other-size",
        "unknown",
    ],
)
def test_a_picture_that_does_not_match_its_size_is_refused(
    encoding: str, data: bytes, match: str
) -> None:
    with pytest.raises(ProtocolError, match=match):
        picture_of(encoding, 6, 4, data)


@pytest.mark.parametrize(
    ("img", "encoding", "match"),
    [
        (np.zeros((4, 6, 3), np.uint8), "jpeg", "not one of"),
        (np.zeros((4, 6), np.uint8), "bgr8", "H x W x 3 uint8"),
        (np.zeros((4, 6, 4), np.uint8), "png", "H x W x 3 uint8"),
        (np.zeros((4, 6, 3), np.float32), "bgr8", "H x W x 3 uint8"),
    ],
    ids=["unknown", "grey", "four-channels", "float"],
)
def test_only_a_bgr_picture_is_encoded(img: np.ndarray, encoding: str, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        picture_data(img, encoding)

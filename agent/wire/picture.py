"""How a camera reply carries its picture (docs/design.md §3, "Camera pictures").

A forehead picture is 640x480 BGR, 8 bits a channel. The world sends it one of two ways,
chosen by the world's operator (``python -m sim --camera-encoding``):

- ``bgr8``: the pixels as they are, row after row (921 600 bytes). Encoding and decoding
  cost a copy: the default, for agents on the world's host or a wired network.
- ``png``: lossless PNG at compression 1 (a quarter of the bytes, ~25 ms to encode and
  ~12 ms to decode a picture on one core): for agents across a thin or lossy link.

Both are lossless, so an agent sees the same pixels either way. :func:`picture_data`
encodes; :func:`picture_of` checks a received picture's bytes against its stated size
before it builds an array, and raises :class:`~agent.wire.fields.ProtocolError` for a
picture that does not match.
"""

from __future__ import annotations

import numpy as np

from agent.wire.fields import PICTURE_ENCODINGS, ProtocolError

#: The encodings a camera reply may carry (their home: :mod:`agent.wire.fields`).
ENCODINGS = PICTURE_ENCODINGS
#: The world's encoding unless its operator chooses another.
DEFAULT_ENCODING = ENCODINGS[0]
#: PNG settings of the ``png`` encoding: fastest deflate, run-length strategy (rendered
#: pictures have long runs of one colour).
PNG_COMPRESSION = 1
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
#: The ``--camera-encoding`` help of the world and its render workers.
ENCODING_HELP = (
    "how camera replies carry pictures: bgr8 (raw pixels, the default: agents on this host "
    "or a wired network) or png (a quarter of the bytes, ~40 ms more a picture: a thin or "
    "lossy link); lossless either way"
)


def picture_data(img: np.ndarray, encoding: str) -> bytes:
    """The bytes of BGR picture ``img`` (H x W x 3, uint8) in ``encoding``.

    Raises ``ValueError`` for an unknown encoding, a picture that is not H x W x 3 uint8,
    or a PNG encoder failure.
    """
    if encoding not in ENCODINGS:
        raise ValueError(f"picture encoding {encoding!r} not one of {ENCODINGS}")
    if img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] != 3:
        raise ValueError(f"a picture is H x W x 3 uint8, not {img.shape} {img.dtype}")
    if encoding == "bgr8":
        return np.ascontiguousarray(img).tobytes()
    import cv2  # only the png encoding needs it

    params = [
        cv2.IMWRITE_PNG_COMPRESSION,
        PNG_COMPRESSION,
        cv2.IMWRITE_PNG_STRATEGY,
        cv2.IMWRITE_PNG_STRATEGY_RLE,
    ]
    ok, png = cv2.imencode(".png", img, params)
    if not ok:
        raise ValueError("PNG encoding failed")
    return bytes(png.tobytes())


def picture_of(encoding: str, width: int, height: int, data: bytes) -> np.ndarray:
    """The BGR picture (``height`` x ``width`` x 3, uint8, writable) that ``data`` carries.

    Raises :class:`~agent.wire.fields.ProtocolError` for an unknown encoding, ``bgr8``
    data whose length is not ``width * height * 3``, or PNG data whose header states
    another size (checked before it is decoded) or that does not decode.
    """
    if encoding == "bgr8":
        if len(data) != width * height * 3:
            raise ProtocolError(f"bgr8 picture of {len(data)} bytes is not {width} x {height} x 3")
        return np.frombuffer(data, dtype=np.uint8).reshape(height, width, 3).copy()
    if encoding == "png":
        import cv2

        # the header's size is checked before anything is decompressed: a PNG may claim
        # any size, and decoding it would allocate what it claims
        if len(data) < 24 or data[:8] != PNG_SIGNATURE or data[12:16] != b"IHDR":
            raise ProtocolError("png data without a PNG header")
        stated = (int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big"))
        if stated != (width, height):
            raise ProtocolError(f"png data is not a {width} x {height} picture")
        img = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_COLOR)
        if img is None or img.shape != (height, width, 3):
            raise ProtocolError(f"png data is not a {width} x {height} picture")
        return np.asarray(img, dtype=np.uint8)
    raise ProtocolError(f"picture encoding {encoding!r} not one of {ENCODINGS}")

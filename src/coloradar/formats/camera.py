"""ColoRadar+ camera files: raw image frames and the ``<kind>_cam_info.json`` beside them.

arpg/coloradar_plus_processing_tools writes each ROS image message's pixel buffer as it is:
``camera/images/rgb/camera_rgb_image_<n>.bin`` holds ``height × width × 3`` uint8 values
(the RealSense colour topic, RGB order assumed), ``camera/images/depth/camera_depth_image_<n>.bin``
``height × width`` uint16 values (depth in the sensor's units, millimetres for a RealSense).
The image size is not in the file; it comes from ``camera/rgb_cam_info.json`` and
``camera/depth_cam_info.json`` (a ROS ``CameraInfo`` as JSON). That tool serialises the JSON
text once more, so the file may hold a JSON *string* that contains the object; both forms are
accepted.
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np

from ..errors import FormatError, SettingsError

__all__ = ["IMAGE_CHANNELS", "IMAGE_DTYPES", "decode_image", "encode_image",
           "parse_camera_info"]

IMAGE_DTYPES: dict[str, np.dtype[Any]] = {"rgb": np.dtype(np.uint8), "depth": np.dtype("<u2")}
"""Pixel type of each camera stream."""

IMAGE_CHANNELS: dict[str, int] = {"rgb": 3, "depth": 1}
"""Values per pixel of each camera stream."""


def parse_camera_info(text: str, name: str = "<cam_info.json>") -> dict[str, Any]:
    """Parse a ``*_cam_info.json``; the result has at least int ``height`` and ``width``.

    Parameters
    ----------
    text
        The file's content: a JSON object, or a JSON string holding one.
    name
        The file's name, for error messages.
    """
    try:
        info: Any = json.loads(text)
        if isinstance(info, str):   # JSON text serialised once more
            info = json.loads(info)
    except json.JSONDecodeError as exc:
        raise FormatError(f"{name}: expected a camera info JSON object ({exc})") from None
    if not isinstance(info, dict):
        raise FormatError(f"{name}: expected a camera info JSON object, got "
                          f"{type(info).__name__}")
    for key in ("height", "width"):
        v = info.get(key)
        if not isinstance(v, int) or isinstance(v, bool) or v <= 0:
            raise FormatError(f"{name}: expected a positive integer {key!r}, got {v!r}")
    return info


def decode_image(buf: bytes | memoryview, kind: str, height: int, width: int,
                 name: str = "<image>") -> np.ndarray:
    """Decode one raw camera frame.

    Parameters
    ----------
    buf
        The file's bytes, row-major pixels.
    kind
        ``"rgb"`` or ``"depth"``.
    height, width
        Image size [pixels] (from the camera info).
    name
        The file's name, for error messages.

    Returns
    -------
    numpy.ndarray
        ``"rgb"``: uint8 ``(height, width, 3)``; ``"depth"``: uint16 ``(height, width)``.
    """
    if kind not in IMAGE_DTYPES:
        raise FormatError(f"{name}: unknown image kind {kind!r}; expected rgb or depth")
    dtype, ch = IMAGE_DTYPES[kind], IMAGE_CHANNELS[kind]
    expected = height * width * ch * dtype.itemsize
    if len(buf) != expected:
        raise FormatError(f"{name}: a {width}x{height} {kind} image should be {expected:,} bytes "
                          f"but the file has {len(buf):,} bytes")
    img = np.frombuffer(buf, dtype=dtype).reshape((height, width, ch) if ch > 1
                                                  else (height, width))
    return img.astype(dtype.newbyteorder("="), copy=True)


def encode_image(image: np.ndarray, kind: str) -> bytes:
    """Bytes of one raw camera frame (inverse of :func:`decode_image`)."""
    img = np.asarray(image)
    ch = IMAGE_CHANNELS.get(kind)
    if ch is None:
        raise SettingsError(f"unknown image kind {kind!r}; expected rgb or depth")
    want = 3 if ch > 1 else 2
    if img.ndim != want or (ch > 1 and img.shape[2] != ch):
        raise SettingsError(f"expected a {'(h, w, 3)' if ch > 1 else '(h, w)'} {kind} image, "
                         f"got shape {img.shape}")
    return np.ascontiguousarray(img, dtype=IMAGE_DTYPES[kind]).tobytes()

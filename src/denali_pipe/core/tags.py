"""The printed AprilTags' look: the tag36h11 markers and the paper's and toner's
albedos, shared by the rig's camera frames and the twin's scene."""

from __future__ import annotations

from functools import lru_cache

import cv2
import numpy as np

TAG_WHITE = 0.85  # printed paper
TAG_BLACK = 0.04  # printed toner

_DICT = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11)


@lru_cache(maxsize=512)
def tag_texture(tag_id: int, px: int) -> np.ndarray:
    """The tag36h11 marker `tag_id` as a (px, px) uint8 greyscale image.

    The black square (1-cell black border + 6x6 data cells) spans the whole
    image: pixel (0, 0) is the tag's top-left (TL) corner. 0 = black, 255 =
    white. Cached; the returned array is read-only.
    """
    img = cv2.aruco.generateImageMarker(_DICT, int(tag_id), int(px), borderBits=1)
    img.setflags(write=False)
    return img

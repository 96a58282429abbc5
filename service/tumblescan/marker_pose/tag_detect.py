"""Tag detection in grey images (level C), returning corners in the contract's convention:
OpenCV pixels ((0, 0) the centre of the top-left pixel) and the order TL, TR, BR, BL of the tag
as printed (ArUco's and ``SOLVEPNP_IPPE_SQUARE``'s).

- ``apriltag`` (pupil-apriltags, the more accurate): its corners put pixel centres at +0.5
  (AprilRobotics/apriltag#121), so 0.5 px is subtracted, and they wind the other way round from
  OpenCV's, so they are reordered ``[1, 0, 3, 2]`` (checked against rendered truth in the tests).
- ``aruco`` (OpenCV's ArUco detector with its AprilTag dictionary and sub-pixel corner
  refinement): already in the contract's convention.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .._typing import FloatArray

APRILTAG_ORDER = [1, 0, 3, 2]  # pupil-apriltags' corner i -> OpenCV's corner order
APRILTAG_OFFSET_PX = 0.5
ARUCO_DICTIONARIES = {
    "tag36h11": "DICT_APRILTAG_36h11",
    "tag25h9": "DICT_APRILTAG_25h9",
    "tag16h5": "DICT_APRILTAG_16h5",
}


@dataclass
class Detection:
    id: int
    corners_px: FloatArray  # (4, 2) TL, TR, BR, BL, OpenCV pixels


class TagDetector:
    """One detector, built once and used on many images of one family."""

    def __init__(self, kind: str, family: str, quad_decimate: float = 1.0) -> None:
        self.kind = kind
        self._impl: Any
        if kind == "apriltag":
            from pupil_apriltags import Detector

            self._impl = Detector(families=family, nthreads=1, quad_decimate=quad_decimate, refine_edges=1)
        else:
            import cv2

            params = cv2.aruco.DetectorParameters()
            params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
            dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, ARUCO_DICTIONARIES[family]))
            self._impl = cv2.aruco.ArucoDetector(dictionary, params)

    def detect(self, gray_u8: np.ndarray) -> list[Detection]:
        """Detections in one 8-bit grey image (H, W)."""
        if self.kind == "apriltag":
            out = []
            for d in self._impl.detect(np.ascontiguousarray(gray_u8)):
                if d.hamming == 0:  # a corrected bit is more often a false tag than a true one here
                    corners = np.asarray(d.corners, dtype=float)[APRILTAG_ORDER] - APRILTAG_OFFSET_PX
                    out.append(Detection(int(d.tag_id), corners))
            return out
        corners, ids, _ = self._impl.detectMarkers(gray_u8)
        if ids is None:
            return []
        return [
            Detection(int(i), np.asarray(c, dtype=float).reshape(4, 2))
            for c, i in zip(corners, ids.ravel(), strict=True)
        ]

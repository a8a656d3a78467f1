"""Drawing detections on a frame, for the detector service's ``image_out`` and offline tools."""

import cv2
import numpy as np

from balltrack.services.detector.detector import Detection


def annotate(image_bgr: np.ndarray, detections: list[Detection]) -> np.ndarray:
    """A copy of the frame with each detection's circle, centre and label drawn (``image_out``)."""
    if image_bgr.ndim == 2:
        canvas = cv2.cvtColor(image_bgr, cv2.COLOR_GRAY2BGR)
    else:
        canvas = image_bgr.copy()
    height, width = canvas.shape[:2]
    thickness = max(1, round(min(width, height) / 240))
    font_scale = max(0.35, min(width, height) / 800)
    for index, detection in enumerate(detections):
        centre = (int(round(detection.u)), int(round(detection.v)))
        colour = (0, 0, 255) if index == 0 else (0, 200, 255)
        cv2.circle(canvas, centre, max(1, int(round(detection.radius_px))), colour, thickness, cv2.LINE_AA)
        cv2.circle(canvas, centre, max(1, thickness), colour, -1, cv2.LINE_AA)
        label = f"{index} r={detection.radius_px:.0f} s={detection.score:.2f}"
        origin = (max(0, centre[0] - int(detection.radius_px)),
                  max(12, centre[1] - int(detection.radius_px) - 4))
        cv2.putText(canvas, label, origin, cv2.FONT_HERSHEY_SIMPLEX, font_scale, (0, 0, 0),
                    thickness + 2, cv2.LINE_AA)
        cv2.putText(canvas, label, origin, cv2.FONT_HERSHEY_SIMPLEX, font_scale, colour,
                    thickness, cv2.LINE_AA)
    return canvas

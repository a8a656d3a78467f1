"""The detector service's wiring helpers that need no Zenoh."""

import cv2

from balltrack.services.detector.config import DetectorConfig
from balltrack.services.detector.service import use_threads


def test_use_threads_sets_opencvs_threads_and_zero_restores_its_default():
    before = cv2.getNumThreads()
    try:
        use_threads(DetectorConfig(threads=1))
        assert cv2.getNumThreads() == 1
        use_threads(DetectorConfig(threads=3))
        assert cv2.getNumThreads() == 3
        cv2.setNumThreads(-1)
        default = cv2.getNumThreads()  # (OpenCV's own count of the cores it may use)
        cv2.setNumThreads(1)
        use_threads(DetectorConfig(threads=0))
        assert cv2.getNumThreads() == default
    finally:
        cv2.setNumThreads(before)

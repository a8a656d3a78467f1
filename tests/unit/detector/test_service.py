"""The detector service's wiring helpers that need no Zenoh."""

import os

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
        use_threads(DetectorConfig(threads=0))
        # (OpenCV's default: one per core, unless the environment sets its own)
        expected = int(os.environ.get("OPENCV_FOR_THREADS_NUM", 0)) or os.cpu_count()
        assert cv2.getNumThreads() == expected
    finally:
        cv2.setNumThreads(before)

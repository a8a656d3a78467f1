"""The detector service: finds tennis balls in camera frames (paper section 2.2).

``detector.py`` is the pure core (``BallDetector``), one module per stage: ``mask.py`` (colour
mask), ``proposals.py`` (blobs and Hough circles), ``fit.py`` (circle fitting), ``measure.py``
and ``checks.py`` (candidates measured, then judged), ``outline.py`` (sub-pixel outline, on ``edges.py``'s colour edges along rays),
``dark.py`` (dark sides); ``jit.py`` marks the functions numba compiles;
``geometry.py`` holds the circle helpers they share, ``annotate.py`` draws detections, and
``config.py`` holds the parameters. ``service.py`` is the Zenoh service around the core.
"""

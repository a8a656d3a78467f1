"""The detector service: finds tennis balls in camera frames (paper section 2.2).

``pipeline.py`` is the pure core (blur, CLAHE, HSV mask, Hough circles, checks);
``config.py`` holds its parameters.
"""

"""balltrack: vision-based ball detection, 3D localisation and tracking as Zenoh services.

The repository's top-level folders install under this one import root: ``balltrack.common``
(messages, keys, config, runner), ``balltrack.services.<name>`` (detector, locator, follower,
simulator), ``balltrack.deploy`` (supervisor, launcher, demo) and ``balltrack.experiments``. The
``balltrack`` command itself is ``balltrack.cli``, the top layer.
"""

__version__ = "0.1.0"

"""Experiments: scripts that measure balltrack and print or plot the results.

Each module runs as ``python -m balltrack.experiments.<name>`` (and ``balltrack experiment <name>``).
"""

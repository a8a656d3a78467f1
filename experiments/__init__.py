"""Experiments: scripts that measure balltrack and print or plot the results.

Each module runs as ``python -m experiments.<name>`` (and ``balltrack experiment <name>``).
"""

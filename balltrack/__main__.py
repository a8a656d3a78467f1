import sys

from balltrack.cli import entry_point

sys.exit(entry_point())

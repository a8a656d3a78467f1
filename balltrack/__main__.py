from balltrack.cli import main
from balltrack.common.terminal import exit_with

exit_with(main)

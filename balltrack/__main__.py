import sys

from balltrack.cli import main

sys.exit(main())

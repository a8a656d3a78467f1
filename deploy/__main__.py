import sys

from balltrack.deploy.cli import main

sys.exit(main())

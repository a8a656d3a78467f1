import sys

from balltrack.services.simulator.service import main

sys.exit(main())

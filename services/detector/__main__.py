import sys

from balltrack.services.detector.service import main

sys.exit(main())

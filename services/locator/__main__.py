import sys

from balltrack.services.locator.service import main

sys.exit(main())

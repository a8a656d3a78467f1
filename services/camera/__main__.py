import sys

from balltrack.services.camera.service import main

sys.exit(main())

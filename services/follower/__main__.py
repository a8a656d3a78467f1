import sys

from balltrack.services.follower.service import main

sys.exit(main())

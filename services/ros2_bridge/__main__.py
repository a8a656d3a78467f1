import sys

from balltrack.services.ros2_bridge.service import main

sys.exit(main())

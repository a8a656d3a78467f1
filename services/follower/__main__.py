import sys

from services.follower.service import main

sys.exit(main())

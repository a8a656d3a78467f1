import sys

from balltrack.entry import main

sys.exit(main())

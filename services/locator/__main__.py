import sys

from services.locator.service import main

sys.exit(main())

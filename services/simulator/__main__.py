import sys

from balltrack.common.shutdown import catch_early_stops

catch_early_stops()  # (before the service's imports: a stop during them is not lost)
from balltrack.services.simulator.service import main  # noqa: E402

sys.exit(main())

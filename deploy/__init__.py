"""Running balltrack: the supervisor and launcher, the demo, Zenoh configs, recordings, the
secure profile and setup scripts.

    balltrack deploy start --router            # router + four services, in the background
    balltrack status --run-dir runs/default    # pids, restarts, liveliness and stats
    balltrack deploy stop
    python -m balltrack.deploy.demo            # the robot chases a ball; summary and pictures
    python -m balltrack.deploy.params --write  # docs/parameters.md's tables, README.md's key table
"""

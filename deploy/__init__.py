"""Running balltrack: a supervisor and launcher, the demo, Zenoh configs and setup scripts.

    python -m deploy start --router            # router + four services, in the background
    python -m deploy status                    # pids, restarts, liveliness and stats
    python -m deploy stop
    python -m deploy.demo                      # the robot chases a ball; summary and pictures
    python -m deploy.params                    # the README's parameter tables
"""

"""Shared layer of balltrack: keys, messages, config, sessions, the service runner, the clock."""

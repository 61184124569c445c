"""The application around the cores: the process, its settings, world and parameter files.

:mod:`simbridge.app.runner` is the process (the loop, the servers, start and stop);
:mod:`simbridge.app.guard` who each peer of every front end is (tokens, rosauth, ROS 2 role);
:mod:`simbridge.app.settings` declares every server setting once (its field, bounds,
description, environment variable and command-line option; the budget records come from it);
:mod:`simbridge.app.config` reads and validates the world and parameter files.
"""

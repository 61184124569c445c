"""The application around the cores: the process, its settings, world and parameter files.

:mod:`simbridge.app.build` is the composition root (the whole application made from the
settings in one place and order, for the server, the headless API and the CLI);
:mod:`simbridge.app.steps` the one tick the server's loop and headless stepping share;
:mod:`simbridge.app.runner` is the process (the loop, the servers, start and stop);
:mod:`simbridge.app.guard` who each peer of every front end is (tokens, rosauth, ROS 2 role);
:mod:`simbridge.app.settings` declares every server setting once (its field, bounds,
description, environment variable and command-line option; the budget records come from it);
:mod:`simbridge.app.config` reads and validates the world and parameter files.
"""

"""simbridge: a rosbridge v2 server with a built-in 2D differential-drive robot simulation.

Unmodified roslibjs pages, roslibpy scripts and Foxglove/Lichtblick connect to it as they would
to rosbridge on a real ROS 2 robot. Layers (dependencies point one way)::

    cli  ->  tools, runner, server, web, headless  ->  graph  ->  protocol, sim, msgs

``protocol``, ``msgs``, ``sim`` and ``graph`` are sans-I/O; ``server``, ``web`` and ``runner``
put them on asyncio and websockets; ``headless`` steps the same graph from Python.
``graph.assembly`` builds the robot world's graph for both. ``tools`` holds the commands that
work beside a server (``record``, ``compare``, ``topic``...).
"""

from __future__ import annotations


__version__ = "0.1.0"

__all__ = ["__version__"]

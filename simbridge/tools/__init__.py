"""The command-line tools around a running (or headless) simbridge.

=============  ================================================================================
``client``     a small rosbridge v2 client (:class:`~simbridge.tools.client.RosbridgeClient`)
``rostool``    ``simbridge topic|service|param``: the ``ros2`` CLI verbs over rosbridge
``bag``        rosbag2 bags (MCAP or SQLite) written and read with rosbags
``record``     ``simbridge record|replay``: a run to a bag, a bag's commands back to a robot
``recorder``   ``simbridge --record``: the server's own graph to a bag (the server builds it)
``compare``    ``simbridge compare``: a simulated run against a real robot's bag
``fit``        ``simbridge fit``: the realism profile of a real robot, from its bag
=============  ================================================================================

Tools sit on top of the parts (``graph``, ``msgs``, ``headless``) and nothing in the server
imports them but the recorder of ``--record``. Each is imported only when its command runs
(``simbridge --help`` stays fast), so this package re-exports nothing: import
``simbridge.tools.bag`` and so on.
"""

from __future__ import annotations

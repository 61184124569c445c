"""CBOR of a /scan and an /odom: simbridge's own encoder vs the cbor2 library, side by side.

simbridge encodes ``compression: cbor`` itself (no run-time dependency): the message body once
per message, the envelope per topic spelling. The baseline is cbor2 (the library rosbridge
3.0.1+ uses) encoding the same publish message with the same RFC 8746 typed arrays (numpy
arrays turned into tagged byte strings first, which the baseline is not charged for). Both
outputs are checked to decode to the same value. Also shown: the cbor-raw body (rosbags CDR)
and the png frame.
"""

from __future__ import annotations

from typing import Any

import cbor2
import numpy as np

from bench.encoding import _messages, _time
from simbridge.graph import Graph
from simbridge.protocol import Outgoing, encode_cbor
from simbridge.protocol.cbor import TYPED_ARRAY_TAGS


def _tagged(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _tagged(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_tagged(v) for v in value]
    if isinstance(value, np.ndarray):
        return cbor2.CBORTag(
            TYPED_ARRAY_TAGS[value.dtype.char], value.astype("<" + value.dtype.char).tobytes()
        )
    return value


def main() -> int:
    graph = Graph()
    msgs = _messages()
    print("cbor: one publish message (median, microseconds)")
    print(
        f"{'topic':<7} {'simbridge':>10} {'cbor2':>8} {'ratio':>6} {'cbor-raw':>9} {'png':>8}"
        f" {'bytes':>6}"
    )
    for topic, msg in msgs.items():
        envelope = {"op": "publish", "topic": topic, "msg": msg}
        tagged = _tagged(envelope)
        ours = encode_cbor(envelope)
        assert cbor2.loads(ours) == cbor2.loads(cbor2.dumps(tagged))
        t_ours = _time(lambda e=envelope: encode_cbor(e))
        t_lib = _time(lambda t=tagged: cbor2.dumps(t))
        mtype = {"/scan": "sensor_msgs/msg/LaserScan", "/odom": "nav_msgs/msg/Odometry"}[topic]
        t_raw = _time(
            lambda m=msg, ty=mtype, tp=topic: Outgoing(
                tp,
                ty,
                m,
                (0, 0),
                graph.topics.cdr_factory(ty, m),  # type: ignore[misc]
            ).frame("cbor-raw", tp)
        )
        t_png = _time(lambda m=msg, tp=topic: Outgoing(tp, None, m).frame("png", tp))
        print(
            f"{topic:<7} {t_ours * 1e6:>10.1f} {t_lib * 1e6:>8.1f} {t_lib / t_ours:>5.1f}x "
            f"{t_raw * 1e6:>9.1f} {t_png * 1e6:>8.1f} {len(ours):>6}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""CBOR of a /scan and an /odom: cbor2 with simbridge's numpy hook vs the hand-written encoder.

simbridge encodes ``compression: cbor`` with cbor2 (C extension) and a small hook for numpy
arrays (RFC 8746 typed arrays). The baseline is the hand-written encoder it replaced
(``bench/cbor_handwritten.py``), run on the same publish message in the same process; both
outputs are checked to be the same bytes. Also shown: the cbor-raw body (rosbags CDR) and the
png frame, for scale.
"""

from __future__ import annotations

from bench.cbor_handwritten import encode_cbor as handwritten
from bench.encoding import _messages, _time
from simbridge.graph import Graph
from simbridge.rosbridge import Outgoing, encode_cbor


def main() -> int:
    graph = Graph()
    msgs = _messages()
    print("cbor: one publish message (median, microseconds; ratio = hand-written / cbor2)")
    print(
        f"{'topic':<7} {'hand-written':>12} {'cbor2+hook':>10} {'ratio':>6} {'same bytes':>10}"
        f" {'cbor-raw':>9} {'png':>8} {'bytes':>6}"
    )
    failed = 0
    for topic, msg in msgs.items():
        envelope = {"op": "publish", "topic": topic, "msg": msg}
        ours = encode_cbor(envelope)
        same = ours == handwritten(envelope)
        failed += not same
        t_old = _time(lambda e=envelope: handwritten(e))
        t_new = _time(lambda e=envelope: encode_cbor(e))
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
            f"{topic:<7} {t_old * 1e6:>12.1f} {t_new * 1e6:>10.1f} {t_old / t_new:>5.2f}x "
            f"{'yes' if same else 'NO':>10} {t_raw * 1e6:>9.1f} {t_png * 1e6:>8.1f} {len(ours):>6}"
        )
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main())

from __future__ import annotations

from simbridge.msgs import TypeRegistry, typedefs


def test_typedefs_use_short_names_idl_primitives_and_array_lengths() -> None:
    """Odometry: pkg/Type names, double/float, -1/0/N lengths, nested types once each."""
    defs = typedefs(TypeRegistry(), "nav_msgs/msg/Odometry")
    by_type = {d["type"]: d for d in defs}
    assert defs[0]["type"] == "nav_msgs/Odometry"
    assert len(by_type) == len(defs)
    cov = by_type["geometry_msgs/PoseWithCovariance"]
    assert cov["fieldtypes"] == ["geometry_msgs/Pose", "double"]
    assert cov["fieldarraylen"] == [-1, 36]
    assert cov["examples"] == ["{}", "[]"]
    assert by_type["builtin_interfaces/Time"]["fieldtypes"] == ["int32", "uint32"]
    for d in defs:
        for ftype in d["fieldtypes"]:
            assert "/" not in ftype or ftype in by_type


def test_typedefs_list_constants_and_primitive_examples() -> None:
    """CancelGoal response: constants by name and value; int8 example '0'."""
    (first, *_rest) = typedefs(TypeRegistry(), "action_msgs/srv/CancelGoal_Response")
    assert first["constnames"][:2] == ["ERROR_NONE", "ERROR_REJECTED"]
    assert first["constvalues"][:2] == ["0", "1"]
    assert first["examples"] == ["0", "[]"]
    laser = typedefs(TypeRegistry(), "sensor_msgs/LaserScan")[0]
    assert laser["fieldtypes"][1:3] == ["float", "float"]
    assert laser["fieldarraylen"][-2:] == [0, 0]

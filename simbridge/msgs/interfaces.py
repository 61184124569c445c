"""Service and action interfaces that rosbags does not carry, and the messages they need.

rosbags holds every standard ROS 2 *message*; clients of a rosbridge also use services and
actions: ``std_srvs``, ``example_interfaces`` (``AddTwoInts``, ``Fibonacci``...), the parameter
services of ``rcl_interfaces``, ``action_msgs/srv/CancelGoal``, rosapi's (``rosapi_msgs``) and
tf2_web_republisher's. The definitions below are simbridge's own text written from the public
interfaces' field lists (names, types and constants are what clients depend on); a request and
its response are separated by ``---``, an action's goal, result and feedback likewise.

The tf2_web_republisher interfaces are registered under both package names: the ROS 2 package
``tf2_web_republisher_interfaces`` and the ROS 1 name ``tf2_web_republisher`` that roslibjs 1.x
and roslibpy still send. The registry (:mod:`simbridge.msgs.registry`) adds them all to every
:class:`~simbridge.msgs.registry.TypeRegistry`; this module is data only.
"""

from __future__ import annotations


__all__ = ["ACTIONS", "MESSAGES", "SERVICES"]

_STATUS = "bool success\nstring message"
_TYPEDEFS = "string type\n---\nTypeDef[] typedefs"

#: Messages missing from rosbags: canonical name -> .msg text.
MESSAGES: dict[str, str] = {
    "rosapi_msgs/msg/TypeDef": (
        "string type\nstring[] fieldnames\nstring[] fieldtypes\nint32[] fieldarraylen\n"
        "string[] examples\nstring[] constnames\nstring[] constvalues"
    ),
    "tf2_web_republisher/msg/TFArray": "geometry_msgs/TransformStamped[] transforms",
    "tf2_web_republisher_interfaces/msg/TFArray": "geometry_msgs/TransformStamped[] transforms",
    **{
        f"example_interfaces/msg/{name}": f"{base} data"
        for name, base in (
            ("Bool", "bool"),
            ("Byte", "byte"),
            ("Char", "char"),
            ("Float32", "float32"),
            ("Float64", "float64"),
            ("Int8", "int8"),
            ("Int16", "int16"),
            ("Int32", "int32"),
            ("Int64", "int64"),
            ("UInt8", "uint8"),
            ("UInt16", "uint16"),
            ("UInt32", "uint32"),
            ("UInt64", "uint64"),
            ("String", "string"),
            ("WString", "wstring"),
        )
    },
    "example_interfaces/msg/Empty": "",
}

#: Services: canonical name -> request and response text separated by ``---``.
SERVICES: dict[str, str] = {
    "std_srvs/srv/Empty": "---",
    "std_srvs/srv/Trigger": f"---\n{_STATUS}",
    "std_srvs/srv/SetBool": f"bool data\n---\n{_STATUS}",
    "example_interfaces/srv/AddTwoInts": "int64 a\nint64 b\n---\nint64 sum",
    "example_interfaces/srv/SetBool": f"bool data\n---\n{_STATUS}",
    "example_interfaces/srv/Trigger": f"---\n{_STATUS}",
    "action_msgs/srv/CancelGoal": (
        "GoalInfo goal_info\n---\n"
        "int8 ERROR_NONE=0\nint8 ERROR_REJECTED=1\nint8 ERROR_UNKNOWN_GOAL_ID=2\n"
        "int8 ERROR_GOAL_TERMINATED=3\n"
        "int8 return_code\nGoalInfo[] goals_canceling"
    ),
    "rcl_interfaces/srv/GetParameters": "string[] names\n---\nParameterValue[] values",
    "rcl_interfaces/srv/SetParameters": (
        "Parameter[] parameters\n---\nSetParametersResult[] results"
    ),
    "rcl_interfaces/srv/SetParametersAtomically": (
        "Parameter[] parameters\n---\nSetParametersResult result"
    ),
    "rcl_interfaces/srv/ListParameters": (
        "uint64 DEPTH_RECURSIVE=0\nstring[] prefixes\nuint64 depth\n---\n"
        "ListParametersResult result"
    ),
    "rcl_interfaces/srv/DescribeParameters": (
        "string[] names\n---\nParameterDescriptor[] descriptors"
    ),
    "rcl_interfaces/srv/GetParameterTypes": "string[] names\n---\nuint8[] types",
    "rosapi_msgs/srv/Topics": "---\nstring[] topics\nstring[] types",
    "rosapi_msgs/srv/TopicsForType": "string type\n---\nstring[] topics",
    "rosapi_msgs/srv/TopicsAndRawTypes": (
        "---\nstring[] topics\nstring[] types\nstring[] typedefs_full_text"
    ),
    "rosapi_msgs/srv/TopicType": "string topic\n---\nstring type",
    "rosapi_msgs/srv/Services": "---\nstring[] services",
    "rosapi_msgs/srv/ServicesForType": "string type\n---\nstring[] services",
    "rosapi_msgs/srv/ServiceType": "string service\n---\nstring type",
    "rosapi_msgs/srv/ServiceProviders": "string service\n---\nstring[] providers",
    "rosapi_msgs/srv/ServiceNode": "string service\n---\nstring node",
    "rosapi_msgs/srv/Nodes": "---\nstring[] nodes",
    "rosapi_msgs/srv/NodeDetails": (
        "string node\n---\nstring[] subscribing\nstring[] publishing\nstring[] services"
    ),
    "rosapi_msgs/srv/GetActionServers": "---\nstring[] action_servers",
    "rosapi_msgs/srv/ActionType": "string action\n---\nstring type",
    "rosapi_msgs/srv/Publishers": "string topic\n---\nstring[] publishers",
    "rosapi_msgs/srv/Subscribers": "string topic\n---\nstring[] subscribers",
    "rosapi_msgs/srv/MessageDetails": _TYPEDEFS,
    "rosapi_msgs/srv/ServiceRequestDetails": _TYPEDEFS,
    "rosapi_msgs/srv/ServiceResponseDetails": _TYPEDEFS,
    "rosapi_msgs/srv/ActionGoalDetails": _TYPEDEFS,
    "rosapi_msgs/srv/ActionResultDetails": _TYPEDEFS,
    "rosapi_msgs/srv/ActionFeedbackDetails": _TYPEDEFS,
    "rosapi_msgs/srv/Interfaces": "---\nstring[] interfaces",
    "rosapi_msgs/srv/GetParam": (
        "string name\nstring default_value\n---\nstring value\nbool successful\nstring reason"
    ),
    "rosapi_msgs/srv/SetParam": "string name\nstring value\n---\nbool successful\nstring reason",
    "rosapi_msgs/srv/HasParam": "string name\n---\nbool exists",
    "rosapi_msgs/srv/DeleteParam": "string name\n---\nbool successful\nstring reason",
    "rosapi_msgs/srv/GetParamNames": "---\nstring[] names",
    "rosapi_msgs/srv/GetTime": "---\nbuiltin_interfaces/Time time",
    "rosapi_msgs/srv/GetROSVersion": "---\nuint8 version\nstring distro",
    **{
        f"{pkg}/srv/RepublishTFs": (
            "string[] source_frames\nstring target_frame\nfloat32 angular_thres\n"
            "float32 trans_thres\nfloat32 rate\nbuiltin_interfaces/Duration timeout\n---\n"
            "string topic_name"
        )
        for pkg in ("tf2_web_republisher", "tf2_web_republisher_interfaces")
    },
}

#: Actions: canonical name -> goal, result and feedback text separated by ``---``.
ACTIONS: dict[str, str] = {
    "example_interfaces/action/Fibonacci": "int32 order\n---\nint32[] sequence\n---\n"
    "int32[] sequence",
    **{
        f"{pkg}/action/TFSubscription": (
            "string[] source_frames\nstring target_frame\nfloat32 angular_thres\n"
            "float32 trans_thres\nfloat32 rate\n---\n---\n"
            "geometry_msgs/TransformStamped[] transforms"
        )
        for pkg in ("tf2_web_republisher", "tf2_web_republisher_interfaces")
    },
}

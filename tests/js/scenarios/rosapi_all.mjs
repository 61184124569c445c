// Every rosapi helper of the library, Param get/set/delete, the other rosapi services called
// directly (absolute and relative names, object and list args) and the rcl_interfaces
// parameter services of /virtual_robot. One Node process for the whole set.
import { callService, rosapi, withTimeout } from '../lib.mjs';

function paramOp(param, method, args, ms) {
  return withTimeout(
    new Promise((resolve) => {
      param[method](
        ...args,
        (v) => resolve({ ok: true, value: v === undefined ? null : v }),
        (e) => resolve({ ok: false, error: String(e) }),
      );
    }),
    ms,
    `Param.${method} ${param.name}`,
  );
}

export default async function rosapiAll(ROSLIB, ros, args, lib) {
  const ms = args.timeout_ms ?? 5000;
  const svc = (name, type) => new ROSLIB.Service({ ros, name, serviceType: type });
  const call = (name, type, req) => callService(svc(name, type), req, ms);
  const out = {};
  out.topics = await rosapi(ros, 'getTopics');
  out.topicsForType = await rosapi(ros, 'getTopicsForType', ['tf2_msgs/msg/TFMessage']);
  out.services = await rosapi(ros, 'getServices');
  out.servicesForType = await rosapi(ros, 'getServicesForType', ['std_srvs/srv/Empty']);
  out.requestDetails = await rosapi(ros, 'getServiceRequestDetails', ['example_interfaces/srv/AddTwoInts']);
  out.responseDetails = await rosapi(ros, 'getServiceResponseDetails', ['rosapi_msgs/srv/GetParam']);
  out.nodes = await rosapi(ros, 'getNodes');
  out.nodeDetails = await withTimeout(
    new Promise((resolve, reject) => {
      ros.getNodeDetails(
        '/virtual_robot',
        (a, b, c) => resolve(lib === 'roslib1' ? { subscribing: a, publishing: b, services: c } : a),
        reject,
      );
    }),
    ms,
    'getNodeDetails',
  );
  out.params = await rosapi(ros, 'getParams');
  out.topicType = await rosapi(ros, 'getTopicType', ['/scan']);
  out.serviceType = await rosapi(ros, 'getServiceType', ['/reset']);
  const typedefs = await rosapi(ros, 'getMessageDetails', ['nav_msgs/msg/Odometry']);
  out.messageDetails = typedefs;
  out.decoded = ros.decodeTypeDefs(typedefs);
  out.rawTypes = await rosapi(ros, 'getTopicsAndRawTypes');
  out.actionServers = await rosapi(ros, 'getActionServers');
  if (lib === 'roslib2') {
    const topic = new ROSLIB.Topic({ ros, name: '/odom', messageType: 'nav_msgs/msg/Odometry' });
    out.publishers = await withTimeout(
      new Promise((resolve, reject) => topic.getPublishers(resolve, reject)),
      ms,
      'getPublishers',
    );
  }
  // rosapi services without a library helper; relative names and list args work too
  out.subscribers = await call('rosapi/subscribers', 'rosapi_msgs/srv/Subscribers', { topic: '/cmd_vel' });
  out.providers = await call('/rosapi/service_providers', 'rosapi/ServiceProviders', ['std_srvs/srv/Empty']);
  out.serviceNode = await call('/rosapi/service_node', 'rosapi/ServiceNode', { service: '/reset' });
  out.hasParam = await call('/rosapi/has_param', 'rosapi/HasParam', { name: '/virtual_robot:lidar.rays' });
  out.time = await call('/rosapi/get_time', 'rosapi/GetTime', {});
  out.version = await call('/rosapi/get_ros_version', 'rosapi/GetROSVersion', {});
  out.interfaces = (await call('/rosapi/interfaces', 'rosapi/Interfaces', {})).interfaces.length;
  out.topicTypeList = await call('/rosapi/topic_type', 'rosapi/TopicType', ['/odom']);
  // ROSLIB.Param
  const speed = new ROSLIB.Param({ ros, name: '/virtual_robot:robot.max_angular_velocity' });
  out.paramSet = await paramOp(speed, 'set', [1.25], ms);
  out.paramGet = await paramOp(speed, 'get', [], ms);
  out.paramDelete = await paramOp(speed, 'delete', [], ms);
  out.paramUnknown = await paramOp(new ROSLIB.Param({ ros, name: '/virtual_robot:nope' }), 'get', [], ms);
  // rcl_interfaces parameter services
  out.getParameters = await call('/virtual_robot/get_parameters', 'rcl_interfaces/srv/GetParameters', {
    names: ['robot.mass', 'lidar.rays'],
  });
  out.setParameters = await call('/virtual_robot/set_parameters', 'rcl_interfaces/srv/SetParameters', {
    parameters: [
      { name: 'lidar.range_max', value: { type: 3, double_value: 3.0 } },
      { name: 'lidar.range_min', value: { type: 3, double_value: -1.0 } },
    ],
  });
  out.listParameters = await call('/virtual_robot/list_parameters', 'rcl_interfaces/srv/ListParameters', {
    prefixes: ['robot'],
    depth: 0,
  });
  out.describeParameters = await call(
    '/virtual_robot/describe_parameters',
    'rcl_interfaces/srv/DescribeParameters',
    { names: ['lidar.range_max'] },
  );
  return out;
}

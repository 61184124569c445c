// The tutorial nodes (simbridge --demo-nodes) as roslibjs' examples use them, all at once:
//  * chatter: subscribe /chatter (std_msgs/String) -> "Hello World: N" from the talker; publish
//    one line and read the listener's "I heard: [...]" on /rosout;
//  * add_two_ints: callService on /add_two_ints (the type as the examples write it);
//  * fibonacci, ROS 1 actionlib (both versions): ActionClient serverName /fibonacci,
//    actionName actionlib_tutorials/FibonacciAction, a Goal with feedback and result;
//  * fibonacci, ROS 2 action (roslib 2.x): ROSLIB.Action sendGoal with feedback, and a cancel;
//  * the DEFAULT TFClient (1.4.1: groovyCompatibility true -> tf2_web_republisher actionlib;
//    2.1.0: TFClient is actionlib only) with fixedFrame world, frame turtle1 (a world-file frame).
// args: order (default 3). Returns what each part received.
import { callService, collect, makeTopic, waitFor, withTimeout } from '../lib.mjs';

async function chatter(ROSLIB, ros, ms) {
  const sub = makeTopic(ROSLIB, ros, '/chatter', 'std_msgs/String');
  const rosout = makeTopic(ROSLIB, ros, '/rosout', 'rcl_interfaces/msg/Log');
  const heard = [];
  rosout.subscribe((m) => { if (m.name === 'listener') heard.push(m.msg); });
  const talker = await collect(sub, 1, ms + 1500);
  const pub = makeTopic(ROSLIB, ros, '/chatter', 'std_msgs/String');
  pub.publish({ data: 'hello from roslibjs' });
  await waitFor(() => heard.includes('I heard: [hello from roslibjs]'), ms, 'the listener log');
  rosout.unsubscribe();
  return { talker: talker.messages.map((m) => m.data), heard };
}

function actionlibFibonacci(ROSLIB, ros, order, ms) {
  const client = new ROSLIB.ActionClient({
    ros,
    serverName: '/fibonacci',
    actionName: 'actionlib_tutorials/FibonacciAction',
  });
  const goal = new ROSLIB.Goal({ actionClient: client, goalMessage: { order } });
  const feedback = [];
  const statuses = new Set();
  goal.on('feedback', (f) => feedback.push(f.sequence));
  goal.on('status', (s) => statuses.add(s.status));
  const done = new Promise((resolve) => goal.on('result', (r) => resolve(r)));
  goal.send();
  return withTimeout(done, ms + order * 1000, 'actionlib fibonacci result').then((result) => {
    client.dispose();
    return { result: result.sequence, feedback, statuses: [...statuses].sort() };
  });
}

async function ros2Fibonacci(ROSLIB, ros, order, ms) {
  const action = new ROSLIB.Action({ ros, name: '/fibonacci', actionType: 'example_interfaces/action/Fibonacci' });
  const run = (o, cancelAfter) => new Promise((resolve, reject) => {
    const feedback = [];
    const id = action.sendGoal(
      { order: o },
      (result) => resolve({ result: result.sequence, feedback }),
      (fb) => {
        feedback.push(fb.sequence);
        if (cancelAfter && feedback.length === cancelAfter) action.cancelGoal(id);
      },
      (err) => (cancelAfter ? resolve({ canceled: true, error: err, feedback }) : reject(new Error(err))),
    );
  });
  const [ok, canceled] = await withTimeout(
    Promise.all([run(order), run(20, 1)]),
    ms + order * 1000,
    'ROS 2 fibonacci',
  );
  return { ok, canceled };
}

async function tfClient(ROSLIB, ros, ms) {
  const tf = new ROSLIB.TFClient({ ros, fixedFrame: 'world', angularThres: 0.01, transThres: 0.001 });
  let turtle = null;
  tf.subscribe('turtle1', (t) => {
    turtle = {
      translation: { x: t.translation.x, y: t.translation.y, z: t.translation.z },
      rotation: { x: t.rotation.x, y: t.rotation.y, z: t.rotation.z, w: t.rotation.w },
    };
  });
  await waitFor(() => turtle !== null, ms, 'turtle1 from the default TFClient');
  tf.dispose();
  return turtle;
}

export default async function tutorials(ROSLIB, ros, args, lib) {
  const ms = args.timeout_ms ?? 5000;
  const order = args.order ?? 3;
  const add = new ROSLIB.Service({ ros, name: '/add_two_ints', serviceType: 'rospy_tutorials/AddTwoInts' });
  const parts = [
    chatter(ROSLIB, ros, ms),
    callService(add, { a: 1, b: 2 }, ms),
    actionlibFibonacci(ROSLIB, ros, order, ms),
    tfClient(ROSLIB, ros, ms),
    lib === 'roslib2' ? ros2Fibonacci(ROSLIB, ros, order, ms) : Promise.resolve(null),
  ];
  const [chat, sum, actionlib, tf, ros2] = await Promise.all(parts);
  return { chatter: chat, sum, actionlib, tf, ros2 };
}

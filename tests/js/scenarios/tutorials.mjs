// The tutorial nodes (simbridge --demo-nodes) as roslibjs' examples use them, all at once:
//  * chatter: subscribe /chatter (std_msgs/String) -> "Hello World: N" from the talker; publish
//    one line and read the listener's "I heard: [...]" on /rosout;
//  * add_two_ints: callService on /add_two_ints (the type as the examples write it);
//  * fibonacci, ROS 1 actionlib (both versions): ActionClient serverName /fibonacci,
//    actionName actionlib_tutorials/FibonacciAction, a Goal with feedback and result;
//  * fibonacci, ROS 2 action (roslib 2.x): ROSLIB.Action sendGoal with feedback, and a cancel;
//    and a goal typed action_tutorials_interfaces/action/Fibonacci (feedback partial_sequence);
//  * use_sim_time of a tutorial node with ROSLIB.Param (as roslibjs's params example) and
//    getParams;
//  * the graph: is /listener a node, a topic? With args.listener_fixture (roslibjs's own test
//    fixture publishes "Hello, World" on /listener), wait until getTopics lists /listener and
//    one message arrives on it;
//  * the DEFAULT TFClient (1.4.1: groovyCompatibility true -> tf2_web_republisher actionlib;
//    2.1.0: TFClient is actionlib only) with fixedFrame world, frame turtle1 (a world-file frame).
// args: order (default 3), listener_fixture. Returns what each part received.
import { callService, collect, makeTopic, now, rosapi, sleep, waitFor, withTimeout } from '../lib.mjs';

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
  const tutorial = new ROSLIB.Action({
    ros,
    name: '/fibonacci',
    actionType: 'action_tutorials_interfaces/action/Fibonacci',
  });
  const typed = new Promise((resolve, reject) => {
    const feedback = [];
    tutorial.sendGoal(
      { order },
      (result) => resolve({ result, feedback }),
      (fb) => feedback.push(fb),
      (err) => reject(new Error(err)),
    );
  });
  const [ok, canceled, tutorialType] = await withTimeout(
    Promise.all([run(order), run(20, 1), typed]),
    ms + order * 1000,
    'ROS 2 fibonacci',
  );
  return { ok, canceled, tutorialType };
}

function param(p, verb, value, ms) {
  return withTimeout(
    new Promise((resolve, reject) => {
      const fail = (e) => reject(new Error(`${verb} ${p.name}: ${e}`));
      if (verb === 'get') p.get(resolve, fail);
      else p.set(value, () => resolve(null), fail);
    }),
    ms,
    `${verb} ${p.name}`,
  );
}

async function useSimTime(ROSLIB, ros, ms) {
  const name = '/add_two_ints_server:use_sim_time';
  const p = new ROSLIB.Param({ ros, name });
  const values = [await param(p, 'get', null, ms)];
  await param(p, 'set', true, ms);
  values.push(await param(p, 'get', null, ms));
  await param(p, 'set', false, ms);
  values.push(await param(p, 'get', null, ms));
  const names = await rosapi(ros, 'getParams', [], ms);
  return { values, listed: names.includes(name) };
}

async function listener(ROSLIB, ros, fixture, ms) {
  const nodes = await rosapi(ros, 'getNodes', [], ms);
  const topics = async () => (await rosapi(ros, 'getTopics', [], ms)).topics;
  const out = { node: nodes.includes('/listener'), topic: (await topics()).includes('/listener') };
  if (!fixture) return out;
  const heard = collect(makeTopic(ROSLIB, ros, '/listener', 'std_msgs/String'), 1, ms);
  const deadline = now() + ms;
  while (!(await topics()).includes('/listener')) {
    if (now() > deadline) throw new Error(`timeout: getTopics did not list /listener in ${ms} ms`);
    await sleep(50);
  }
  return { ...out, topic: true, message: (await heard).messages[0] };
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
    useSimTime(ROSLIB, ros, ms),
    listener(ROSLIB, ros, Boolean(args.listener_fixture), ms),
  ];
  const [chat, sum, actionlib, tf, ros2, simTime, graph] = await Promise.all(parts);
  return { chatter: chat, sum, actionlib, tf, ros2, simTime, listener: graph };
}

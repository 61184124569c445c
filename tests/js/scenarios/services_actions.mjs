// Client-provided services and (roslib 2.x) ROS 2 actions between two connections of one
// process: `ros` calls, `provider` (a second Ros) serves. One Node process for the whole set.
import { callService, rosapi, waitFor, withTimeout } from '../lib.mjs';

function connect(ROSLIB, lib, url) {
  const opts = { url };
  if (lib === 'roslib1') opts.encoding = 'utf8';
  const r = new ROSLIB.Ros(opts);
  return withTimeout(
    new Promise((resolve, reject) => {
      r.on('connection', () => resolve(r));
      r.on('error', reject);
    }),
    5000,
    'second connection',
  );
}

function outcome(promise) {
  return promise.then(
    (value) => ({ ok: true, value }),
    (err) => ({ ok: false, error: err.values ?? String(err) }),
  );
}

async function advertised(ros, name, ms) {
  await waitFor(() => true, 1, 'tick');
  await withTimeout(
    (async () => {
      for (;;) {
        const services = await rosapi(ros, 'getServices');
        if (services.includes(name)) return;
        await new Promise((r) => setTimeout(r, 20));
      }
    })(),
    ms,
    `advertisement of ${name}`,
  );
}

async function services(ROSLIB, ros, provider, lib, ms) {
  const out = {};
  const add = new ROSLIB.Service({ ros: provider, name: '/add_two_ints', serviceType: 'example_interfaces/srv/AddTwoInts' });
  add.advertise((req, resp) => {
    resp.sum = req.a + req.b;
    return true;
  });
  // the callback returns nothing: roslibjs drops `result` from the reply
  const quiet = new ROSLIB.Service({ ros: provider, name: 'quiet', serviceType: 'std_srvs/srv/Trigger' });
  quiet.advertise((req, resp) => {
    resp.success = true;
    resp.message = 'no result key';
  });
  // advertised but never answered: the server's timeout must answer the caller
  provider.callOnConnection({ op: 'advertise_service', service: '/slow', type: 'std_srvs/srv/Trigger' });
  const refuse = new ROSLIB.Service({ ros: provider, name: '/refuse', serviceType: 'std_srvs/srv/Trigger' });
  refuse.advertise(() => false);
  await advertised(ros, '/refuse', ms);

  const caller = (name, type) => new ROSLIB.Service({ ros, name, serviceType: type });
  const addC = caller('/add_two_ints', 'example_interfaces/srv/AddTwoInts');
  out.object = await outcome(callService(addC, { a: 2, b: 3 }, ms));
  out.list = await outcome(callService(addC, [40, 2], ms));
  out.quiet = await outcome(callService(caller('/quiet', 'std_srvs/srv/Trigger'), {}, ms));
  out.refuse = await outcome(callService(caller('/refuse', 'std_srvs/srv/Trigger'), {}, ms));
  // a call waiting on /slow does not block this client's other calls
  const slowC = caller('/slow', 'std_srvs/srv/Trigger');
  const started = performance.now();
  const pending = lib === 'roslib2'
    ? outcome(withTimeout(new Promise((resolve, reject) => slowC.callService({}, resolve, (e) => reject(new Error(e)), 0.4)), ms, 'slow'))
    : outcome(callService(slowC, {}, ms));
  out.topicsWhileWaiting = (await rosapi(ros, 'getTopics')).topics.includes('/odom');
  out.slow = await pending;
  out.slowMs = performance.now() - started;
  if (lib === 'roslib2') {
    const asyncSvc = new ROSLIB.Service({ ros: provider, name: '/async_fail', serviceType: 'std_srvs/srv/Trigger' });
    await asyncSvc.advertiseAsync(async () => {
      throw new Error('no can do');
    });
    await advertised(ros, '/async_fail', ms);
    out.asyncFail = await outcome(callService(caller('/async_fail', 'std_srvs/srv/Trigger'), {}, ms));
  }
  return out;
}

async function actions(ROSLIB, ros, provider, ms) {
  const out = {};
  const name = '/fibonacci';
  const type = 'example_interfaces/action/Fibonacci';
  const server = new ROSLIB.Action({ ros: provider, name, actionType: type });
  const running = new Map();
  const cancels = [];
  server.advertise(
    (goal, id) => {
      const seq = [0, 1];
      if (goal.order < 0) {
        server.setFailed(id);
        return;
      }
      if (goal.order > 50) {
        // long goal: feedback until cancelled
        running.set(id, setInterval(() => server.sendFeedback(id, { sequence: seq }), 20));
        return;
      }
      for (let i = 2; i <= goal.order; i++) {
        seq.push(seq[i - 1] + seq[i - 2]);
        server.sendFeedback(id, { sequence: seq.slice() });
      }
      server.setSucceeded(id, { sequence: seq });
    },
    (id) => {
      cancels.push(id);
      clearInterval(running.get(id));
      running.delete(id);
      server.setCanceled(id, { sequence: [0, 1] });
    },
  );
  await withTimeout(
    (async () => {
      for (;;) {
        if ((await rosapi(ros, 'getActionServers')).includes(name)) return;
        await new Promise((r) => setTimeout(r, 20));
      }
    })(),
    ms,
    'action advertisement',
  );
  out.actionServers = await rosapi(ros, 'getActionServers');
  const client = new ROSLIB.Action({ ros, name, actionType: type });
  const send = (goal) => {
    const feedback = [];
    let id;
    const done = new Promise((resolve) => {
      id = client.sendGoal(
        goal,
        (result) => resolve({ ok: true, result, feedback }),
        (fb) => feedback.push(fb),
        (err) => resolve({ ok: false, error: err, feedback }),
      );
    });
    return { id, feedback, done: withTimeout(done, ms, `goal ${JSON.stringify(goal)}`) };
  };
  out.succeeded = await send({ order: 6 }).done;
  out.failed = await send({ order: -1 }).done;
  const long = send({ order: 100 });
  await waitFor(() => long.feedback.length > 0, ms, 'feedback of the long goal');
  client.cancelGoal(long.id);
  out.canceled = await long.done;
  const a = send({ order: 101 });
  const b = send({ order: 102 });
  await waitFor(() => running.size === 2, ms, 'two goals running');
  client.cancelAllGoals();
  out.cancelAll = [await a.done, await b.done].map((r) => ({ ok: r.ok, error: r.error }));
  out.cancels = cancels.length;
  const missing = new ROSLIB.Action({ ros, name: '/no_such_action', actionType: type });
  out.missing = await withTimeout(
    new Promise((resolve) => missing.sendGoal({ order: 1 }, () => resolve('succeeded?'), undefined, (e) => resolve(e))),
    ms,
    'goal to a missing action',
  );
  server.unadvertise();
  return out;
}

export default async function servicesActions(ROSLIB, ros, args, lib, ctx) {
  const ms = args.timeout_ms ?? 5000;
  const provider = await connect(ROSLIB, lib, ctx.url);
  try {
    const out = { services: await services(ROSLIB, ros, provider, lib, ms) };
    if (lib === 'roslib2') out.actions = await actions(ROSLIB, ros, provider, ms);
    return out;
  } finally {
    provider.close();
  }
}

// Call a service that does not exist (args.name, default /no_such_service)
// and report which callback fired:
//   {fail_called, fail_value, success_called, response, timed_out}
// timed_out is true when neither callback fired within args.timeout_ms
// (default 5000): roslibjs never times out a call on its own.
import { callService, ServiceFailure } from '../lib.mjs';

export default async function unknownService(ROSLIB, ros, args) {
  const service = new ROSLIB.Service({
    ros,
    name: args.name ?? '/no_such_service',
    serviceType: args.type ?? 'std_srvs/srv/Empty',
  });
  const out = { fail_called: false, fail_value: null, success_called: false, response: null, timed_out: false };
  try {
    out.response = await callService(service, {}, args.timeout_ms ?? 5000);
    out.success_called = true;
  } catch (err) {
    if (err instanceof ServiceFailure) {
      out.fail_called = true;
      out.fail_value = err.values === undefined ? null : err.values;
    } else if (/^timeout/.test(err.message)) {
      out.timed_out = true;
    } else {
      throw err;
    }
  }
  return out;
}

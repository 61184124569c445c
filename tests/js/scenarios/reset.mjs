// Call /reset (std_srvs/srv/Empty) with {} through ROSLIB.Service and return
// the response values ({} expected). A failure callback rejects -> ok:false.
import { callService } from '../lib.mjs';

export default async function reset(ROSLIB, ros, args) {
  const service = new ROSLIB.Service({
    ros,
    name: args.name ?? '/reset',
    serviceType: 'std_srvs/srv/Empty',
  });
  const response = await callService(service, {}, args.timeout_ms ?? 5000);
  return { response };
}

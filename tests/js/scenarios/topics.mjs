// ros.getTopics() -> {topics, types} (whole /rosapi/topics response in both
// versions; 1.4.1 calls "/rosapi/topics", 2.1.0 the relative "rosapi/topics").
// With args.with_topic_type, also ros.getTopicType() for every topic
// (-> /rosapi/topic_type), returned as {topic_types: {name: type}}.
import { rosapi } from '../lib.mjs';

export default async function topics(ROSLIB, ros, args) {
  const timeoutMs = args.timeout_ms ?? 5000;
  const res = await rosapi(ros, 'getTopics', [], timeoutMs);
  const out = { topics: res.topics, types: res.types };
  if (args.with_topic_type) {
    out.topic_types = {};
    for (const name of res.topics) {
      out.topic_types[name] = await rosapi(ros, 'getTopicType', [name], timeoutMs);
    }
  }
  return out;
}

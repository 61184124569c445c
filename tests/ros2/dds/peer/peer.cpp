// ddspeer: a ROS 2 node's view of the DDS graph, made of Fast DDS as rmw_fastrtps_cpp is, for the
// tests of simbridge's DDS front end. It speaks what rmw_fastrtps puts on the wire: participant
// USER_DATA `enclave=/;`, topics `rt/<name>`, types `<pkg>::msg::dds_::<Type>_`, plain CDR
// (XCDR1), ROS's default QoS, its nodes announced on `ros_discovery_info`, services as
// `rq/<name>Request` and `rr/<name>Reply` correlated by the sample identity of the DDS write.
//
// Every feature is an option and they combine in one process; what happens is printed on stdout
// as one JSON object a line (`{"event": ...}`) and commands are read from stdin, one a line
// (`cmd_vel VX WZ`, `call_reset`, `quit`). End of stdin, SIGTERM or SIGINT end it cleanly.
// `ddspeer --help` lists the options.

#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <fastdds/dds/domain/DomainParticipantListener.hpp>
#include <fastdds/dds/publisher/DataWriter.hpp>
#include <fastdds/dds/publisher/Publisher.hpp>
#include <fastdds/dds/subscriber/DataReader.hpp>
#include <fastdds/dds/subscriber/DataReaderListener.hpp>
#include <fastdds/dds/subscriber/SampleInfo.hpp>
#include <fastdds/dds/subscriber/Subscriber.hpp>
#include <fastdds/dds/topic/Topic.hpp>
#include <fastdds/dds/topic/TypeSupport.hpp>
#include <fastdds/rtps/common/WriteParams.h>
#include <fastdds/rtps/transport/UDPv4TransportDescriptor.h>
#include <fastdds/rtps/transport/shared_mem/SharedMemTransportDescriptor.h>
#include <fastrtps/utils/IPLocator.h>
#include <fastdds/rtps/participant/ParticipantDiscoveryInfo.h>
#include <fastdds/rtps/reader/ReaderDiscoveryInfo.h>
#include <fastdds/rtps/writer/WriterDiscoveryInfo.h>

#include <nlohmann/json.hpp>

#include <atomic>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <iostream>
#include <map>
#include <memory>
#include <mutex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "ros_types.h"
#include "ros_typesPubSubTypes.h"

using namespace eprosima::fastdds::dds;
namespace rtps = eprosima::fastrtps::rtps;
using json = nlohmann::json;

namespace bi = builtin_interfaces::msg::dds_;
namespace geo = geometry_msgs::msg::dds_;
namespace nav = nav_msgs::msg::dds_;
namespace sen = sensor_msgs::msg::dds_;
namespace stdm = std_msgs::msg::dds_;
namespace tf2 = tf2_msgs::msg::dds_;
namespace viz = visualization_msgs::msg::dds_;
namespace srv = std_srvs::srv::dds_;

namespace {

std::atomic<bool> g_stop{false};
std::mutex g_out_mutex;

void emit(const json& event)
{
    std::lock_guard<std::mutex> lock(g_out_mutex);
    std::cout << event.dump() << '\n' << std::flush;
}

void fail(const std::string& what)
{
    emit({{"event", "error"}, {"error", what}});
    std::exit(2);
}

double now_seconds()
{
    using namespace std::chrono;
    return duration_cast<duration<double>>(system_clock::now().time_since_epoch()).count();
}

bi::Time_ stamp_now()
{
    double t = now_seconds();
    bi::Time_ stamp;
    stamp.sec(static_cast<int32_t>(t));
    stamp.nanosec(static_cast<uint32_t>((t - std::floor(t)) * 1e9));
    return stamp;
}

std::string hex(const uint8_t* bytes, size_t n)
{
    static const char* digits = "0123456789abcdef";
    std::string out;
    for (size_t i = 0; i < n; ++i) {
        out += digits[bytes[i] >> 4];
        out += digits[bytes[i] & 15];
    }
    return out;
}

// A GUID as 32 hex digits: prefix (12 bytes) then entity id (4), the first 16 bytes of a Gid.
std::string guid_hex(const rtps::GUID_t& guid)
{
    uint8_t raw[16];
    std::copy(guid.guidPrefix.value, guid.guidPrefix.value + 12, raw);
    std::copy(guid.entityId.value, guid.entityId.value + 4, raw + 12);
    return hex(raw, 16);
}

std::string octets_text(const std::vector<rtps::octet>& data)
{
    std::string out;
    for (auto c : data) {
        if (c == 0) {
            out += "\\0";
        } else {
            out += static_cast<char>(c);
        }
    }
    return out;
}

// --- messages as JSON (field names as ROS spells them) ---------------------------------------

json to_json(const bi::Time_& m) { return {{"sec", m.sec()}, {"nanosec", m.nanosec()}}; }
json to_json(const stdm::Header_& m)
{
    return {{"stamp", to_json(m.stamp())}, {"frame_id", m.frame_id()}};
}
json to_json(const geo::Vector3_& m) { return {{"x", m.x()}, {"y", m.y()}, {"z", m.z()}}; }
json to_json(const geo::Point_& m) { return {{"x", m.x()}, {"y", m.y()}, {"z", m.z()}}; }
json to_json(const geo::Quaternion_& m)
{
    return {{"x", m.x()}, {"y", m.y()}, {"z", m.z()}, {"w", m.w()}};
}
json to_json(const geo::Pose_& m)
{
    return {{"position", to_json(m.position())}, {"orientation", to_json(m.orientation())}};
}
json to_json(const geo::Twist_& m)
{
    return {{"linear", to_json(m.linear())}, {"angular", to_json(m.angular())}};
}
json to_json(const nav::Odometry_& m)
{
    return {
        {"header", to_json(m.header())},
        {"child_frame_id", m.child_frame_id()},
        {"pose", {{"pose", to_json(m.pose().pose())}, {"covariance", m.pose().covariance()}}},
        {"twist", {{"twist", to_json(m.twist().twist())}, {"covariance", m.twist().covariance()}}},
    };
}
json to_json(const sen::LaserScan_& m)
{
    return {
        {"header", to_json(m.header())},     {"angle_min", m.angle_min()},
        {"angle_max", m.angle_max()},         {"angle_increment", m.angle_increment()},
        {"time_increment", m.time_increment()}, {"scan_time", m.scan_time()},
        {"range_min", m.range_min()},         {"range_max", m.range_max()},
        {"ranges", m.ranges()},               {"intensities", m.intensities()},
    };
}
json to_json(const tf2::TFMessage_& m)
{
    json transforms = json::array();
    for (const auto& t : m.transforms()) {
        transforms.push_back({
            {"header", to_json(t.header())},
            {"child_frame_id", t.child_frame_id()},
            {"transform",
             {{"translation", to_json(t.transform().translation())},
              {"rotation", to_json(t.transform().rotation())}}},
        });
    }
    return {{"transforms", transforms}};
}
json to_json(const stdm::String_& m) { return {{"data", m.data()}}; }
json to_json(const viz::Marker_& m)
{
    json points = json::array();
    for (const auto& p : m.points()) {
        points.push_back(to_json(p));
    }
    return {
        {"header", to_json(m.header())}, {"ns", m.ns()},     {"id", m.id()},
        {"type", m.type()},              {"action", m.action()},
        {"pose", to_json(m.pose())},     {"scale", to_json(m.scale())},
        {"color", {{"r", m.color().r()}, {"g", m.color().g()}, {"b", m.color().b()}, {"a", m.color().a()}}},
        {"frame_locked", m.frame_locked()}, {"points", points}, {"text", m.text()},
    };
}
json to_json(const viz::MarkerArray_& m)
{
    json markers = json::array();
    for (const auto& marker : m.markers()) {
        markers.push_back(to_json(marker));
    }
    return {{"markers", markers}};
}

// --- options ----------------------------------------------------------------------------------

struct EchoSpec
{
    std::string topic;     // ROS name, e.g. /odom
    std::string type;      // ROS type, e.g. nav_msgs/msg/Odometry
    std::string qos;       // default | sensor | latched
};

// --raw: bytes written as they are, under a ROS type's DDS name (bad input for the tests)
struct RawSpec
{
    std::string topic;               // ROS name, e.g. /cmd_vel
    std::string type;                // ROS type, e.g. geometry_msgs/msg/Twist
    std::vector<unsigned char> data;  // the whole payload, its encapsulation header included
};

struct Options
{
    int domain = -1;
    int gid_size = 24;
    std::string node = "ddspeer";
    std::string ns = "/";
    std::string localhost;  // "", "humble" or "jazzy": rmw_fastrtps's localhost-only modes
    bool announce = true;
    std::vector<EchoSpec> echoes;
    bool cmd_vel = false;
    double cmd_vx = 0.0;
    double cmd_wz = 0.0;
    double rate = 10.0;
    std::string cmd_vel_topic = "/cmd_vel";
    bool chatter = false;
    bool robot = false;
    bool serve_reset = false;
    bool call_reset = false;
    double duration = 0.0;
    std::map<std::string, std::string> type_hashes;  // ROS type -> RIHS01_...
    std::vector<RawSpec> raws;
};

const char* kUsage =
    "usage: ddspeer [options]\n"
    "  --domain N            DDS domain (default: $ROS_DOMAIN_ID, else 0)\n"
    "  --distro humble|jazzy|kilted   Gid size on ros_discovery_info: 24 (humble), 16 (later)\n"
    "  --node NAME           this node's name, announced on ros_discovery_info (ddspeer)\n"
    "  --localhost humble|jazzy   discover on this machine only, as rmw_fastrtps does with\n"
    "                        ROS_LOCALHOST_ONLY=1 (humble: UDP on 127.0.0.1 only, multicast\n"
    "                        discovery) or ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST (jazzy: no\n"
    "                        multicast, 127.0.0.1 as the initial peer, 32 participant ports)\n"
    "  --namespace NS        the node's namespace (/); --robot's topics go under it\n"
    "  --no-announce         publish nothing on ros_discovery_info\n"
    "  --echo TOPIC[=pkg/msg/Type][@default|sensor|latched]   print each sample\n"
    "  --cmd-vel VX,WZ       publish geometry_msgs/msg/Twist on /cmd_vel at --rate\n"
    "  --cmd-vel-topic NAME  where --cmd-vel publishes (/cmd_vel)\n"
    "  --rate HZ             rate of --cmd-vel (10)\n"
    "  --chatter             publish std_msgs/msg/String on /peer_chatter at 2 Hz\n"
    "  --robot               a stand-in robot: /odom 20 Hz, /scan 10 Hz, /tf, /tf_static,\n"
    "                        driven by /cmd_vel\n"
    "  --serve-reset         serve /reset (std_srvs/srv/Empty); --robot's resets its pose\n"
    "  --call-reset          a client of /reset: stdin `call_reset` sends a request\n"
    "  --type-hash pkg/msg/Type=RIHS01_<hex>   endpoint USER_DATA typehash= of that type\n"
    "                        (Iron and later, so not with --distro humble)\n"
    "  --raw TOPIC=pkg/msg/Type:HEX   write these bytes (CDR header included) as they are\n"
    "                        on TOPIC at 10 Hz, under the type's DDS name (no other option of\n"
    "                        this peer may use that type)\n"
    "  --duration S          exit after S seconds (default: until stdin ends)\n";

RawSpec parse_raw(const std::string& arg)
{
    RawSpec spec;
    auto eq = arg.find('=');
    auto colon = arg.rfind(':');
    if (eq == std::string::npos || colon == std::string::npos || colon < eq) {
        fail("--raw wants TOPIC=pkg/msg/Type:HEX");
    }
    spec.topic = arg.substr(0, eq);
    spec.type = arg.substr(eq + 1, colon - eq - 1);
    std::string hex = arg.substr(colon + 1);
    if (hex.size() < 8 || hex.size() % 2) {
        fail("--raw " + arg + ": HEX must hold whole bytes, the 4-byte CDR header first");
    }
    for (size_t k = 0; k < hex.size(); k += 2) {
        spec.data.push_back(static_cast<unsigned char>(std::stoi(hex.substr(k, 2), nullptr, 16)));
    }
    return spec;
}

// The DDS name of a ROS type: geometry_msgs/msg/Twist -> geometry_msgs::msg::dds_::Twist_
std::string dds_type_of(const std::string& ros_type)
{
    auto last = ros_type.rfind('/');
    std::string out = ros_type.substr(0, last);
    for (auto p = out.find('/'); p != std::string::npos; p = out.find('/')) {
        out.replace(p, 1, "::");
    }
    return out + "::dds_::" + ros_type.substr(last + 1) + "_";
}

// A type whose samples are bytes written as they are (std::vector<unsigned char>).
class RawType : public TopicDataType
{
public:
    explicit RawType(const std::string& name)
    {
        setName(name.c_str());
        m_typeSize = 1 << 16;
        m_isGetKeyDefined = false;
    }

    bool serialize(void* data, rtps::SerializedPayload_t* payload) override
    {
        auto* bytes = static_cast<std::vector<unsigned char>*>(data);
        if (bytes->size() > payload->max_size) {
            return false;
        }
        std::copy(bytes->begin(), bytes->end(), payload->data);
        payload->length = static_cast<uint32_t>(bytes->size());
        payload->encapsulation = (*bytes)[1] == 1 ? CDR_LE : CDR_BE;
        return true;
    }

    bool deserialize(rtps::SerializedPayload_t*, void*) override { return false; }

    std::function<uint32_t()> getSerializedSizeProvider(void* data) override
    {
        auto size = static_cast<uint32_t>(static_cast<std::vector<unsigned char>*>(data)->size());
        return [size] { return size; };
    }

    void* createData() override { return new std::vector<unsigned char>(); }

    void deleteData(void* data) override { delete static_cast<std::vector<unsigned char>*>(data); }

    bool getKey(void*, rtps::InstanceHandle_t*, bool) override { return false; }
};

EchoSpec parse_echo(const std::string& arg)
{
    EchoSpec spec;
    std::string rest = arg;
    auto at = rest.find('@');
    if (at != std::string::npos) {
        spec.qos = rest.substr(at + 1);
        rest = rest.substr(0, at);
    }
    auto eq = rest.find('=');
    if (eq != std::string::npos) {
        spec.type = rest.substr(eq + 1);
        rest = rest.substr(0, eq);
    }
    spec.topic = rest;
    std::string base = rest.substr(rest.rfind('/') + 1);
    if (spec.type.empty()) {
        static const std::map<std::string, std::string> by_name = {
            {"odom", "nav_msgs/msg/Odometry"},      {"scan", "sensor_msgs/msg/LaserScan"},
            {"tf", "tf2_msgs/msg/TFMessage"},       {"tf_static", "tf2_msgs/msg/TFMessage"},
            {"cmd_vel", "geometry_msgs/msg/Twist"}, {"walls", "visualization_msgs/msg/Marker"},
            {"peer_chatter", "std_msgs/msg/String"}, {"ground_truth", "nav_msgs/msg/Odometry"},
        };
        auto it = by_name.find(base);
        if (it == by_name.end()) {
            fail("--echo " + arg + ": no default type for this topic; add =pkg/msg/Type");
        }
        spec.type = it->second;
    }
    if (spec.qos.empty()) {
        spec.qos = (base == "tf_static" || base == "walls") ? "latched" : "default";
    }
    if (spec.qos != "default" && spec.qos != "sensor" && spec.qos != "latched") {
        fail("--echo " + arg + ": QoS must be default, sensor or latched");
    }
    if (spec.topic.empty() || spec.topic[0] != '/') {
        fail("--echo " + arg + ": the topic must be an absolute ROS name (/odom)");
    }
    return spec;
}

Options parse(int argc, char** argv)
{
    Options o;
    auto value = [&](int& i) -> std::string {
        if (i + 1 >= argc) {
            fail(std::string(argv[i]) + " needs a value");
        }
        return argv[++i];
    };
    std::string distro = "humble";
    for (int i = 1; i < argc; ++i) {
        std::string a = argv[i];
        if (a == "--help" || a == "-h") {
            std::cout << kUsage;
            std::exit(0);
        } else if (a == "--domain") {
            o.domain = std::stoi(value(i));
        } else if (a == "--distro") {
            distro = value(i);
            if (distro != "humble" && distro != "jazzy" && distro != "kilted") {
                fail("--distro must be humble, jazzy or kilted");
            }
        } else if (a == "--node") {
            o.node = value(i);
        } else if (a == "--localhost") {
            o.localhost = value(i);
            if (o.localhost != "humble" && o.localhost != "jazzy") {
                fail("--localhost must be humble or jazzy");
            }
        } else if (a == "--namespace") {
            o.ns = value(i);
        } else if (a == "--no-announce") {
            o.announce = false;
        } else if (a == "--echo") {
            o.echoes.push_back(parse_echo(value(i)));
        } else if (a == "--cmd-vel") {
            std::string v = value(i);
            auto comma = v.find(',');
            if (comma == std::string::npos) {
                fail("--cmd-vel wants VX,WZ");
            }
            o.cmd_vel = true;
            o.cmd_vx = std::stod(v.substr(0, comma));
            o.cmd_wz = std::stod(v.substr(comma + 1));
        } else if (a == "--cmd-vel-topic") {
            o.cmd_vel_topic = value(i);
        } else if (a == "--rate") {
            o.rate = std::stod(value(i));
            if (!(o.rate > 0)) {
                fail("--rate must be positive");
            }
        } else if (a == "--chatter") {
            o.chatter = true;
        } else if (a == "--robot") {
            o.robot = true;
        } else if (a == "--serve-reset") {
            o.serve_reset = true;
        } else if (a == "--call-reset") {
            o.call_reset = true;
        } else if (a == "--type-hash") {
            std::string v = value(i);
            auto eq = v.find('=');
            if (eq == std::string::npos || v.compare(eq + 1, 7, "RIHS01_") != 0) {
                fail("--type-hash wants pkg/msg/Type=RIHS01_<64 hex>");
            }
            o.type_hashes[v.substr(0, eq)] = v.substr(eq + 1);
        } else if (a == "--raw") {
            o.raws.push_back(parse_raw(value(i)));
        } else if (a == "--duration") {
            o.duration = std::stod(value(i));
        } else {
            fail("unknown option " + a + "\n" + kUsage);
        }
    }
    o.gid_size = distro == "humble" ? 24 : 16;
    if (o.domain < 0) {
        const char* env = std::getenv("ROS_DOMAIN_ID");
        o.domain = (env && *env) ? std::atoi(env) : 0;
    }
    return o;
}

// The DDS name of a ROS topic, and of a ROS type (rmw_fastrtps_shared_cpp namespace_prefix,
// rmw_fastrtps_cpp type_support_common).
std::string dds_topic(const std::string& ros_name) { return "rt" + ros_name; }

// nav_msgs::msg::dds_::Odometry_ -> nav_msgs/msg/Odometry
std::string ros_type_of(const std::string& dds_type)
{
    std::string out = dds_type;
    auto pos = out.find("::dds_::");
    if (pos != std::string::npos) {
        out.erase(pos, 6);
    }
    for (auto p = out.find("::"); p != std::string::npos; p = out.find("::")) {
        out.replace(p, 2, "/");
    }
    if (!out.empty() && out.back() == '_') {
        out.pop_back();
    }
    return out;
}

// --- QoS as rmw_fastrtps sets it --------------------------------------------------------------

DataWriterQos writer_qos(bool latched, int depth)
{
    DataWriterQos q = DATAWRITER_QOS_DEFAULT;
    q.reliability().kind = RELIABLE_RELIABILITY_QOS;
    q.durability().kind = latched ? TRANSIENT_LOCAL_DURABILITY_QOS : VOLATILE_DURABILITY_QOS;
    q.history().kind = KEEP_LAST_HISTORY_QOS;
    q.history().depth = depth;
    q.endpoint().history_memory_policy = rtps::PREALLOCATED_WITH_REALLOC_MEMORY_MODE;
    q.representation().m_value.clear();
    q.representation().m_value.push_back(XCDR_DATA_REPRESENTATION);
    return q;
}

DataReaderQos reader_qos(const std::string& kind, int depth)
{
    DataReaderQos q = DATAREADER_QOS_DEFAULT;
    q.reliability().kind = kind == "sensor" ? BEST_EFFORT_RELIABILITY_QOS : RELIABLE_RELIABILITY_QOS;
    q.durability().kind = kind == "latched" ? TRANSIENT_LOCAL_DURABILITY_QOS : VOLATILE_DURABILITY_QOS;
    q.history().kind = KEEP_LAST_HISTORY_QOS;
    q.history().depth = depth;
    q.endpoint().history_memory_policy = rtps::PREALLOCATED_WITH_REALLOC_MEMORY_MODE;
    q.type_consistency().representation.m_value.clear();
    q.type_consistency().representation.m_value.push_back(XCDR_DATA_REPRESENTATION);
    return q;
}

// --- the peer -------------------------------------------------------------------------------

class Peer;

// Hands each sample a reader takes to a callback, with its SampleInfo.
template <typename T>
class TakingListener : public DataReaderListener
{
public:
    using Callback = std::function<void(const T&, const SampleInfo&)>;
    explicit TakingListener(Callback cb) : cb_(std::move(cb)) {}

    void on_data_available(DataReader* reader) override
    {
        T sample;
        SampleInfo info;
        while (reader->take_next_sample(&sample, &info) == ReturnCode_t::RETCODE_OK) {
            if (info.valid_data) {
                cb_(sample, info);
            }
        }
    }

    void on_subscription_matched(DataReader* reader, const SubscriptionMatchedStatus& status) override
    {
        emit({{"event", "matched"}, {"kind", "reader"},
              {"topic", reader->get_topicdescription()->get_name()},
              {"count", status.current_count}});
    }

private:
    Callback cb_;
};

class WriterMatchListener : public DataWriterListener
{
public:
    void on_publication_matched(DataWriter* writer, const PublicationMatchedStatus& status) override
    {
        emit({{"event", "matched"}, {"kind", "writer"}, {"topic", writer->get_topic()->get_name()},
              {"count", status.current_count}});
    }
};

class DiscoveryListener : public DomainParticipantListener
{
public:
    static inline const rtps::GuidPrefix_t* local_prefix = nullptr;

    void on_participant_discovery(DomainParticipant*, rtps::ParticipantDiscoveryInfo&& info) override
    {
        using S = rtps::ParticipantDiscoveryInfo::DISCOVERY_STATUS;
        bool alive = info.status == S::DISCOVERED_PARTICIPANT || info.status == S::CHANGED_QOS_PARTICIPANT;
        emit({{"event", "participant"}, {"guid", guid_hex(info.info.m_guid)},
              {"name", info.info.m_participantName.to_string()},
              {"user_data", octets_text(info.info.m_userData.data_vec())}, {"alive", alive}});
    }

    void on_subscriber_discovery(DomainParticipant*, rtps::ReaderDiscoveryInfo&& info) override
    {
        using S = rtps::ReaderDiscoveryInfo::DISCOVERY_STATUS;
        const auto& d = info.info;
        endpoint("reader", d.guid(), d.topicName().to_string(), d.typeName().to_string(),
                 d.m_qos.m_reliability.kind == RELIABLE_RELIABILITY_QOS,
                 d.m_qos.m_durability.kind, d.m_qos.m_userData.data_vec(),
                 info.status == S::DISCOVERED_READER || info.status == S::CHANGED_QOS_READER);
    }

    void on_publisher_discovery(DomainParticipant*, rtps::WriterDiscoveryInfo&& info) override
    {
        using S = rtps::WriterDiscoveryInfo::DISCOVERY_STATUS;
        const auto& d = info.info;
        endpoint("writer", d.guid(), d.topicName().to_string(), d.typeName().to_string(),
                 d.m_qos.m_reliability.kind == RELIABLE_RELIABILITY_QOS,
                 d.m_qos.m_durability.kind, d.m_qos.m_userData.data_vec(),
                 info.status == S::DISCOVERED_WRITER || info.status == S::CHANGED_QOS_WRITER);
    }

private:
    static void endpoint(const char* kind, const rtps::GUID_t& guid, const std::string& topic,
                         const std::string& type, bool reliable, DurabilityQosPolicyKind durability,
                         const std::vector<rtps::octet>& user_data, bool alive)
    {
        const char* dur = durability == TRANSIENT_LOCAL_DURABILITY_QOS ? "transient_local"
                          : durability == VOLATILE_DURABILITY_QOS    ? "volatile"
                                                                     : "other";
        if (local_prefix && guid.guidPrefix == *local_prefix) {
            return;  // Fast DDS reports this participant's own endpoints too
        }
        emit({{"event", "endpoint"}, {"kind", kind}, {"guid", guid_hex(guid)}, {"topic", topic},
              {"type", type}, {"reliability", reliable ? "reliable" : "best_effort"},
              {"durability", dur}, {"user_data", octets_text(user_data)}, {"alive", alive}});
    }
};

// rmw_fastrtps_shared_cpp's participant.cpp: ROS_LOCALHOST_ONLY=1 in Humble (the builtin
// transports replaced by UDPv4 on 127.0.0.1 only and shared memory; discovery stays multicast,
// on the loopback interface), ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST from Jazzy on (no
// multicast locator, 127.0.0.1 as the initial peer on 32 participants' ports, shared memory)
void localhost_only(DomainParticipantQos& pq, const std::string& mode)
{
    namespace rtps_t = eprosima::fastdds::rtps;
    if (mode.empty()) {
        return;
    }
    pq.transport().use_builtin_transports = false;
    auto udp = std::make_shared<rtps_t::UDPv4TransportDescriptor>();
    if (mode == "humble") {
        udp->interfaceWhiteList.emplace_back("127.0.0.1");
        pq.transport().user_transports.push_back(udp);
        pq.transport().user_transports.push_back(
            std::make_shared<rtps_t::SharedMemTransportDescriptor>());
        return;
    }
    auto& builtin = pq.wire_protocol().builtin;
    builtin.metatrafficMulticastLocatorList.clear();
    builtin.metatrafficUnicastLocatorList.push_back(eprosima::fastrtps::rtps::Locator_t());
    pq.transport().user_transports.push_back(
        std::make_shared<rtps_t::SharedMemTransportDescriptor>());
    udp->maxInitialPeersRange = 32;
    pq.transport().user_transports.push_back(udp);
    eprosima::fastrtps::rtps::Locator_t peer;
    eprosima::fastrtps::rtps::IPLocator::setIPv4(peer, "127.0.0.1");
    builtin.initialPeersList.push_back(peer);
}

class Peer
{
public:
    explicit Peer(const Options& o) : o_(o)
    {
        DomainParticipantQos pq = PARTICIPANT_QOS_DEFAULT;
        pq.name("/");
        // rmw_fastrtps_shared_cpp participant.cpp: the enclave, NUL-terminated
        std::string enclave = "enclave=/;";
        std::vector<rtps::octet> ud(enclave.begin(), enclave.end());
        ud.push_back(0);
        pq.user_data().data_vec(ud);
        localhost_only(pq, o.localhost);
        // the participant listener hears discovery only: with DATA_ON_READERS in its mask the
        // readers' own on_data_available would never be called
        StatusMask mask = StatusMask::all();
        mask >> StatusMask::data_on_readers();
        mask >> StatusMask::data_available();
        participant_ = DomainParticipantFactory::get_instance()->create_participant(
            o.domain, pq, &discovery_, mask);
        if (!participant_) {
            fail("could not create a participant on domain " + std::to_string(o.domain));
        }
        local_prefix_ = participant_->guid().guidPrefix;
        DiscoveryListener::local_prefix = &local_prefix_;
        publisher_ = participant_->create_publisher(PUBLISHER_QOS_DEFAULT);
        subscriber_ = participant_->create_subscriber(SUBSCRIBER_QOS_DEFAULT);
        emit({{"event", "participant_created"}, {"guid", guid_hex(participant_->guid())},
              {"domain", o.domain}, {"gid_size", o.gid_size}});
    }

    ~Peer()
    {
        participant_->delete_contained_entities();
        DomainParticipantFactory::get_instance()->delete_participant(participant_);
    }

    void setup()
    {
        discovery_reader();
        for (const auto& e : o_.echoes) {
            echo(e);
        }
        if (o_.cmd_vel) {
            cmd_vel_writer_ = writer<geo::Twist_PubSubType>(dds_topic(o_.cmd_vel_topic), false, 10);
        }
        if (o_.chatter) {
            chatter_writer_ = writer<stdm::String_PubSubType>(dds_topic("/peer_chatter"), false, 10);
        }
        for (const auto& raw : o_.raws) {
            Topic* t = topic_of(dds_topic(raw.topic), TypeSupport(new RawType(dds_type_of(raw.type))));
            DataWriter* w = publisher_->create_datawriter(t, writer_qos(false, 10), &writer_listener_);
            if (!w) {
                fail("could not create a writer on " + dds_topic(raw.topic));
            }
            writer_gids_.push_back(w->guid());
            raw_writers_.push_back(w);
        }
        if (o_.robot) {
            robot_setup();
        }
        if (o_.serve_reset) {
            service_setup();
        }
        if (o_.call_reset) {
            client_setup();
        }
        if (o_.announce) {
            announce();
        }
        emit({{"event", "ready"}, {"guid", guid_hex(participant_->guid())}, {"node", node_fqn()}});
    }

    void run()
    {
        std::thread input([this] { read_commands(); });
        input.detach();
        double start = now_seconds();
        double period = 1.0 / o_.rate;
        double next_cmd = start, next_chatter = start, next_odom = start, next_scan = start;
        double next_raw = start;
        int chatter_count = 0;
        double last = start;
        while (!g_stop) {
            double t = now_seconds();
            if (o_.duration > 0 && t - start >= o_.duration) {
                break;
            }
            if (cmd_vel_writer_ && t >= next_cmd) {
                geo::Twist_ m;
                {
                    std::lock_guard<std::mutex> lock(mutex_);
                    m.linear().x(o_.cmd_vx);
                    m.angular().z(o_.cmd_wz);
                }
                cmd_vel_writer_->write(&m);
                next_cmd += period;
            }
            if (!raw_writers_.empty() && t >= next_raw) {
                for (size_t k = 0; k < raw_writers_.size(); ++k) {
                    std::vector<unsigned char> bytes = o_.raws[k].data;
                    raw_writers_[k]->write(&bytes);
                }
                next_raw += 0.1;
            }
            if (chatter_writer_ && t >= next_chatter) {
                stdm::String_ m;
                m.data("hello " + std::to_string(chatter_count++));
                chatter_writer_->write(&m);
                next_chatter += 0.5;
            }
            if (o_.robot) {
                robot_step(t - last);
                if (t >= next_odom) {
                    publish_odom();
                    next_odom += 0.05;
                }
                if (t >= next_scan) {
                    publish_scan();
                    next_scan += 0.1;
                }
            }
            last = t;
            std::this_thread::sleep_for(std::chrono::milliseconds(5));
        }
        emit({{"event", "stopping"}});
    }

private:
    // rmw_dds_common qos.cpp: `typehash=RIHS01_<hex>;` from Iron on, nothing in Humble
    std::vector<rtps::octet> type_hash_user_data(const std::string& dds_type) const
    {
        auto it = o_.type_hashes.find(ros_type_of(dds_type));
        if (o_.gid_size == 24 || it == o_.type_hashes.end()) {
            return {};
        }
        std::string text = "typehash=" + it->second + ";";
        return std::vector<rtps::octet>(text.begin(), text.end());
    }

    // the robot's topics under its node's namespace (/robot1/odom), as multi-robot worlds have
    std::string robot_topic(const std::string& name) const
    {
        return o_.ns == "/" ? name : o_.ns + name;
    }

    std::string node_fqn() const { return o_.ns == "/" ? "/" + o_.node : o_.ns + "/" + o_.node; }

    template <typename PubSub>
    Topic* topic(const std::string& dds_name)
    {
        TypeSupport type(new PubSub());
        return topic_of(dds_name, type);
    }

    Topic* topic_of(const std::string& dds_name, TypeSupport type)
    {
        auto it = topics_.find(dds_name);
        if (it != topics_.end()) {
            return it->second;
        }
        if (type.register_type(participant_) != ReturnCode_t::RETCODE_OK) {
            // already registered under this name: fine, the same type
        }
        Topic* t = participant_->create_topic(dds_name, type.get_type_name(), TOPIC_QOS_DEFAULT);
        if (!t) {
            fail("could not create topic " + dds_name + " of type " + type.get_type_name());
        }
        topics_[dds_name] = t;
        return t;
    }

    template <typename PubSub>
    DataWriter* writer(const std::string& dds_name, bool latched, int depth)
    {
        Topic* t = topic<PubSub>(dds_name);
        DataWriterQos q = writer_qos(latched, depth);
        q.user_data().data_vec(type_hash_user_data(t->get_type_name()));
        DataWriter* w = publisher_->create_datawriter(t, q, &writer_listener_);
        if (!w) {
            fail("could not create a writer on " + dds_name);
        }
        writer_gids_.push_back(w->guid());
        return w;
    }

    template <typename PubSub, typename T>
    DataReader* reader(const std::string& dds_name, const std::string& qos, int depth,
                       std::function<void(const T&, const SampleInfo&)> cb)
    {
        auto listener = std::make_unique<TakingListener<T>>(std::move(cb));
        Topic* t = topic<PubSub>(dds_name);
        DataReaderQos q = reader_qos(qos, depth);
        q.user_data().data_vec(type_hash_user_data(t->get_type_name()));
        DataReader* r = subscriber_->create_datareader(t, q, listener.get());
        if (!r) {
            fail("could not create a reader on " + dds_name);
        }
        listeners_.push_back(std::move(listener));
        reader_gids_.push_back(r->guid());
        return r;
    }

    template <typename PubSub, typename T>
    void echo_as(const EchoSpec& e)
    {
        // tf2's listeners keep 100 samples (tf2_ros qos.hpp), ROS's default profile 10,
        // the sensor data profile 5
        int depth = e.qos == "sensor" ? 5 : (e.qos == "latched" ? 100 : 10);
        std::string topic_name = e.topic, type_name = e.type;
        reader<PubSub, T>(dds_topic(e.topic), e.qos, depth,
                          [topic_name, type_name](const T& m, const SampleInfo& info) {
                              emit({{"event", "sample"}, {"topic", topic_name}, {"type", type_name},
                                    {"writer", guid_hex(info.sample_identity.writer_guid())},
                                    {"data", to_json(m)}});
                          });
    }

    void echo(const EchoSpec& e)
    {
        const std::string& t = e.type;
        if (t == "nav_msgs/msg/Odometry") {
            echo_as<nav::Odometry_PubSubType, nav::Odometry_>(e);
        } else if (t == "sensor_msgs/msg/LaserScan") {
            echo_as<sen::LaserScan_PubSubType, sen::LaserScan_>(e);
        } else if (t == "tf2_msgs/msg/TFMessage") {
            echo_as<tf2::TFMessage_PubSubType, tf2::TFMessage_>(e);
        } else if (t == "geometry_msgs/msg/Twist") {
            echo_as<geo::Twist_PubSubType, geo::Twist_>(e);
        } else if (t == "std_msgs/msg/String") {
            echo_as<stdm::String_PubSubType, stdm::String_>(e);
        } else if (t == "visualization_msgs/msg/Marker") {
            echo_as<viz::Marker_PubSubType, viz::Marker_>(e);
        } else if (t == "visualization_msgs/msg/MarkerArray") {
            echo_as<viz::MarkerArray_PubSubType, viz::MarkerArray_>(e);
        } else {
            fail("--echo: type " + t + " is not built into ddspeer");
        }
    }

    // --- ros_discovery_info (rmw_dds_common graph_cache; rmw_fastrtps init_rmw_context_impl) -

    template <typename Gid>
    static std::string gid_hex(const Gid& gid)
    {
        return hex(gid.data().data(), 16);
    }

    template <typename Info>
    static json nodes_json(const Info& m, int gid_size)
    {
        json nodes = json::array();
        for (const auto& n : m.node_entities_info_seq()) {
            json readers = json::array(), writers = json::array();
            for (const auto& g : n.reader_gid_seq()) {
                readers.push_back(gid_hex(g));
            }
            for (const auto& g : n.writer_gid_seq()) {
                writers.push_back(gid_hex(g));
            }
            nodes.push_back({{"namespace", n.node_namespace()}, {"name", n.node_name()},
                             {"readers", readers}, {"writers", writers}});
        }
        return {{"event", "nodes"}, {"gid", gid_hex(m.gid())}, {"gid_size", gid_size},
                {"nodes", nodes}};
    }

    template <typename PubSub>
    TypeSupport discovery_type()
    {
        TypeSupport type(new PubSub());
        type->setName("rmw_dds_common::msg::dds_::ParticipantEntitiesInfo_");
        return type;
    }

    template <typename PubSub, typename Info>
    void discovery_reader_as()
    {
        Topic* t = topic_of("ros_discovery_info", discovery_type<PubSub>());
        DataReaderQos q = reader_qos("latched", 1);
        q.history().kind = KEEP_ALL_HISTORY_QOS;
        int gid_size = o_.gid_size;
        auto listener = std::make_unique<TakingListener<Info>>(
            [gid_size](const Info& m, const SampleInfo&) { emit(nodes_json(m, gid_size)); });
        if (!subscriber_->create_datareader(t, q, listener.get())) {
            fail("could not create the ros_discovery_info reader");
        }
        listeners_.push_back(std::move(listener));
    }

    void discovery_reader()
    {
        if (o_.gid_size == 24) {
            discovery_reader_as<gid24::rmw_dds_common::msg::dds_::ParticipantEntitiesInfo_PubSubType,
                                gid24::rmw_dds_common::msg::dds_::ParticipantEntitiesInfo_>();
        } else {
            discovery_reader_as<gid16::rmw_dds_common::msg::dds_::ParticipantEntitiesInfo_PubSubType,
                                gid16::rmw_dds_common::msg::dds_::ParticipantEntitiesInfo_>();
        }
    }

    template <typename Gid>
    static Gid to_gid(const rtps::GUID_t& guid)
    {
        Gid g;
        auto& data = g.data();
        data.fill(0);
        std::copy(guid.guidPrefix.value, guid.guidPrefix.value + 12, data.begin());
        std::copy(guid.entityId.value, guid.entityId.value + 4, data.begin() + 12);
        return g;
    }

    template <typename PubSub, typename Info, typename Node, typename Gid>
    void announce_as()
    {
        Topic* t = topic_of("ros_discovery_info", discovery_type<PubSub>());
        DataWriterQos q = writer_qos(true, 1);
        DataWriter* w = publisher_->create_datawriter(t, q);
        if (!w) {
            fail("could not create the ros_discovery_info writer");
        }
        Info info;
        info.gid(to_gid<Gid>(participant_->guid()));
        Node node;
        node.node_namespace(o_.ns);
        node.node_name(o_.node);
        for (const auto& g : reader_gids_) {
            node.reader_gid_seq().push_back(to_gid<Gid>(g));
        }
        for (const auto& g : writer_gids_) {
            node.writer_gid_seq().push_back(to_gid<Gid>(g));
        }
        info.node_entities_info_seq().push_back(node);
        w->write(&info);
    }

    void announce()
    {
        if (o_.gid_size == 24) {
            using namespace gid24::rmw_dds_common::msg::dds_;
            announce_as<ParticipantEntitiesInfo_PubSubType, ParticipantEntitiesInfo_,
                        NodeEntitiesInfo_, Gid_>();
        } else {
            using namespace gid16::rmw_dds_common::msg::dds_;
            announce_as<ParticipantEntitiesInfo_PubSubType, ParticipantEntitiesInfo_,
                        NodeEntitiesInfo_, Gid_>();
        }
    }

    // --- the stand-in robot ---------------------------------------------------------------

    void robot_setup()
    {
        odom_writer_ = writer<nav::Odometry_PubSubType>(dds_topic(robot_topic("/odom")), false, 10);
        scan_writer_ = writer<sen::LaserScan_PubSubType>(dds_topic(robot_topic("/scan")), false, 10);
        tf_writer_ = writer<tf2::TFMessage_PubSubType>(dds_topic(robot_topic("/tf")), false, 100);
        // tf2's static broadcaster: transient local, depth 1 (tf2_ros qos.hpp)
        tf_static_writer_ = writer<tf2::TFMessage_PubSubType>(dds_topic(robot_topic("/tf_static")), true, 1);
        reader<geo::Twist_PubSubType, geo::Twist_>(
            dds_topic(robot_topic("/cmd_vel")), "default", 10, [this](const geo::Twist_& m, const SampleInfo&) {
                {
                    std::lock_guard<std::mutex> lock(mutex_);
                    vx_ = m.linear().x();
                    wz_ = m.angular().z();
                }
                emit({{"event", "cmd_vel"}, {"data", to_json(m)}});
            });
        tf2::TFMessage_ msg;
        geo::TransformStamped_ t;
        t.header().stamp(stamp_now());
        t.header().frame_id("base_link");
        t.child_frame_id("laser");
        t.transform().translation().x(0.1);
        t.transform().translation().z(0.2);
        t.transform().rotation().w(1.0);
        msg.transforms().push_back(t);
        tf_static_writer_->write(&msg);
    }

    void robot_step(double dt)
    {
        std::lock_guard<std::mutex> lock(mutex_);
        x_ += vx_ * std::cos(th_) * dt;
        y_ += vx_ * std::sin(th_) * dt;
        th_ += wz_ * dt;
    }

    void publish_odom()
    {
        nav::Odometry_ m;
        geo::TransformStamped_ t;
        auto stamp = stamp_now();
        {
            std::lock_guard<std::mutex> lock(mutex_);
            m.header().stamp(stamp);
            m.header().frame_id("odom");
            m.child_frame_id("base_link");
            auto& p = m.pose().pose();
            p.position().x(x_);
            p.position().y(y_);
            p.orientation().z(std::sin(th_ / 2));
            p.orientation().w(std::cos(th_ / 2));
            m.twist().twist().linear().x(vx_);
            m.twist().twist().angular().z(wz_);
            t.header() = m.header();
            t.child_frame_id("base_link");
            t.transform().translation().x(x_);
            t.transform().translation().y(y_);
            t.transform().rotation() = p.orientation();
        }
        odom_writer_->write(&m);
        tf2::TFMessage_ tf;
        tf.transforms().push_back(t);
        tf_writer_->write(&tf);
    }

    // 360 rays inside a 8 m x 8 m room centred on the origin
    void publish_scan()
    {
        sen::LaserScan_ m;
        double x, y, th;
        {
            std::lock_guard<std::mutex> lock(mutex_);
            x = x_, y = y_, th = th_;
        }
        m.header().stamp(stamp_now());
        m.header().frame_id("laser");
        const int n = 360;
        m.angle_min(static_cast<float>(-M_PI));
        m.angle_increment(static_cast<float>(2 * M_PI / n));
        m.angle_max(static_cast<float>(-M_PI + 2 * M_PI / n * (n - 1)));
        m.scan_time(0.1f);
        m.range_min(0.12f);
        m.range_max(8.0f);
        const double half = 4.0;
        for (int i = 0; i < n; ++i) {
            double a = th - M_PI + 2 * M_PI * i / n;
            double dx = std::cos(a), dy = std::sin(a), r = 1e9;
            if (dx > 1e-9) r = std::min(r, (half - x) / dx);
            if (dx < -1e-9) r = std::min(r, (-half - x) / dx);
            if (dy > 1e-9) r = std::min(r, (half - y) / dy);
            if (dy < -1e-9) r = std::min(r, (-half - y) / dy);
            m.ranges().push_back(r > 8.0 ? INFINITY : static_cast<float>(r));
        }
        scan_writer_->write(&m);
    }

    // --- /reset as rmw_fastrtps serves it: rq/resetRequest in, rr/resetReply out, the reply
    // carrying the request's sample identity as its related sample identity ----------------

    void service_setup()
    {
        reply_writer_ = writer<srv::Empty_Response_PubSubType>("rr/resetReply", false, 10);
        reader<srv::Empty_Request_PubSubType, srv::Empty_Request_>(
            "rq/resetRequest", "default", 10,
            [this](const srv::Empty_Request_&, const SampleInfo& info) {
                {
                    std::lock_guard<std::mutex> lock(mutex_);
                    x_ = y_ = th_ = 0.0;
                }
                srv::Empty_Response_ resp;
                rtps::WriteParams params;
                params.related_sample_identity(info.sample_identity);
                reply_writer_->write(&resp, params);
                emit({{"event", "request"}, {"service", "/reset"},
                      {"client", guid_hex(info.sample_identity.writer_guid())},
                      {"sequence", info.sample_identity.sequence_number().to64long()}});
            });
    }

    void client_setup()
    {
        request_writer_ = writer<srv::Empty_Request_PubSubType>("rq/resetRequest", false, 10);
        reader<srv::Empty_Response_PubSubType, srv::Empty_Response_>(
            "rr/resetReply", "default", 10,
            [this](const srv::Empty_Response_&, const SampleInfo& info) {
                auto related = info.related_sample_identity;
                bool ours = related.writer_guid() == request_writer_->guid();
                emit({{"event", "reply"}, {"service", "/reset"}, {"ours", ours},
                      {"sequence", related.sequence_number().to64long()}});
            });
    }

    void call_reset()
    {
        if (!request_writer_) {
            emit({{"event", "error"}, {"error", "call_reset needs --call-reset"}});
            return;
        }
        srv::Empty_Request_ req;
        rtps::WriteParams params;
        request_writer_->write(&req, params);
        emit({{"event", "called"}, {"service", "/reset"},
              {"sequence", params.sample_identity().sequence_number().to64long()}});
    }

    void read_commands()
    {
        std::string line;
        while (std::getline(std::cin, line)) {
            std::istringstream in(line);
            std::string cmd;
            in >> cmd;
            if (cmd == "quit") {
                break;
            } else if (cmd == "cmd_vel") {
                double vx = 0, wz = 0;
                in >> vx >> wz;
                std::lock_guard<std::mutex> lock(mutex_);
                o_.cmd_vx = vx;
                o_.cmd_wz = wz;
            } else if (cmd == "call_reset") {
                call_reset();
            } else if (!cmd.empty()) {
                emit({{"event", "error"}, {"error", "unknown command " + cmd}});
            }
        }
        g_stop = true;
    }

    Options o_;
    rtps::GuidPrefix_t local_prefix_;
    DiscoveryListener discovery_;
    WriterMatchListener writer_listener_;
    DomainParticipant* participant_ = nullptr;
    Publisher* publisher_ = nullptr;
    Subscriber* subscriber_ = nullptr;
    std::map<std::string, Topic*> topics_;
    std::vector<std::unique_ptr<DataReaderListener>> listeners_;
    std::vector<rtps::GUID_t> reader_gids_, writer_gids_;
    DataWriter* cmd_vel_writer_ = nullptr;
    DataWriter* chatter_writer_ = nullptr;
    std::vector<DataWriter*> raw_writers_;
    DataWriter* odom_writer_ = nullptr;
    DataWriter* scan_writer_ = nullptr;
    DataWriter* tf_writer_ = nullptr;
    DataWriter* tf_static_writer_ = nullptr;
    DataWriter* reply_writer_ = nullptr;
    DataWriter* request_writer_ = nullptr;
    std::mutex mutex_;
    double x_ = 0, y_ = 0, th_ = 0, vx_ = 0, wz_ = 0;
};

}  // namespace

int main(int argc, char** argv)
{
    Options o = parse(argc, argv);
    std::signal(SIGTERM, [](int) { g_stop = true; });
    std::signal(SIGINT, [](int) { g_stop = true; });
    {
        Peer peer(o);
        peer.setup();
        peer.run();
    }
    emit({{"event", "stopped"}});
    std::_Exit(0);  // the stdin thread may still block in getline
}

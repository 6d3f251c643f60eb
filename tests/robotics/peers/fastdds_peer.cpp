// A Fast DDS (eProsima, the default middleware of ROS 2 Humble and Jazzy) peer of the node, on types
// fastddsgen makes of the IDL beside it, UDPv4 on 127.0.0.1 only (unicast discovery, 4 MB socket buffers).
//   fastdds_peer sub TOPIC COUNT OUTDIR TIMEOUT_S: take COUNT sensor_msgs/Image (reliable reader); per
//     sample OUTDIR/N.bin (the pixel bytes) and "sec nanosec frame_id width height encoding step" on stdout.
//   fastdds_peer pub IMAGE_TOPIC POINTS_TOPIC DIR TIMEOUT_S: a camera + LiDAR: the frames of DIR (meta.txt:
//     "W H FRAMES CAMERA_FRAME LIDAR_FRAME", then per frame "STAMP_NS POINTS"; rgb_I.bin, points_I.bin xyz
//     float32) as rgb8 Images and PointCloud2s, best effort, at 10 Hz, round and round until TIMEOUT_S.
#include <chrono>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <fastdds/dds/publisher/DataWriter.hpp>
#include <fastdds/dds/publisher/Publisher.hpp>
#include <fastdds/dds/subscriber/DataReader.hpp>
#include <fastdds/dds/subscriber/SampleInfo.hpp>
#include <fastdds/dds/subscriber/Subscriber.hpp>
#include <fastdds/dds/topic/TypeSupport.hpp>
#include <fastdds/rtps/transport/UDPv4TransportDescriptor.h>
#include <fastrtps/utils/IPLocator.h>

#include "sensor_msgsPubSubTypes.h"

using namespace eprosima::fastdds::dds;
namespace sm = sensor_msgs::msg::dds_;
using Clock = std::chrono::steady_clock;

static DomainParticipant* participant() {
  DomainParticipantQos qos;
  auto udp = std::make_shared<eprosima::fastdds::rtps::UDPv4TransportDescriptor>();
  udp->interfaceWhiteList.push_back("127.0.0.1");
  udp->sendBufferSize = udp->receiveBufferSize = 4 << 20;
  qos.transport().user_transports.push_back(udp);
  qos.transport().use_builtin_transports = false;
  eprosima::fastrtps::rtps::Locator_t peer;
  eprosima::fastrtps::rtps::IPLocator::setIPv4(peer, 127, 0, 0, 1);
  qos.wire_protocol().builtin.initialPeersList.push_back(peer);
  return DomainParticipantFactory::get_instance()->create_participant(0, qos);
}

static std::vector<uint8_t> read_file(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return std::vector<uint8_t>(std::istreambuf_iterator<char>(f), {});
}

static int subscribe(const std::string& topic, int count, const std::string& out, double timeout) {
  DomainParticipant* p = participant();
  TypeSupport type(new sm::Image_PubSubType());
  type.register_type(p);
  Topic* t = p->create_topic(topic, type.get_type_name(), TOPIC_QOS_DEFAULT);
  DataReaderQos rq = DATAREADER_QOS_DEFAULT;
  rq.reliability().kind = RELIABLE_RELIABILITY_QOS;
  rq.history().kind = KEEP_LAST_HISTORY_QOS;
  rq.history().depth = 10;
  DataReader* r = p->create_subscriber(SUBSCRIBER_QOS_DEFAULT)->create_datareader(t, rq);
  int got = 0;
  auto end = Clock::now() + std::chrono::duration<double>(timeout);
  sm::Image_ m;
  SampleInfo info;
  while (got < count && Clock::now() < end) {
    if (r->take_next_sample(&m, &info) != ReturnCode_t::RETCODE_OK) {
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
      continue;
    }
    if (!info.valid_data) continue;
    std::ofstream(out + "/" + std::to_string(got) + ".bin", std::ios::binary)
        .write(reinterpret_cast<const char*>(m.data().data()), m.data().size());
    std::printf("%d %u %s %u %u %s %u\n", m.header().stamp().sec(), m.header().stamp().nanosec(),
                m.header().frame_id().c_str(), m.width(), m.height(), m.encoding().c_str(), m.step());
    std::fflush(stdout);
    ++got;
  }
  p->delete_contained_entities();
  DomainParticipantFactory::get_instance()->delete_participant(p);
  return got == count ? 0 : 1;
}

template <class T>
static void stamp(T& m, long long ns, const std::string& frame) {
  m.header().stamp().sec(static_cast<int32_t>(ns / 1000000000LL));
  m.header().stamp().nanosec(static_cast<uint32_t>(ns % 1000000000LL));
  m.header().frame_id(frame);
}

static sm::PointCloud2_ cloud(const std::vector<uint8_t>& xyz) {
  sm::PointCloud2_ c;
  for (int i = 0; i < 3; ++i) {
    sm::PointField_ f;
    f.name(std::string(1, "xyz"[i]));
    f.offset(4 * i);
    f.datatype(7);  // FLOAT32
    f.count(1);
    c.fields().push_back(f);
  }
  c.height(1);
  c.width(static_cast<uint32_t>(xyz.size() / 12));
  c.is_bigendian(false);
  c.point_step(12);
  c.row_step(static_cast<uint32_t>(xyz.size()));
  c.data(xyz);
  c.is_dense(true);
  return c;
}

static int publish(const std::string& image_topic, const std::string& points_topic, const std::string& dir,
                   double timeout) {
  std::ifstream meta(dir + "/meta.txt");
  unsigned w, h, frames;
  std::string camera, lidar;
  meta >> w >> h >> frames >> camera >> lidar;
  std::vector<sm::Image_> images(frames);
  std::vector<sm::PointCloud2_> clouds(frames);
  for (unsigned i = 0; i < frames; ++i) {
    long long ns;
    unsigned n;
    meta >> ns >> n;
    images[i].height(h);
    images[i].width(w);
    images[i].encoding("rgb8");
    images[i].is_bigendian(0);
    images[i].step(3 * w);
    images[i].data(read_file(dir + "/rgb_" + std::to_string(i) + ".bin"));
    stamp(images[i], ns, camera);
    clouds[i] = cloud(read_file(dir + "/points_" + std::to_string(i) + ".bin"));
    stamp(clouds[i], ns, lidar);
  }
  DomainParticipant* p = participant();
  TypeSupport itype(new sm::Image_PubSubType()), ctype(new sm::PointCloud2_PubSubType());
  itype.register_type(p);
  ctype.register_type(p);
  DataWriterQos wq = DATAWRITER_QOS_DEFAULT;
  wq.reliability().kind = BEST_EFFORT_RELIABILITY_QOS;  // a camera driver's sensor-data profile
  wq.history().depth = 5;
  Publisher* pub = p->create_publisher(PUBLISHER_QOS_DEFAULT);
  DataWriter* iw = pub->create_datawriter(p->create_topic(image_topic, itype.get_type_name(), TOPIC_QOS_DEFAULT), wq);
  DataWriter* cw = pub->create_datawriter(p->create_topic(points_topic, ctype.get_type_name(), TOPIC_QOS_DEFAULT), wq);
  auto end = Clock::now() + std::chrono::duration<double>(timeout);
  for (unsigned i = 0; Clock::now() < end; i = (i + 1) % frames) {
    iw->write(&images[i]);
    cw->write(&clouds[i]);  // after its image: the node pairs the image once a scan at or after it came
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  p->delete_contained_entities();
  DomainParticipantFactory::get_instance()->delete_participant(p);
  return 0;
}

int main(int argc, char** argv) {
  std::string mode = argc > 1 ? argv[1] : "";
  if (mode == "sub" && argc == 6) return subscribe(argv[2], std::atoi(argv[3]), argv[4], std::atof(argv[5]));
  if (mode == "pub" && argc == 6) return publish(argv[2], argv[3], argv[4], std::atof(argv[5]));
  std::fprintf(stderr, "usage: %s sub TOPIC COUNT OUTDIR TIMEOUT_S | pub IMAGE_TOPIC POINTS_TOPIC DIR TIMEOUT_S\n",
               argv[0]);
  return 2;
}

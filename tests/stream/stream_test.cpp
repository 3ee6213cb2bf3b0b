// The live streams: the destination's text form and its board-file key, the conversion to
// Unity's frame, and a stream that sends each pose to a socket, or counts the sends a refusing
// destination makes fail without ever holding anything up. The protocols themselves are checked
// by an independent receiver (stream_receive_check.py) on a real capture.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <numbers>
#include <random>
#include <set>
#include <thread>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include "board/loader.h"
#include "board/stream_spec.h"
#include "firmware/stream/encoders.h"
#include "firmware/stream/pose_stream.h"
#include "firmware/stream/unity_frame.h"
#include "hal/core/clock.h"

namespace caphub::firmware {
namespace {

using ::testing::HasSubstr;

TEST(StreamSpec, ParsesKindHostPortAndRate) {
    auto s = board::parseStreamSpec("vmc:192.168.1.20:39540@120");
    ASSERT_TRUE(s) << s.error().message;
    EXPECT_EQ(s->kind, board::StreamKind::Vmc);
    EXPECT_EQ(s->host, "192.168.1.20");
    EXPECT_EQ(s->port, 39540);
    EXPECT_EQ(s->rateHz, 120);
    EXPECT_EQ(board::toString(*s), "vmc:192.168.1.20:39540@120");
}

TEST(StreamSpec, FillsInTheKindsDefaults) {
    auto vr = board::parseStreamSpec("vrchat");
    ASSERT_TRUE(vr);
    EXPECT_EQ(vr->host, "127.0.0.1");
    EXPECT_EQ(vr->port, 9000);
    EXPECT_EQ(vr->rateHz, 60);
    auto c = board::parseStreamSpec("caphub:[::1]@30");
    ASSERT_TRUE(c) << c.error().message;
    EXPECT_EQ(c->host, "::1");
    EXPECT_EQ(c->port, 39600);
    EXPECT_EQ(c->rateHz, 30);
    EXPECT_EQ(board::toString(*c), "caphub:[::1]:39600@30");
    auto v = board::parseStreamSpec("vmc:studio-pc");
    ASSERT_TRUE(v);
    EXPECT_EQ(v->host, "studio-pc");
    EXPECT_EQ(v->port, 39539);
}

TEST(StreamSpec, RejectsWhatItCannotUseSayingWhat) {
    const std::pair<const char*, const char*> cases[] = {
        {"osc:127.0.0.1:9000", "unknown kind 'osc'"},
        {"vmc:127.0.0.1:0", "the port '0'"},
        {"vmc:127.0.0.1:70000", "the port '70000'"},
        {"vmc:127.0.0.1:port", "the port 'port'"},
        {"vmc:127.0.0.1:", "an empty port"},
        {"vmc::39539", "an empty host"},
        {"vmc:127.0.0.1:39539@0", "the rate '0'"},
        {"vmc:127.0.0.1:39539@fast", "the rate 'fast'"},
        {"vmc:[::1:39539", "closing ']'"},
        // A second '@' streamed to the host "h@60".
        {"vmc:h@60@70", "the host 'h@60' is not a host name or an address"},
        {"vmc:a/b:9000", "the host 'a/b'"},
    };
    for (const auto& [spec, what] : cases) {
        auto s = board::parseStreamSpec(spec);
        ASSERT_FALSE(s) << spec;
        EXPECT_EQ(s.error().code, EINVAL);
        EXPECT_THAT(s.error().message, HasSubstr(what)) << spec;
        EXPECT_THAT(s.error().message, HasSubstr("KIND:HOST:PORT[@RATE]")) << spec;
    }
}

const std::string kBoard = R"(schema = 1
name = "test"

[[bus]]
name = "i2c1"
type = "i2c"
device = "/dev/i2c-1"
clock_hz = 400000

[[mux]]
name = "mux0"
bus = "i2c1"
address = 0x70

[[sensor]]
name = "a"
segment = "pelvis"
chip = "icm20948"
bus = "i2c1"
mux = "mux0"
channel = 0
address = 0x68
odr_hz = 100
)";

TEST(StreamSpec, TheBoardsOutputsListStreams) {
    const auto r = board::loadBoardText(
        kBoard + "\n[outputs]\nstreams = [\"vmc:127.0.0.1:39539@60\", \"vrchat\"]\n", "t.toml");
    ASSERT_TRUE(r.ok()) << r.errors[0].str();
    ASSERT_EQ(r.board->outputs.streams.size(), 2u);
    EXPECT_EQ(r.board->outputs.streams[0].kind, board::StreamKind::Vmc);
    EXPECT_EQ(r.board->outputs.streams[1].kind, board::StreamKind::VrChat);
    EXPECT_EQ(r.board->outputs.streams[1].port, 9000);
}

TEST(StreamSpec, ABadStreamInTheBoardIsReportedWithItsLineAndKey) {
    const std::string text = kBoard + "\n[outputs]\nstreams = [\"vmc\",\n  \"vmc:h:99999\"]\n";
    const auto r = board::loadBoardText(text, "t.toml");
    ASSERT_FALSE(r.ok());
    ASSERT_EQ(r.errors.size(), 1u);
    EXPECT_EQ(r.errors[0].key, "outputs.streams");
    EXPECT_EQ(r.errors[0].where.file, "t.toml");
    EXPECT_EQ(
        r.errors[0].where.line,
        1 + std::count(text.begin(), text.begin() + static_cast<long>(text.find("vmc:h:")), '\n'));
    EXPECT_THAT(r.errors[0].message, HasSubstr("element 1"));
    EXPECT_THAT(r.errors[0].message, HasSubstr("the port '99999'"));

    const auto notArray =
        board::loadBoardText(kBoard + "\n[outputs]\nstreams = \"vmc\"\n", "t.toml");
    ASSERT_EQ(notArray.errors.size(), 1u);
    EXPECT_EQ(notArray.errors[0].key, "outputs.streams");
    EXPECT_THAT(notArray.errors[0].message, HasSubstr("expected an array"));
}

Eigen::Quaternionf randomRotation(std::mt19937& rng) {
    std::normal_distribution<float> n;
    return Eigen::Quaternionf(n(rng), n(rng), n(rng), n(rng)).normalized();
}

double angleDeg(const Eigen::Quaternionf& a, const Eigen::Quaternionf& b) {
    return a.cast<double>().angularDistance(b.cast<double>()) * 180.0 / std::numbers::pi;
}

TEST(UnityFrame, ARotationIsMirroredAcrossX) {
    // Unity's frame is caphub's with x negated: a rotation R there is M R M, M = diag(-1, 1, 1).
    const Eigen::Matrix3f m = Eigen::Vector3f(-1, 1, 1).asDiagonal();
    std::mt19937 rng(7);
    for (int i = 0; i < 100; ++i) {
        const Eigen::Quaternionf q = randomRotation(rng);
        const Eigen::Matrix3f expected = m * q.toRotationMatrix() * m;
        EXPECT_TRUE(unity::rotation(q).toRotationMatrix().isApprox(expected, 1e-5f));
        const Eigen::Vector3f v(0.3f, -1.2f, 0.7f);
        EXPECT_TRUE(
            unity::position(q * v).isApprox(unity::rotation(q) * unity::position(v), 1e-5f));
    }
    // The subject's left (+X in caphub) is Unity's -X; up and forward stay.
    EXPECT_EQ(unity::position({1, 2, 3}), Eigen::Vector3f(-1, 2, 3));
}

TEST(UnityFrame, EulerAnglesAreUnitysZxyOrderAndRoundTrip) {
    // 30 deg about Y alone is (0, 30, 0); about X then: Quaternion.Euler(x, y, z) = Y * X * Z.
    const float r = std::numbers::pi_v<float> / 180;
    const Eigen::Quaternionf yOnly(Eigen::AngleAxisf(30 * r, Eigen::Vector3f::UnitY()));
    EXPECT_TRUE(unity::eulerZxyDeg(yOnly).isApprox(Eigen::Vector3f(0, 30, 0), 1e-4f));
    const Eigen::Quaternionf composed = Eigen::AngleAxisf(40 * r, Eigen::Vector3f::UnitY()) *
                                        Eigen::AngleAxisf(20 * r, Eigen::Vector3f::UnitX()) *
                                        Eigen::AngleAxisf(-10 * r, Eigen::Vector3f::UnitZ());
    EXPECT_TRUE(unity::eulerZxyDeg(composed).isApprox(Eigen::Vector3f(20, 40, -10), 1e-3f))
        << unity::eulerZxyDeg(composed).transpose();
    std::mt19937 rng(11);
    for (int i = 0; i < 200; ++i) {
        const Eigen::Quaternionf q = randomRotation(rng);
        // float angles: a few 1e-4 deg.
        EXPECT_LT(angleDeg(unity::fromEulerZxyDeg(unity::eulerZxyDeg(q)), q), 0.01);
    }
    // Gimbal lock (x = +-90): still the same rotation.
    for (float x : {90.0f, -90.0f}) {
        const Eigen::Quaternionf q = unity::fromEulerZxyDeg({x, 25, 35});
        EXPECT_LT(angleDeg(unity::fromEulerZxyDeg(unity::eulerZxyDeg(q)), q), 0.01) << x;
    }
}

TEST(StreamEncoders, NameEveryBoneAndTrackerOnce) {
    std::set<std::string_view> names;
    for (int s = 0; s < body::kSegmentCount; ++s) {
        names.insert(vmcBoneName(s));
    }
    EXPECT_EQ(names.size(), static_cast<std::size_t>(body::kSegmentCount));
    EXPECT_EQ(vmcBoneName(body::idx(body::Segment::LForearm)), "LeftLowerArm");
    EXPECT_EQ(vrChatTrackerSegment(1), body::idx(body::Segment::Pelvis));
    EXPECT_EQ(vrChatHeadSegment(), body::idx(body::Segment::Skull));
}

TEST(StreamEncoders, VmcSplitsItsBonesIntoBundlesThatFitAFrame) {
    PoseFrame p;
    p.serial = 1;
    std::vector<Datagram> out;
    makeEncoder(board::StreamKind::Vmc)->encode(p, EncodeContext{}, out);
    ASSERT_GE(out.size(), 2u);
    for (const Datagram& d : out) {
        EXPECT_LE(d.size(), kMaxDatagram);
        ASSERT_GE(d.size(), 16u);
        EXPECT_EQ(std::string(reinterpret_cast<const char*>(d.data()), 7), "#bundle");
    }
}

// A UDP socket on 127.0.0.1 at a free port.
struct Receiver {
    int fd = ::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    int port = 0;
    Receiver() {
        sockaddr_in a{};
        a.sin_family = AF_INET;
        a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
        EXPECT_EQ(::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a), 0);
        socklen_t len = sizeof a;
        ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len);
        port = ntohs(a.sin_port);
        timeval tv{10, 0};  // generous: a loaded machine
        ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
    }
    ~Receiver() { ::close(fd); }
    // The next datagram's size, -1 when none came in time.
    ssize_t receive() {
        std::uint8_t buf[4096];
        return ::recv(fd, buf, sizeof buf, 0);
    }
};

PoseFrame poseNumber(std::uint64_t serial, const Clock& clock) {
    PoseFrame p;
    p.serial = serial;
    p.t = clock.now();
    p.newestSampleT = p.t;
    p.publishedT = p.t;
    return p;
}

TEST(PoseStream, SendsEachPoseThatComesToItsDestination) {
    Receiver rx;
    PoseFeed feed;
    MonotonicClock clock;
    board::StreamConfig config{board::StreamKind::Caphub, "127.0.0.1", rx.port, 1000};
    PoseStream stream(config, feed, clock);
    stream.start(clock.now());
    // The first pose: the skeleton's datagram, then the frame's.
    feed.publish(poseNumber(1, clock));
    EXPECT_GT(rx.receive(), 0);
    EXPECT_GT(rx.receive(), 0);
    for (std::uint64_t k = 2; k <= 5; ++k) {
        // At 1000 Hz a frame is due 1 ms after the last (a pose sooner would be skipped).
        std::this_thread::sleep_for(std::chrono::milliseconds(3));
        feed.publish(poseNumber(k, clock));
        EXPECT_GT(rx.receive(), 0) << k;  // each pose, woken by it (no polling)
    }
    stream.stop();
    EXPECT_EQ(stream.sent(), 5u);
    EXPECT_EQ(stream.errors(), 0u);
    EXPECT_EQ(stream.datagrams(), 6u);
    EXPECT_GT(stream.latencyPercentile(0.5), Duration{0});
}

TEST(PoseStream, PosesFasterThanItsRateAreSkippedNotDelayed) {
    Receiver rx;
    PoseFeed feed;
    MonotonicClock clock;
    PoseStream stream({board::StreamKind::VrChat, "127.0.0.1", rx.port, 20}, feed, clock);
    stream.start(clock.now());
    // 200 poses a second for half a second to a 20 Hz stream: about 10 frames (+2 of credit),
    // never more; each the pose that was newest when it went.
    const auto t0 = std::chrono::steady_clock::now();
    for (std::uint64_t k = 1; k <= 100; ++k) {
        feed.publish(poseNumber(k, clock));
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    stream.stop();
    const double elapsedS =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    // The credit starts at 1 and lets a frame go 10 % early: at most rate x time / 0.9 + 2.
    EXPECT_LE(stream.sent(), static_cast<std::uint64_t>(20 * elapsedS / 0.9) + 2);
    EXPECT_GE(stream.sent(), 2u);
}

TEST(PoseStream, ARefusingDestinationIsCountedNeverWaitedFor) {
    // A port nobody listens on: the kernel answers with ICMP port unreachable, which the next
    // send reports (ECONNREFUSED) - or the sends go out into nothing. Either way the stream keeps
    // taking poses, and publishing never waits for it.
    int port = 0;
    {
        Receiver closed;
        port = closed.port;
    }
    PoseFeed feed;
    MonotonicClock clock;
    PoseStream stream({board::StreamKind::Vmc, "127.0.0.1", port, 1000}, feed, clock);
    stream.start(clock.now());
    for (std::uint64_t k = 1; k <= 50; ++k) {
        feed.publish(poseNumber(k, clock));
        std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    // Wait (generously) until the stream has taken the last pose.
    for (int i = 0; i < 1000 && stream.sent() + stream.errors() < 10; ++i) {
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    stream.stop();
    EXPECT_GE(stream.sent() + stream.errors(), 10u);
    EXPECT_GT(stream.errors(), 0u) << "loopback reports the unreachable port";
    EXPECT_THAT(stream.lastError(), HasSubstr("refused"));
}

TEST(PoseStream, AHostThatCannotBeResolvedIsAnErrorNotAHang) {
    PoseFeed feed;
    MonotonicClock clock;
    PoseStream stream({board::StreamKind::Vmc, "no-such-host.invalid", 39539, 60}, feed, clock);
    stream.start(clock.now());
    for (int i = 0; i < 1000 && stream.errors() == 0; ++i) {
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    stream.stop();  // returns although the stream waits to try again
    EXPECT_GT(stream.errors(), 0u);
    EXPECT_THAT(stream.lastError(), HasSubstr("cannot resolve 'no-such-host.invalid'"));
}

}  // namespace
}  // namespace caphub::firmware

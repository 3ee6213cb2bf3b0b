// The MJPEG stream read by an HTTP client, and sinks that fail without stopping the capture.
#include <atomic>
#include <chrono>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <httplib.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include "render/mjpeg_server.h"
#include "render/sinks.h"

namespace caphub::render {
namespace {

Image gradient(int shift) {
    Image img(64, 48);
    for (int y = 0; y < img.height; ++y) {
        for (int x = 0; x < img.width; ++x) {
            auto* p = img.pixel(x, y);
            p[0] = static_cast<std::uint8_t>(x * 4 + shift);
            p[1] = static_cast<std::uint8_t>(y * 5);
            p[2] = static_cast<std::uint8_t>(shift);
        }
    }
    return img;
}

bool isJpeg(const std::string& b) {
    return b.size() > 4 && static_cast<unsigned char>(b[0]) == 0xFF &&
           static_cast<unsigned char>(b[1]) == 0xD8 &&
           static_cast<unsigned char>(b[b.size() - 2]) == 0xFF &&
           static_cast<unsigned char>(b[b.size() - 1]) == 0xD9;
}

TEST(Mjpeg, ClientReadsAtLeastFiveValidJpegFramesFromTheStream) {
    MjpegOptions o;
    o.port = 0;  // a free port on 127.0.0.1
    auto server = MjpegServer::start(o);
    ASSERT_TRUE(server) << server.error().message;
    const int port = (*server)->port();

    std::atomic<bool> done{false};
    std::thread producer([&] {
        for (int i = 0; !done && i < 400; ++i) {
            ASSERT_TRUE((*server)->publish(gradient(i)));
            std::this_thread::sleep_for(std::chrono::milliseconds(20));
        }
    });

    constexpr int kFrames = 5;
    std::string buffer;
    std::vector<std::string> frames;
    httplib::Client client("127.0.0.1", port);
    client.set_read_timeout(10, 0);
    std::string contentType;
    auto res = client.Get(
        "/stream",
        [&](const httplib::Response& r) {
            contentType = r.get_header_value("Content-Type");
            return true;
        },
        [&](const char* data, std::size_t len) {
            buffer.append(data, len);
            // Parts: headers with Content-Length, blank line, the JPEG.
            for (;;) {
                const auto h = buffer.find("Content-Length: ");
                const auto end = buffer.find("\r\n\r\n");
                if (h == std::string::npos || end == std::string::npos) {
                    break;
                }
                const std::size_t n = std::stoul(buffer.substr(h + 16));
                if (buffer.size() < end + 4 + n) {
                    break;
                }
                frames.push_back(buffer.substr(end + 4, n));
                buffer.erase(0, end + 4 + n);
            }
            return static_cast<int>(frames.size()) < kFrames;
        });
    done = true;
    producer.join();
    EXPECT_EQ(contentType.rfind("multipart/x-mixed-replace", 0), 0u) << contentType;
    ASSERT_GE(static_cast<int>(frames.size()), kFrames);
    for (const auto& f : frames) {
        EXPECT_TRUE(isJpeg(f)) << f.size();
    }
}

// A raw connection that sends a request (or nothing) and reads only the status line.
class RawClient {
public:
    explicit RawClient(int port) {
        fd_ = socket(AF_INET, SOCK_STREAM, 0);
        sockaddr_in a{};
        a.sin_family = AF_INET;
        a.sin_port = htons(static_cast<std::uint16_t>(port));
        a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
        connected_ = connect(fd_, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0;
        timeval tv{10, 0};
        setsockopt(fd_, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
    }
    ~RawClient() { close(fd_); }
    bool connected() const { return connected_; }
    void send(const std::string& text) {
        (void)::send(fd_, text.data(), text.size(), MSG_NOSIGNAL);
    }
    // The first line of the answer (empty when none came within 10 s).
    std::string statusLine() {
        std::string line;
        char c = 0;
        while (line.size() < 200 && recv(fd_, &c, 1, 0) == 1 && c != '\n') {
            line += c;
        }
        return line;
    }

private:
    int fd_ = -1;
    bool connected_ = false;
};

// Eight viewers of /stream (twice what the server lets watch) and eight idle connections that
// send nothing: 50 clients asking for /frame.jpg at once are all answered, in bounded time.
// Before, httplib's default eight threads were all held by the viewers and every further
// request hung (50 clients: 27 got nothing).
TEST(Mjpeg, ViewersAndIdleSocketsNeverStopRequestsBeingServed) {
    MjpegOptions o;
    o.port = 0;
    auto server = MjpegServer::start(o);
    ASSERT_TRUE(server) << server.error().message;
    const int port = (*server)->port();
    ASSERT_TRUE((*server)->publish(gradient(1)));
    std::atomic<bool> done{false};
    std::thread producer([&] {
        for (int i = 0; !done; ++i) {
            (void)(*server)->publish(gradient(i));
            std::this_thread::sleep_for(std::chrono::milliseconds(50));
        }
    });

    std::vector<std::unique_ptr<RawClient>> viewers;
    int accepted = 0;
    int refused = 0;
    for (int i = 0; i < 8; ++i) {
        auto c = std::make_unique<RawClient>(port);
        ASSERT_TRUE(c->connected());
        c->send("GET /stream HTTP/1.1\r\nHost: hub\r\n\r\n");
        const std::string status = c->statusLine();
        accepted += status.find(" 200") != std::string::npos;
        refused += status.find(" 503") != std::string::npos;
        viewers.push_back(std::move(c));
    }
    EXPECT_EQ(accepted, o.maxStreams);
    EXPECT_EQ(refused, 8 - o.maxStreams);
    std::vector<std::unique_ptr<RawClient>> idle;
    for (int i = 0; i < 8; ++i) {
        idle.push_back(std::make_unique<RawClient>(port));
    }

    std::atomic<int> served{0};
    std::vector<std::thread> clients;
    for (int i = 0; i < 50; ++i) {
        clients.emplace_back([&] {
            httplib::Client c("127.0.0.1", port);
            c.set_connection_timeout(30, 0);
            c.set_read_timeout(30, 0);
            auto res = c.Get("/frame.jpg");
            if (res && res->status == 200 && isJpeg(res->body)) {
                served.fetch_add(1);
            }
        });
    }
    for (auto& t : clients) {
        t.join();
    }
    EXPECT_EQ(served.load(), 50);
    EXPECT_EQ((*server)->streamsWatching(), o.maxStreams);
    viewers.clear();
    done = true;
    producer.join();
}

TEST(Mjpeg, PortTakenIsReportedWithTheAddress) {
    MjpegOptions o;
    o.port = 0;
    auto first = MjpegServer::start(o);
    ASSERT_TRUE(first) << first.error().message;
    o.port = (*first)->port();
    auto second = MjpegServer::start(o);
    ASSERT_FALSE(second);
    EXPECT_NE(second.error().message.find(std::to_string(o.port)), std::string::npos);
}

class FailingSink final : public FrameSink {
public:
    std::string name() const override { return "failing"; }
    Result<void> write(const Image&, std::uint64_t) override { return Error{EIO, "disk gone"}; }
};

class CountingSink final : public FrameSink {
public:
    explicit CountingSink(int& n) : n_(n) {}
    std::string name() const override { return "counting"; }
    Result<void> write(const Image&, std::uint64_t) override {
        ++n_;
        return {};
    }

private:
    int& n_;
};

TEST(Sinks, AFailingSinkIsDroppedWithItsReasonAndTheOthersGoOn) {
    SinkSet set;
    int written = 0;
    set.add(std::make_unique<FailingSink>());
    set.add(std::make_unique<CountingSink>(written));
    const Image img = gradient(0);
    for (std::uint64_t i = 0; i < 3; ++i) {
        set.write(img, i);
    }
    EXPECT_EQ(written, 3);
    EXPECT_EQ(set.liveCount(), 1u);
    ASSERT_EQ(set.failures().size(), 1u);
    EXPECT_NE(set.failures()[0].find("disk gone"), std::string::npos);
}

TEST(Sinks, PngFolderSinkWritesNumberedFrames) {
    const auto dir =
        std::filesystem::temp_directory_path() / ("caphub_png_sink_" + std::to_string(::getpid()));
    auto sink = makePngFolderSink(dir);
    ASSERT_TRUE(sink->write(gradient(1), 0));
    ASSERT_TRUE(sink->write(gradient(2), 1));
    auto back = readPng(dir / "frame_000001.png");
    ASSERT_TRUE(back) << back.error().message;
    EXPECT_EQ(back->rgb, gradient(2).rgb);
    std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace caphub::render

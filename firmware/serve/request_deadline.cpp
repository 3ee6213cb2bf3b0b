// RequestDeadlineServer (request_deadline.h): the connection loop and its stream.
#include "firmware/serve/request_deadline.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <cerrno>
#include <cstdlib>
#include <string>

#include <netdb.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

namespace caphub::firmware::serve {

namespace {

using DeadlineClock = std::chrono::steady_clock;

// A connected socket read with a deadline for the request and a timeout per read, written with
// a timeout per write (cpp-httplib's Stream interface).
class DeadlineStream final : public httplib::Stream {
public:
    DeadlineStream(socket_t sock, const std::atomic<socket_t>& listening,
                   std::chrono::milliseconds perRead, std::chrono::milliseconds perWrite)
        : sock_(sock), listening_(listening), perRead_(perRead), perWrite_(perWrite) {}

    void setDeadline(DeadlineClock::time_point deadline) { deadline_ = deadline; }

    // Waits for the socket to be readable within the per-read timeout and the deadline, in
    // slices that notice the server stopping.
    bool is_readable() const override {
        if (begin_ < end_) {
            return true;
        }
        const auto until = std::min(DeadlineClock::now() + perRead_, deadline_);
        return waitFor(POLLIN, until);
    }

    bool is_writable() const override { return waitFor(POLLOUT, DeadlineClock::now() + perWrite_); }

    ssize_t read(char* ptr, size_t size) override {
        if (begin_ == end_) {
            if (!is_readable()) {
                return -1;
            }
            ssize_t n;
            do {
                n = ::recv(sock_, buffer_.data(), buffer_.size(), 0);
            } while (n < 0 && errno == EINTR);
            if (n <= 0) {
                return n;
            }
            begin_ = 0;
            end_ = static_cast<std::size_t>(n);
        }
        const std::size_t n = std::min(size, end_ - begin_);
        std::copy_n(buffer_.data() + begin_, n, ptr);
        begin_ += n;
        return static_cast<ssize_t>(n);
    }

    ssize_t write(const char* ptr, size_t size) override {
        if (!is_writable()) {
            return -1;
        }
        ssize_t n;
        do {
            n = ::send(sock_, ptr, size, MSG_NOSIGNAL);
        } while (n < 0 && errno == EINTR);
        return n;
    }

    void get_remote_ip_and_port(std::string& ip, int& port) const override {
        sockaddr_storage addr{};
        socklen_t len = sizeof addr;
        if (::getpeername(sock_, reinterpret_cast<sockaddr*>(&addr), &len) == 0) {
            numericAddress(addr, len, ip, port);
        }
    }

    void get_local_ip_and_port(std::string& ip, int& port) const override {
        sockaddr_storage addr{};
        socklen_t len = sizeof addr;
        if (::getsockname(sock_, reinterpret_cast<sockaddr*>(&addr), &len) == 0) {
            numericAddress(addr, len, ip, port);
        }
    }

    socket_t socket() const override { return sock_; }

private:
    static void numericAddress(const sockaddr_storage& addr, socklen_t len, std::string& ip,
                               int& port) {
        std::array<char, NI_MAXHOST> host{};
        std::array<char, NI_MAXSERV> service{};
        if (::getnameinfo(reinterpret_cast<const sockaddr*>(&addr), len, host.data(), host.size(),
                          service.data(), service.size(), NI_NUMERICHOST | NI_NUMERICSERV) == 0) {
            ip = host.data();
            port = std::atoi(service.data());
        }
    }

    // Polls for `events` until `until`, 100 ms at a time so that a stopped server (its
    // listening socket closed) is noticed.
    bool waitFor(short events, DeadlineClock::time_point until) const {
        while (listening_.load() != INVALID_SOCKET) {
            const auto left =
                std::chrono::duration_cast<std::chrono::milliseconds>(until - DeadlineClock::now());
            if (left.count() <= 0) {
                return false;
            }
            pollfd p{sock_, events, 0};
            const int r = ::poll(&p, 1, static_cast<int>(std::min<long long>(left.count(), 100)));
            if (r > 0) {
                return (p.revents & (events | POLLHUP | POLLERR)) != 0;
            }
            if (r < 0 && errno != EINTR) {
                return false;
            }
        }
        return false;
    }

    socket_t sock_;
    const std::atomic<socket_t>& listening_;
    std::chrono::milliseconds perRead_;
    std::chrono::milliseconds perWrite_;
    DeadlineClock::time_point deadline_ = DeadlineClock::time_point::max();
    std::array<char, 4096> buffer_{};
    std::size_t begin_ = 0;
    std::size_t end_ = 0;
};

}  // namespace

bool RequestDeadlineServer::process_and_close_socket(socket_t sock) {
    using std::chrono::microseconds;
    using std::chrono::milliseconds;
    using std::chrono::seconds;
    const auto perRead = std::chrono::duration_cast<milliseconds>(seconds(read_timeout_sec_) +
                                                                  microseconds(read_timeout_usec_));
    const auto perWrite = std::chrono::duration_cast<milliseconds>(
        seconds(write_timeout_sec_) + microseconds(write_timeout_usec_));
    DeadlineStream stream(sock, svr_sock_, perRead, perWrite);
    bool ok = false;
    for (std::size_t left = std::max<std::size_t>(keep_alive_max_count_, 1); left > 0; --left) {
        // Each request, the first from the accept, the next from the answer before it.
        stream.setDeadline(DeadlineClock::now() + requestTimeout_);
        if (!stream.is_readable()) {
            break;
        }
        bool closed = false;
        ok = process_request(stream, left == 1, closed, nullptr);
        if (!ok || closed) {
            break;
        }
    }
    ::shutdown(sock, SHUT_RDWR);
    ::close(sock);
    return ok;
}

}  // namespace caphub::firmware::serve

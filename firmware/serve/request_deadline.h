// The HTTP server of `caphub serve` with a deadline for each request to arrive.
//
// cpp-httplib (Debian's 0.11.4) bounds each read by its read timeout, not a request as a whole:
// a client that sends its request line and headers a byte every few seconds holds a worker
// thread for as long as it likes, and as many such clients as there are workers leave the page
// and the API unanswered (slowloris). This server reads each connection through a stream that
// refuses to wait past a deadline: the request (line, headers and body: bodies are at most 16
// KiB here) must have arrived within `requestTimeoutS` of the connection's accept. What the
// request is answered with, once read, is bounded by the write timeout per write as before.
// The stream also gives up at once when the server stops.
#pragma once

#include <chrono>

#include <httplib.h>

namespace caphub::firmware::serve {

class RequestDeadlineServer : public httplib::Server {
public:
    // The longest from a connection's accept (or the answer before) to its request read in
    // full; > 0.
    void setRequestTimeout(std::chrono::milliseconds timeout) { requestTimeout_ = timeout; }

private:
    // Replaces the library's per-connection loop (a private virtual: overriding it is allowed);
    // the request itself is parsed and routed by the library's `process_request`.
    bool process_and_close_socket(socket_t sock) override;

    std::chrono::milliseconds requestTimeout_{10000};
};

}  // namespace caphub::firmware::serve

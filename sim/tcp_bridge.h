// wavemesh simulated board: the TCP side of the UART bridge.
//
// A non-blocking listening socket on 127.0.0.1 that serves one client at a time: a connection that
// comes while a client is served gets the protocol's ERROR BUSY frame and is closed, as the native
// device does (proto.h: wm_proto_busy_frame, WM_PROTO_BUSY_WAIT_MS), without holding up the simulation
// or the served client; a new client may connect after the previous one has left.
// Bytes the client sends queue in `rx` for the UART model; bytes the board sends are appended to
// `tx` and written out by service().  Nothing here blocks except wait_for_client().
#pragma once

#include <chrono>
#include <cstdint>
#include <deque>
#include <string>
#include <vector>

class TcpBridge {
public:
    TcpBridge() = default;
    ~TcpBridge();
    TcpBridge(const TcpBridge &) = delete;
    TcpBridge &operator=(const TcpBridge &) = delete;

    // Listen on 127.0.0.1:port (0 = any free port).  False with a message in error() on failure.
    bool listen_on(int port);
    int port() const { return port_; }
    const std::string &error() const { return error_; }

    // Accept a waiting client, read what it sent (up to a bounded queue), write pending output.
    // Returns false when the connected client has just left (or its socket failed).
    bool service();
    // Block until a client connects or timeout_ms passes; true when one is connected.
    bool wait_for_client(int timeout_ms);
    // Write all pending output (blocking up to timeout_ms); used before exiting.
    void flush(int timeout_ms);

    bool connected() const { return client_ >= 0; }
    std::deque<uint8_t> rx;  // received from the client, oldest first
    std::string tx;          // to send to the client

    uint64_t bytes_in = 0;
    uint64_t bytes_out = 0;

private:
    using Clock = std::chrono::steady_clock;
    // A connection being refused: waiting for its first bytes (then the BUSY frame goes out and our
    // side ends), then waiting for it to close; closed by `until` either way.
    struct Refused {
        int fd;
        bool sent;
        Clock::time_point until;
    };

    void accept_pending();
    void refuse_pending();
    void drop_client();

    std::vector<Refused> refused_;

    int listen_ = -1;
    int client_ = -1;
    int port_ = 0;
    std::string error_;
};

// wavemesh simulated board: the TCP side of the UART bridge (see tcp_bridge.h).
#include "tcp_bridge.h"

#include <algorithm>
#include <arpa/inet.h>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <fcntl.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include "proto.h"

namespace {

// Most bytes kept waiting for the UART: the rest stay in the kernel's buffer (TCP back-pressure).
constexpr size_t RX_QUEUE_MAX = 64 * 1024;
// Connections being refused at once; more wait in the listen backlog until these are done.
constexpr size_t REFUSED_MAX = 8;

void set_nonblocking(int fd) {
    int flags = fcntl(fd, F_GETFL, 0);
    fcntl(fd, F_SETFL, flags | O_NONBLOCK);
}

}  // namespace

TcpBridge::~TcpBridge() {
    drop_client();
    for (const Refused &r : refused_) close(r.fd);
    if (listen_ >= 0) close(listen_);
}

bool TcpBridge::listen_on(int port) {
    listen_ = socket(AF_INET, SOCK_STREAM, 0);
    if (listen_ < 0) {
        error_ = std::string("socket: ") + strerror(errno);
        return false;
    }
    int one = 1;
    setsockopt(listen_, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
    sockaddr_in addr{};
    addr.sin_family = AF_INET;
    addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    addr.sin_port = htons(static_cast<uint16_t>(port));
    if (bind(listen_, reinterpret_cast<sockaddr *>(&addr), sizeof addr) < 0) {
        error_ = "bind 127.0.0.1:" + std::to_string(port) + ": " + strerror(errno);
        return false;
    }
    if (::listen(listen_, 4) < 0) {
        error_ = std::string("listen: ") + strerror(errno);
        return false;
    }
    socklen_t len = sizeof addr;
    getsockname(listen_, reinterpret_cast<sockaddr *>(&addr), &len);
    port_ = ntohs(addr.sin_port);
    set_nonblocking(listen_);
    return true;
}

void TcpBridge::accept_pending() {
    for (;;) {
        if (client_ >= 0 && refused_.size() >= REFUSED_MAX) return;
        int fd = accept(listen_, nullptr, nullptr);
        if (fd < 0) return;  // EAGAIN: nobody waiting
        set_nonblocking(fd);
        if (client_ >= 0) {  // one client at a time: this one gets ERROR BUSY (refuse_pending)
            refused_.push_back({fd, false, Clock::now() + std::chrono::milliseconds(WM_PROTO_BUSY_WAIT_MS)});
            continue;
        }
        int one = 1;
        setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
        client_ = fd;
        rx.clear();
        tx.clear();
        fprintf(stdout, "wmsim: client connected\n");
        fflush(stdout);
    }
}

void TcpBridge::refuse_pending() {
    Clock::time_point now = Clock::now();
    for (size_t i = 0; i < refused_.size();) {
        Refused &r = refused_[i];
        uint8_t junk[256];
        ssize_t n = recv(r.fd, junk, sizeof junk, 0);
        bool gone = n == 0 || (n < 0 && errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR);
        if (!r.sent && !gone && (n > 0 || now >= r.until)) {  // its first bytes, or the wait ended
            uint8_t frame[WM_PROTO_BUSY_FRAME_MAX];
            size_t len = wm_proto_busy_frame(frame, sizeof frame);
            if (send(r.fd, frame, len, MSG_NOSIGNAL | MSG_DONTWAIT) < 0) {  // nothing more to do for it
            }
            shutdown(r.fd, SHUT_WR);
            r.sent = true;
            r.until = now + std::chrono::milliseconds(WM_PROTO_BUSY_WAIT_MS);
            fprintf(stdout, "wmsim: second client refused (busy)\n");
            fflush(stdout);
        } else if (gone || (r.sent && now >= r.until)) {
            close(r.fd);
            refused_.erase(refused_.begin() + static_cast<std::ptrdiff_t>(i));
            continue;
        }
        ++i;
    }
}

void TcpBridge::drop_client() {
    if (client_ >= 0) close(client_);
    client_ = -1;
    rx.clear();
    tx.clear();
}

bool TcpBridge::service() {
    accept_pending();
    if (!refused_.empty()) refuse_pending();
    if (client_ < 0) {
        tx.clear();  // a board's UART talks to nobody
        return true;
    }
    // read
    uint8_t buf[4096];
    while (rx.size() < RX_QUEUE_MAX) {
        ssize_t n = recv(client_, buf, sizeof buf, 0);
        if (n > 0) {
            rx.insert(rx.end(), buf, buf + n);
            bytes_in += static_cast<uint64_t>(n);
            continue;
        }
        if (n == 0 || (errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR)) {
            drop_client();
            return false;
        }
        break;
    }
    // write
    while (!tx.empty()) {
        ssize_t n = send(client_, tx.data(), tx.size(), MSG_NOSIGNAL);
        if (n > 0) {
            bytes_out += static_cast<uint64_t>(n);
            tx.erase(0, static_cast<size_t>(n));
            continue;
        }
        if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK || errno == EINTR)) break;
        drop_client();
        return false;
    }
    return true;
}

bool TcpBridge::wait_for_client(int timeout_ms) {
    accept_pending();
    if (!refused_.empty()) refuse_pending();
    if (client_ >= 0) return true;
    pollfd p{listen_, POLLIN, 0};
    if (poll(&p, 1, refused_.empty() ? timeout_ms : std::min(timeout_ms, 10)) > 0) accept_pending();
    return client_ >= 0;
}

void TcpBridge::flush(int timeout_ms) {
    while (client_ >= 0 && !tx.empty()) {
        pollfd p{client_, POLLOUT, 0};
        if (poll(&p, 1, timeout_ms) <= 0) return;
        ssize_t n = send(client_, tx.data(), tx.size(), MSG_NOSIGNAL);
        if (n <= 0) return;
        bytes_out += static_cast<uint64_t>(n);
        tx.erase(0, static_cast<size_t>(n));
    }
}

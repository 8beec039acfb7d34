// wavemesh simulated board: the TCP side of the UART bridge (see tcp_bridge.h).
#include "tcp_bridge.h"

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

namespace {

// Most bytes kept waiting for the UART: the rest stay in the kernel's buffer (TCP back-pressure).
constexpr size_t RX_QUEUE_MAX = 64 * 1024;

void set_nonblocking(int fd) {
    int flags = fcntl(fd, F_GETFL, 0);
    fcntl(fd, F_SETFL, flags | O_NONBLOCK);
}

}  // namespace

TcpBridge::~TcpBridge() {
    drop_client();
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
        int fd = accept(listen_, nullptr, nullptr);
        if (fd < 0) return;  // EAGAIN: nobody waiting
        if (client_ >= 0) {
            // one client at a time
            fprintf(stdout, "wmsim: refused a second client\n");
            fflush(stdout);
            close(fd);
            continue;
        }
        set_nonblocking(fd);
        int one = 1;
        setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
        client_ = fd;
        rx.clear();
        tx.clear();
        fprintf(stdout, "wmsim: client connected\n");
        fflush(stdout);
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
    if (client_ >= 0) return true;
    pollfd p{listen_, POLLIN, 0};
    if (poll(&p, 1, timeout_ms) > 0) accept_pending();
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

#!/usr/bin/env python3
"""A small HTTP proxy on 127.0.0.1 that passes GETs (with their Range header) to a web server on
127.0.0.1 and can spoil the answers, for volreel's tests of remote reading.

    fault_proxy.py UPSTREAM_PORT MODE_FILE [RATE]

It prints the port it listens on, then serves until killed. With RATE (bytes per second) every
body goes out in chunks paced by one token bucket shared by all connections: a link of that rate,
first come first served (nginx's limit_rate applies per request and lets each request start with a
second's worth of bytes). Before every request it reads
MODE_FILE (missing or empty: "pass"):
    pass        the upstream's answer as it is
    flip        byte ranges (HTTP 206) with one byte of the body changed
    flip frames every answer for a file under frames/ with one byte of the body changed
    truncate    half of the body, then the connection closed (Content-Length promises all of it)
    stall       one byte of the body, then nothing for 60 seconds
    stall half  half of the body at once, then nothing for 60 seconds
    status N    HTTP status N with an empty body, the upstream not asked
    page N      HTTP status N with a 10 kB HTML page (longer than a brick), the upstream not asked
    auth T      HTTP 401 unless the request has "Authorization: Basic T", else as pass
    whole       the request passed without its Range header: the whole file, HTTP 200 (a server
                that does not serve byte ranges)
"""
import http.client
import http.server
import socket
import sys
import threading
import time

UPSTREAM = int(sys.argv[1])
MODE_FILE = sys.argv[2]
RATE = float(sys.argv[3]) if len(sys.argv) > 3 else 0.0
CHUNK = 16384
link_lock = threading.Lock()
link_free = 0.0  # when the shared link has sent everything handed to it so far


def send_paced(wfile, body):
    """Writes body in chunks, each after the link has had the time to carry it."""
    global link_free
    for at in range(0, len(body), CHUNK):
        chunk = body[at : at + CHUNK]
        if RATE > 0:
            with link_lock:
                link_free = max(link_free, time.monotonic()) + len(chunk) / RATE
                due = link_free
            time.sleep(max(0.0, due - time.monotonic()))
        wfile.write(chunk)
PASSED_HEADERS = ("content-range", "content-type", "etag", "last-modified", "accept-ranges")


def mode():
    try:
        with open(MODE_FILE) as f:
            return f.read().strip() or "pass"
    except FileNotFoundError:
        return "pass"


class Handler(http.server.BaseHTTPRequestHandler):
    protocol_version = "HTTP/1.1"

    def do_GET(self):
        m = mode()
        if m.startswith("auth "):
            if self.headers.get("Authorization") != "Basic " + m.split()[1]:
                self.send_response(401)
                self.send_header("WWW-Authenticate", 'Basic realm="test"')
                self.send_header("Content-Length", "0")
                self.end_headers()
                return
            m = "pass"
        if m.startswith("status ") or m.startswith("page "):
            page = b"" if m.startswith("status ") else b"<html>" + b"busy " * 2048 + b"</html>"
            self.send_response(int(m.split()[1]))
            self.send_header("Content-Length", str(len(page)))
            if page:
                self.send_header("Content-Type", "text/html")
            self.end_headers()
            self.wfile.write(page)
            return
        upstream = http.client.HTTPConnection("127.0.0.1", UPSTREAM, timeout=30)
        headers = {k: v for k, v in self.headers.items() if k.lower() == "range" and m != "whole"}
        upstream.request("GET", self.path, headers=headers)
        answer = upstream.getresponse()
        body = bytearray(answer.read())
        upstream.close()
        if m == "flip" and answer.status == 206 and body:
            body[len(body) // 2] ^= 0x40
        if m == "flip frames" and "/frames/" in self.path and body:
            body[len(body) // 2] ^= 0x40
        self.send_response(answer.status)
        for k, v in answer.getheaders():
            if k.lower() in PASSED_HEADERS:
                self.send_header(k, v)
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        if m == "truncate":
            self.wfile.write(body[: len(body) // 2])
            self.wfile.flush()
            self.close_connection = True
            self.connection.shutdown(socket.SHUT_RDWR)
        elif m in ("stall", "stall half"):
            self.wfile.write(body[: 1 if m == "stall" else len(body) // 2])
            self.wfile.flush()
            time.sleep(60)
            self.close_connection = True
        else:
            send_paced(self.wfile, body)

    def log_message(self, *args):
        pass


class Server(http.server.ThreadingHTTPServer):
    daemon_threads = True


if __name__ == "__main__":
    server = Server(("127.0.0.1", 0), Handler)
    print(server.server_address[1], flush=True)
    server.serve_forever()

#!/usr/bin/python3
"""What 50 web clients cost the capture: `caphub serve` on the virtual suit for SECONDS, once with
no client and once with 50 (40 polling the state 4 times a second, every fifth request the take
list; 10 holding the live pose stream), all on 127.0.0.1. Prints, per run, what the hub printed
at its end (samples, dropped, sensor losses, pose latency p50/p99) and the clients' requests
served, failed, and their slowest answer.

usage: serve_load.py CAPHUB [SECONDS] [BOARD]     (a release build; docs/serve.md has figures)
"""
import http.client
import json
import re
import signal
import subprocess
import sys
import tempfile
import threading
import time


def start_hub(caphub, board, tmp, tag):
    p = subprocess.Popen(
        [caphub, "serve", "--board", board, "--listen", "127.0.0.1:0",
         "--recordings", f"{tmp}/{tag}-rec", "--state-dir", f"{tmp}/{tag}-state",
         "--status-file", f"{tmp}/{tag}-status.json"],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    lines = []
    port = []

    def read():
        for line in p.stdout:
            lines.append(line)
            m = re.search(r"http://127\.0\.0\.1:(\d+)/", line)
            if m:
                port.append(int(m.group(1)))

    threading.Thread(target=read, daemon=True).start()
    for _ in range(600):
        if port:
            return p, port[0], lines
        time.sleep(0.1)
    raise SystemExit("caphub serve did not start: " + "".join(lines))


def login(port):
    c = http.client.HTTPConnection("127.0.0.1", port, timeout=30)
    c.request("POST", "/api/login", body="{}", headers={"Content-Type": "application/json"})
    r = c.getresponse()
    r.read()
    return r.getheader("Set-Cookie").split(";")[0]


def run(caphub, board, seconds, clients, tmp, tag):
    hub, port, lines = start_hub(caphub, board, tmp, tag)
    cookie = login(port)
    stats = {"served": 0, "failed": 0, "slowest": 0.0, "pose_events": 0}
    lock = threading.Lock()
    end = time.monotonic() + seconds

    def poller(i):
        c = http.client.HTTPConnection("127.0.0.1", port, timeout=30)
        k = 0
        while time.monotonic() < end:
            path = "/api/takes" if k % 5 == 4 else "/api/state"
            k += 1
            t0 = time.monotonic()
            try:
                c.request("GET", path, headers={"Cookie": cookie})
                r = c.getresponse()
                body = r.read()
                ok = r.status == 200 and (path != "/api/state" or "sensors" in json.loads(body))
            except Exception:
                ok = False
                c = http.client.HTTPConnection("127.0.0.1", port, timeout=30)
            dt = time.monotonic() - t0
            with lock:
                stats["served" if ok else "failed"] += 1
                stats["slowest"] = max(stats["slowest"], dt)
            time.sleep(0.25)

    def streamer(i):
        c = http.client.HTTPConnection("127.0.0.1", port, timeout=30)
        c.request("GET", "/api/poses", headers={"Cookie": cookie})
        r = c.getresponse()
        n = 0
        while time.monotonic() < end:
            line = r.fp.readline()
            if not line:
                break
            n += line.startswith(b"data: ")
        with lock:
            stats["pose_events"] += n
        c.close()

    threads = [threading.Thread(target=streamer if i % 5 == 0 else poller, args=(i,))
               for i in range(clients)]
    for t in threads:
        t.start()
    time.sleep(seconds)
    for t in threads:
        t.join()
    hub.send_signal(signal.SIGTERM)
    hub.wait(timeout=60)
    time.sleep(0.2)
    final = [l for l in lines if "caphub serve: stopped" in l]
    print(f"{clients} clients, {seconds} s: {final[0].strip() if final else 'no final line'}")
    if clients:
        print(f"  clients: {stats['served']} requests served, {stats['failed']} failed, slowest "
              f"{stats['slowest'] * 1e3:.0f} ms; {stats['pose_events']} pose events on "
              f"{clients // 5} streams")


def main():
    caphub = sys.argv[1]
    seconds = int(sys.argv[2]) if len(sys.argv) > 2 else 60
    board = sys.argv[3] if len(sys.argv) > 3 else "sim-suit"
    with tempfile.TemporaryDirectory() as tmp:
        run(caphub, board, seconds, 0, tmp, "idle")
        run(caphub, board, seconds, 50, tmp, "load")


if __name__ == "__main__":
    main()

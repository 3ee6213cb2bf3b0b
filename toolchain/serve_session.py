#!/usr/bin/env python3
"""The README's main command's session: `caphub serve` on the virtual suit (127.0.0.1 only),
operated through its HTTP API as the web page does it (docs/serve.md):

  1. the sensors' guided calibration (gyroscopes at rest, accelerometers in six positions,
     magnetometers turned), saved in the hub's state folder; the hub is restarted, which
     applies it;
  2. the body's calibration in the T-pose the virtual subject holds at the start;
  3. two named takes (the second with a marker), then exports (BVH and glb) of each made and
     downloaded through the API.

usage: serve_session.py CAPHUB BOARD OUT      (Python's standard library only)
Writes OUT/state (calibration.toml), OUT/recordings (the takes), OUT/exports (the downloads),
OUT/serve-1.log and OUT/serve-2.log (what the hub printed); prints what it does.
"""
import http.client
import json
import os
import re
import subprocess
import sys
import threading
import time


class Hub:
    """`caphub serve` in the background, on a free port of 127.0.0.1."""

    def __init__(self, caphub, board, out, log, extra=(), preview=None):
        self.log = open(log, "w")
        # The preview: PNGs of the hub's rendered view at 2 frames a second, or none.
        shown = ["--preview", preview, "--preview-fps", "2"] if preview else ["--no-preview"]
        self.proc = subprocess.Popen(
            [caphub, "serve", "--board", board, "--listen", "127.0.0.1:0",
             "--state-dir", f"{out}/state", "--recordings", f"{out}/recordings",
             "--status-file", f"{out}/status.json", *shown, *extra],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        self.lines = []
        port = []

        def read():
            for line in self.proc.stdout:
                self.lines.append(line)
                self.log.write(line)
                self.log.flush()
                m = re.search(r"http://127\.0\.0\.1:(\d+)/", line)
                if m:
                    port.append(int(m.group(1)))

        self.reader = threading.Thread(target=read, daemon=True)
        self.reader.start()
        for _ in range(600):
            if port or self.proc.poll() is not None:
                break
            time.sleep(0.1)
        if not port:
            self.proc.kill()
            sys.exit("caphub serve did not start:\n" + "".join(self.lines))
        self.port = port[0]
        self.cookie = ""
        self.csrf = ""
        login = self.call("POST", "/api/login", {})
        self.csrf = login["csrf"]

    def request(self, method, path, body=None, timeout=300):
        c = http.client.HTTPConnection("127.0.0.1", self.port, timeout=timeout)
        headers = {"Cookie": self.cookie, "X-CSRF-Token": self.csrf,
                   "Content-Type": "application/json"}
        data = json.dumps(body) if body is not None else ("{}" if method == "POST" else None)
        c.request(method, path, body=data, headers=headers)
        r = c.getresponse()
        payload = r.read()
        if r.getheader("Set-Cookie"):
            self.cookie = r.getheader("Set-Cookie").split(";")[0]
        c.close()
        if r.status >= 300:
            sys.exit(f"{method} {path}: {r.status} {payload[:300].decode(errors='replace')}")
        return r, payload

    def call(self, method, path, body=None):
        return json.loads(self.request(method, path, body)[1] or b"{}")

    def stop(self):
        self.proc.terminate()
        self.proc.wait(timeout=60)
        self.reader.join(timeout=5)
        self.log.close()
        return "".join(self.lines)


def sensor_calibration(hub, request):
    hub.call("POST", "/api/sensor-calibration", request)
    shown = ""
    for _ in range(3000):  # 5 minutes at most
        s = hub.call("GET", "/api/sensor-calibration")
        p = s["procedure"]
        step = p.get("step", "")
        key = p["stage"] + re.sub(r"\d+ s", "", step.split(":")[0])
        if step and key != shown:  # each position or phase once
            shown = key
            print(f"    {p['stage']}: {step}")
        if not s["running"]:
            break
        time.sleep(0.1)
    r = p.get("result", {})
    q = r.get("quality", {})
    if p["stage"] != "done":
        sys.exit(f"  {request['kind']}: {p['stage']}: {p['instruction']}")
    extra = f", {100 * q['coverage']:.0f} % of directions" if "coverage" in q else ""
    print(f"  {request['kind']}: {r['calibrated']} of {r['sensors_total']} sensors; "
          f"{q['figure']}: {q['value']:.3f} {q['unit']}{extra}; "
          f"{r['samples_dropped']} samples dropped")


def wait_state(hub, done, seconds):
    for _ in range(int(seconds * 10)):
        s = hub.call("GET", "/api/state")
        if done(s):
            return s
        time.sleep(0.1)
    return s


def main():
    if len(sys.argv) != 4:
        sys.exit(__doc__)
    caphub, board, out = sys.argv[1:]
    os.makedirs(f"{out}/exports", exist_ok=True)
    t0 = time.monotonic()

    print("1. sensor calibration (caphub serve; the virtual subject does each motion)")
    hub = Hub(caphub, board, out, f"{out}/serve-1.log")
    print(f"  hub on http://127.0.0.1:{hub.port}/")
    print("  gyroscopes: every sensor lying still")
    sensor_calibration(hub, {"kind": "gyro"})
    print("  accelerometers: each sensor held with each face up in turn")
    sensor_calibration(hub, {"kind": "accel", "positions": 6, "hold_s": 2, "move_s": 1})
    print("  magnetometers: each sensor turned through every direction")
    sensor_calibration(hub, {"kind": "mag", "duration_s": 20})
    hub.stop()

    print("2. body calibration (caphub serve again: it applies the sensor calibration)")
    hub = Hub(caphub, board, out, f"{out}/serve-2.log", ["--lead-in", "tpose", "--lead-in-s", "8"],
              preview=f"png:{out}/preview")
    state = hub.call("GET", "/api/state")
    print(f"  sensor calibration in force: {state['sensor_calibration']}")
    hub.call("POST", "/api/calibrate", {"pose": "tpose", "countdown_s": 0.5})
    state = wait_state(hub, lambda s: s["body"]["request"]["state"] in ("done", "failed"), 30)
    body = state["body"]
    print(f"  body: {body['request']['state']}: {body['calibration']} {body['request']['message']}")

    print("3. two named takes, exports downloaded through the API")
    takes = []
    for name, seconds in (("walk-1", 4), ("walk-2", 4)):
        hub.call("POST", "/api/take/start", {"name": name})
        time.sleep(seconds / 2)
        if name == "walk-2":
            hub.call("POST", "/api/take/marker", {"label": "half way"})
        time.sleep(seconds / 2)
        t = hub.call("POST", "/api/take/stop")
        takes.append(t["file"])
        print(f"  take {t['file']}: {t['records']} records")
    listed = {t["file"]: t for t in hub.call("GET", "/api/takes")["takes"]}
    downloads = []
    for file in takes:
        info = listed[file]
        print(f"  {file}: {info['duration_s']:.1f} s, {info['poses']} poses, "
              f"{info['markers']} markers")
        for fmt in ("bvh", "glb"):
            r, payload = hub.request("GET", f"/api/takes/{file}/export?format={fmt}")
            path = f"{out}/exports/{file[:-4]}.{fmt}"
            with open(path, "wb") as f:
                f.write(payload)
            downloads.append(path)
            print(f"    {fmt}: {len(payload)} bytes, {r.getheader('X-Caphub-Frames')} frames")
    tail = hub.stop().strip().splitlines()[-1]
    print(f"  {tail}")
    print(f"session: {time.monotonic() - t0:.1f} s")
    print()
    print(f"output: {out}/state/calibration.toml (the sensor calibration, applied at each start)")
    for file in takes:
        print(f"        {out}/recordings/{file} (a take)")
    for path in downloads:
        print(f"        {path} (downloaded export)")
    frames = sorted(os.listdir(f"{out}/preview")) if os.path.isdir(f"{out}/preview") else []
    if frames:
        print(f"        {out}/preview/ ({len(frames)} PNGs of the hub's preview, "
              f"{frames[0]} .. {frames[-1]})")
    print(f"        {out}/serve-1.log, {out}/serve-2.log (what the hub printed)")


if __name__ == "__main__":
    main()

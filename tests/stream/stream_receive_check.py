#!/usr/bin/env python3
"""The live streams as a receiver sees them: `caphub run` on the virtual suit streams VMC, VRChat
OSC and caphub's native protocol to UDP sockets on 127.0.0.1, which this script reads with its own
OSC decoder (no liblo: an independent implementation). It checks each protocol's addresses, types,
bone/tracker counts and rate, and that the rotations received are the recording's poses: the
recording is exported to CSV by `caphub export` and each frame received must equal one of its
rows (every segment within 0.5 deg after undoing Unity's convention; the native stream within
0.05 deg at exactly its serial's row). A destination that refuses (a closed port) gets sends that
fail and are counted, while the capture drops nothing and records every sample it takes (as a
capture without streams, run beside it for comparison).

Before that, the Blender add-on's receiver (pure Python, loaded without Blender) is fed malformed
datagrams of every kind and a flood: each is refused and counted, the next good frame is taken,
and one poll() is bounded.

usage: stream_receive_check.py CAPHUB WORKDIR [ADDON_PARENT]
"""
import csv
import math
import os
import re
import socket
import struct
import subprocess
import sys
import threading
import time

# ---------------------------------------------------------------------------------------------
# OSC 1.0: packets are messages or "#bundle" with an 8-byte time tag then size-prefixed elements.


def _osc_string(data, i):
    end = data.index(b"\0", i)
    return data[i:end].decode("ascii"), (end + 4) & ~3


def parse_osc(data, out):
    """Appends (address, typetags, args) for every message in the packet."""
    if data.startswith(b"#bundle\0"):
        i = 16
        while i < len(data):
            (n,) = struct.unpack_from(">i", data, i)
            i += 4
            parse_osc(data[i:i + n], out)
            i += n
        return
    address, i = _osc_string(data, 0)
    tags, i = _osc_string(data, i)
    if not tags.startswith(","):
        raise ValueError(f"{address}: no type tag string")
    args = []
    for t in tags[1:]:
        if t == "f":
            args.append(struct.unpack_from(">f", data, i)[0])
            i += 4
        elif t == "i":
            args.append(struct.unpack_from(">i", data, i)[0])
            i += 4
        elif t == "h":
            args.append(struct.unpack_from(">q", data, i)[0])
            i += 8
        elif t == "s":
            s, i = _osc_string(data, i)
            args.append(s)
        else:
            raise ValueError(f"{address}: unexpected type '{t}'")
    if i != len(data):
        raise ValueError(f"{address}: {len(data) - i} bytes after the arguments")
    out.append((address, tags, args))


class Receiver:
    """A UDP socket on 127.0.0.1 that keeps every datagram with its arrival time."""

    def __init__(self):
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.2)
        self.port = self.sock.getsockname()[1]
        self.packets = []
        self.running = True
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self):
        while self.running:
            try:
                data = self.sock.recv(65536)
            except socket.timeout:
                continue
            self.packets.append((time.monotonic(), data))

    def stop(self):
        time.sleep(0.3)
        self.running = False
        self.thread.join()
        self.sock.close()


# ---------------------------------------------------------------------------------------------
# Quaternions (w, x, y, z), Hamilton.


def qmul(a, b):
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw)


def qnorm(q):
    n = math.sqrt(sum(c * c for c in q))
    return tuple(c / n for c in q)


def angle_deg(a, b):
    d = abs(sum(x * y for x, y in zip(qnorm(a), qnorm(b))))
    return math.degrees(2 * math.acos(min(1.0, d)))


def axis_angle(axis, deg):
    h = math.radians(deg) / 2
    return (math.cos(h),) + tuple(math.sin(h) * c for c in axis)


def unity_to_caphub_rotation(q):
    # Unity's frame is caphub's with X negated (docs/streams.md): M R M, self-inverse.
    w, x, y, z = q
    return (w, x, -y, -z)


def unity_euler_to_quaternion(x, y, z):
    # Unity's Quaternion.Euler(x, y, z): about Z, then X, then Y (fixed axes): qY qX qZ.
    return qmul(qmul(axis_angle((0, 1, 0), y), axis_angle((1, 0, 0), x)),
                axis_angle((0, 0, 1), z))


# ---------------------------------------------------------------------------------------------

# Unity's humanoid hierarchy (HumanBodyBones) and the caphub segment each bone stands for.
UNITY_PARENT = {
    "Hips": None, "Spine": "Hips", "Chest": "Spine", "Neck": "Chest", "Head": "Neck",
    "LeftShoulder": "Chest", "LeftUpperArm": "LeftShoulder", "LeftLowerArm": "LeftUpperArm",
    "LeftHand": "LeftLowerArm", "RightShoulder": "Chest", "RightUpperArm": "RightShoulder",
    "RightLowerArm": "RightUpperArm", "RightHand": "RightLowerArm", "LeftUpperLeg": "Hips",
    "LeftLowerLeg": "LeftUpperLeg", "LeftFoot": "LeftLowerLeg", "LeftToes": "LeftFoot",
    "RightUpperLeg": "Hips", "RightLowerLeg": "RightUpperLeg", "RightFoot": "RightLowerLeg",
    "RightToes": "RightFoot",
}
UNITY_TO_SEGMENT = {
    "Hips": "pelvis", "Spine": "l5", "Chest": "t12", "Neck": "c7", "Head": "skull",
    "LeftShoulder": "l_clavicle", "LeftUpperArm": "l_upperarm", "LeftLowerArm": "l_forearm",
    "LeftHand": "l_hand", "RightShoulder": "r_clavicle", "RightUpperArm": "r_upperarm",
    "RightLowerArm": "r_forearm", "RightHand": "r_hand", "LeftUpperLeg": "l_thigh",
    "LeftLowerLeg": "l_calf", "LeftFoot": "l_hindfoot", "LeftToes": "l_middistal",
    "RightUpperLeg": "r_thigh", "RightLowerLeg": "r_calf", "RightFoot": "r_hindfoot",
    "RightToes": "r_middistal",
}
# VRChat's trackers (docs.vrchat.com, "OSC Trackers"): hip, chest, feet, knees, elbows; head.
VRCHAT_SEGMENT = {
    "1": "pelvis", "2": "t12", "3": "l_hindfoot", "4": "r_hindfoot", "5": "l_calf",
    "6": "r_calf", "7": "l_forearm", "8": "r_forearm", "head": "skull",
}

failures = []


def check(ok, what):
    if not ok:
        failures.append(what)
        print("FAIL:", what)
    return ok


def read_csv(path):
    rows = []
    with open(path, newline="") as f:
        reader = csv.reader(f)
        header = next(reader)
        segments = [h[:-3] for h in header if h.endswith("_qw")]
        for r in reader:
            # The numeric columns; the last one, not_measured, names the held segments.
            v = [float(x) for x in r[:1 + 7 * len(segments)]]
            row = {"t": v[0], "q": {}, "p": {}}
            for k, name in enumerate(segments):
                base = 1 + 7 * k
                row["q"][name] = tuple(v[base:base + 4])
                row["p"][name] = tuple(v[base + 4:base + 7])
            rows.append(row)
    return segments, rows


def best_row(rows, rotations, positions=None):
    """The row whose world rotations are nearest (worst segment) and that worst angle. Rows that
    tie (the first poses, before the sensors are up, all hold the same rotations) are told apart
    by the positions when given."""
    errs = []
    for k, row in enumerate(rows):
        err = 0.0
        for seg, q in rotations.items():
            err = max(err, angle_deg(q, row["q"][seg]))
        errs.append(err)
    least = min(errs)
    ties = [k for k, e in enumerate(errs) if e <= least + 1e-3]
    if positions is None or len(ties) == 1:
        return ties[0], least

    def distance(k):
        return max(max(abs(a - b) for a, b in zip(p, rows[k]["p"][seg]))
                   for seg, p in positions.items())
    return min(ties, key=distance), least


def rate_of(times):
    return (len(times) - 1) / (times[-1] - times[0]) if len(times) > 1 else 0.0


def check_vmc(packets, rows, rate_hz):
    frames, current, kinds = [], {}, {}
    for t, data in packets:
        msgs = []
        parse_osc(data, msgs)
        for address, tags, args in msgs:
            kinds.setdefault(address, set()).add(tags)
            if address == "/VMC/Ext/Bone/Pos":
                current[args[0]] = args[1:]
            elif address == "/VMC/Ext/Root/Pos":
                current["__root"] = args
            elif address == "/VMC/Ext/T":
                current["__t"] = args[0]
            elif address == "/VMC/Ext/OK":
                current["__ok"] = args
                current["__arrived"] = t
                frames.append(current)
                current = {}
    print(f"vmc: {len(packets)} datagrams, {len(frames)} frames, addresses "
          + ", ".join(f"{a} {sorted(k)}" for a, k in sorted(kinds.items())))
    check(set(kinds) == {"/VMC/Ext/Root/Pos", "/VMC/Ext/Bone/Pos", "/VMC/Ext/T", "/VMC/Ext/OK"},
          f"vmc addresses {sorted(kinds)}")
    check(kinds.get("/VMC/Ext/Bone/Pos") == {",sfffffff"}, "vmc Bone/Pos types")
    check(kinds.get("/VMC/Ext/Root/Pos") == {",sfffffff"}, "vmc Root/Pos types")
    check(kinds.get("/VMC/Ext/T") == {",f"}, "vmc T types")
    check(kinds.get("/VMC/Ext/OK") == {",iiii"}, "vmc OK types")
    if not check(len(frames) >= 30, f"vmc: only {len(frames)} frames"):
        return
    for f in frames:
        bones = {k for k in f if not k.startswith("__")}
        if not check(bones == set(UNITY_PARENT), f"vmc frame bones {sorted(bones)}"):
            return
    times = [f["__arrived"] for f in frames]
    r = rate_of(times)
    print(f"vmc: {r:.1f} frames/s (asked {rate_hz})")
    check(0.5 * rate_hz <= r <= 1.1 * rate_hz, f"vmc rate {r:.1f} Hz for {rate_hz}")
    worst, last, matched = 0.0, -1, 0
    for f in frames:
        world = {}
        for bone in UNITY_PARENT:  # parents come first in this order
            q = tuple(f[bone][6:7] + f[bone][3:6])  # x y z w -> w x y z
            parent = UNITY_PARENT[bone]
            world[bone] = q if parent is None else qmul(world[parent], q)
        rotations = {UNITY_TO_SEGMENT[b]: unity_to_caphub_rotation(q) for b, q in world.items()}
        hips = f["Hips"]
        k, err = best_row(rows, rotations, {"pelvis": (-hips[0], hips[1], hips[2])})
        worst = max(worst, err)
        check(k >= last, f"vmc frames out of order: row {k} after {last}")
        last = k
        matched += 1
        p = rows[k]["p"]["pelvis"]
        check(max(abs(-hips[0] - p[0]), abs(hips[1] - p[1]), abs(hips[2] - p[2])) < 0.002,
              f"vmc Hips position {hips[:3]} vs pelvis {p}")
    print(f"vmc: {matched} frames each a recorded pose; worst segment {worst:.4f} deg")
    check(worst < 0.5, f"vmc rotations off the recording by {worst:.3f} deg")


def check_vrchat(packets, rows, rate_hz):
    frames, kinds = [], {}
    for t, data in packets:
        msgs = []
        parse_osc(data, msgs)
        frame = {}
        for address, tags, args in msgs:
            kinds.setdefault(address, set()).add(tags)
            m = re.fullmatch(r"/tracking/trackers/(\w+)/(position|rotation)", address)
            if check(m is not None, f"vrchat address {address}"):
                frame.setdefault(m.group(1), {})[m.group(2)] = args
        frame["__arrived"] = t
        frames.append(frame)
    print(f"vrchat: {len(frames)} bundles, {len(kinds)} addresses")
    expected = {f"/tracking/trackers/{n}/{w}" for n in VRCHAT_SEGMENT
                for w in ("position", "rotation")}
    check(set(kinds) == expected, f"vrchat addresses {sorted(kinds)}")
    check(all(k == {",fff"} for k in kinds.values()), "vrchat types")
    if not check(len(frames) >= 20, f"vrchat: only {len(frames)} frames"):
        return
    r = rate_of([f["__arrived"] for f in frames])
    print(f"vrchat: {r:.1f} frames/s (asked {rate_hz})")
    check(0.5 * rate_hz <= r <= 1.1 * rate_hz, f"vrchat rate {r:.1f} Hz for {rate_hz}")
    worst, worst_mm, last = 0.0, 0.0, -1
    for f in frames:
        rotations = {VRCHAT_SEGMENT[n]: unity_to_caphub_rotation(
            unity_euler_to_quaternion(*f[n]["rotation"])) for n in VRCHAT_SEGMENT}
        positions = {}
        for n, seg in VRCHAT_SEGMENT.items():
            x, y, z = f[n]["position"]
            positions[seg] = (-x, y, z)
        k, err = best_row(rows, rotations, positions)
        worst = max(worst, err)
        check(k >= last, f"vrchat frames out of order: row {k} after {last}")
        last = k
        for n, seg in VRCHAT_SEGMENT.items():
            x, y, z = f[n]["position"]
            p = rows[k]["p"][seg]
            worst_mm = max(worst_mm, 1e3 * max(abs(-x - p[0]), abs(y - p[1]), abs(z - p[2])))
    print(f"vrchat: every frame a recorded pose; worst tracker {worst:.4f} deg, "
          f"{worst_mm:.2f} mm")
    check(worst < 0.5, f"vrchat rotations off the recording by {worst:.3f} deg")
    check(worst_mm < 2, f"vrchat positions off the recording by {worst_mm:.2f} mm")


def check_caphub(packets, rows, rate_hz):
    frames, skeleton, kinds = [], None, {}
    for t, data in packets:
        msgs = []
        parse_osc(data, msgs)
        frame = {}
        for address, tags, args in msgs:
            kinds.setdefault(address, set()).add(tags)
            if address == "/caphub/skeleton":
                skeleton = args
            elif address.startswith("/caphub/"):
                frame[address] = args
        if "/caphub/frame" in frame:
            frame["__arrived"] = t
            frames.append(frame)
    print(f"caphub: {len(frames)} frames, addresses "
          + ", ".join(f"{a} {len(next(iter(k))) - 1} args" for a, k in sorted(kinds.items())))
    check(kinds.get("/caphub/frame") == {",hhhhii"}, "caphub frame types")
    check(kinds.get("/caphub/root") == {",fff"}, "caphub root types")
    check(kinds.get("/caphub/local") == {"," + "f" * 84}, "caphub local types")
    check(kinds.get("/caphub/skeleton") == {",ii" + "sifff" * 21}, "caphub skeleton types")
    if not check(skeleton is not None and len(frames) >= 30, "caphub: no skeleton or frames"):
        return
    names = [skeleton[2 + 5 * k] for k in range(skeleton[1])]
    parents = [skeleton[3 + 5 * k] for k in range(skeleton[1])]
    r = rate_of([f["__arrived"] for f in frames])
    print(f"caphub: {r:.1f} frames/s (asked {rate_hz})")
    check(0.5 * rate_hz <= r <= 1.1 * rate_hz, f"caphub rate {r:.1f} Hz for {rate_hz}")
    worst, serials = 0.0, []
    for f in frames:
        serial, t_ns, newest_ns, sent_ns, mask, calibrated = f["/caphub/frame"]
        serials.append(serial)
        check(newest_ns <= sent_ns, "caphub: sent before its newest sample")
        local = f["/caphub/local"]
        world = []
        for s in range(len(names)):
            q = tuple(local[4 * s:4 * s + 4])
            world.append(q if parents[s] < 0 else qmul(world[parents[s]], q))
        row = rows[serial - 1]  # serial n is the n-th pose recorded
        for s, name in enumerate(names):
            worst = max(worst, angle_deg(world[s], row["q"][name]))
        root = f["/caphub/root"]
        check(max(abs(a - b) for a, b in zip(root, row["p"]["pelvis"])) < 0.001,
              f"caphub root {root} vs {row['p']['pelvis']}")
    check(serials == sorted(serials) and len(set(serials)) == len(serials),
          "caphub serials not increasing")
    print(f"caphub: frames {serials[0]}..{serials[-1]} at their serial's recorded pose; "
          f"worst segment {worst:.4f} deg")
    check(worst < 0.05, f"caphub rotations off the recording by {worst:.4f} deg")


def run_capture(caphub, work, name, streams):
    cmd = [caphub, "run", "--board", "sim-suit", "--duration", "4", "--realtime", "0",
           "--no-preview", "--record", os.path.join(work, name + ".cap"),
           "--status-file", os.path.join(work, name + "-status.json"), "--no-stream"]
    if streams:
        cmd = cmd[:-1]
        for s in streams:
            cmd += ["--stream", s]
    print("$", " ".join(cmd))
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    print(out.stdout)
    if out.returncode != 0:
        print(out.stderr)
    check(out.returncode == 0, f"caphub run exited {out.returncode}")
    return out.stdout


def summary(caphub, text, cap):
    """samples taken and dropped as printed, and the raw samples in the recording."""
    m = re.search(r"(\d+) samples in ([\d.]+) s, (\d+) dropped, (\d+) sensor losses", text)
    info = subprocess.run([caphub, "info", cap], capture_output=True, text=True, timeout=120)
    rec = re.search(r"raw sample\s+(\d+)", info.stdout)
    if not check(m is not None and rec is not None, "no summary or recording info"):
        return -1, 1, -1, 1, -1
    return (int(m.group(1)), float(m.group(2)), int(m.group(3)), int(m.group(4)),
            int(rec.group(1)))


# ---------------------------------------------------------------------------------------------
# The Blender add-on's receiver (firmware/stream/blender/caphub_live: osc.py and receiver.py are
# plain Python, loaded here without Blender) on malformed and hostile datagrams and on a flood.
# blender_live_check.py sends the same datagrams through the add-on's timer inside Blender.

SEGMENTS = ["pelvis", "l5", "t12", "c7", "skull", "l_clavicle", "l_upperarm", "l_forearm",
            "l_hand", "r_clavicle", "r_upperarm", "r_forearm", "r_hand", "l_thigh", "l_calf",
            "l_hindfoot", "l_middistal", "r_thigh", "r_calf", "r_hindfoot", "r_middistal"]
PARENTS = [-1, 0, 1, 2, 3, 3, 5, 6, 7, 3, 9, 10, 11, 0, 13, 14, 15, 0, 17, 18, 19]


def osc_string(s):
    b = s.encode() + b"\0"
    return b + b"\0" * (-len(b) % 4)


def osc_message(address, tags, payload=b""):
    return osc_string(address) + osc_string(tags) + payload


def osc_bundle(*elements):
    return b"#bundle\0" + bytes(8) + b"".join(struct.pack(">i", len(e)) + e for e in elements)


def floats(values):
    return struct.pack(f">{len(values)}f", *values)


def native_skeleton(parents=PARENTS, offset=(0.0, 0.1, 0.0)):
    payload = struct.pack(">ii", 1, len(SEGMENTS))
    for name, parent in zip(SEGMENTS, parents):
        payload += osc_string(name) + struct.pack(">i", parent) + floats(offset)
    return osc_bundle(osc_message("/caphub/skeleton", ",ii" + "sifff" * len(SEGMENTS), payload))


def pelvis_rotation(serial):
    """The good frames' pelvis: serial degrees about Y (the others: identity)."""
    return axis_angle((0.0, 1.0, 0.0), serial)


def native_frame(serial, local=None, root=(0.0, 0.9, 0.0), frame_msg=None, local_msg=None):
    local = list(pelvis_rotation(serial)) + [1.0, 0.0, 0.0, 0.0] * 20 if local is None else local
    return osc_bundle(
        frame_msg or osc_message("/caphub/frame", ",hhhhii",
                                 struct.pack(">qqqqii", serial, serial * 16_666_667, 0, 0, 0, 1)),
        osc_message("/caphub/root", ",fff", floats(root)),
        local_msg or osc_message("/caphub/local", "," + "f" * len(local), floats(local)))


def bad_datagrams():
    """(what, datagram): each must be refused whole and counted, the receiver going on."""
    nan, inf = float("nan"), float("inf")
    unit = [1.0, 0.0, 0.0, 0.0]
    deep = native_frame(1)
    for _ in range(1000):
        deep = osc_bundle(deep)
    nine = native_frame(1)
    for _ in range(9):
        nine = osc_bundle(nine)
    count_payload = struct.pack(">i", 1)
    return [
        ("an argument cut short (83 of 84 floats)", native_frame(
            2, local_msg=osc_message("/caphub/local", "," + "f" * 84, floats(unit * 21)[:-4]))),
        ("a type tag longer than its data (h in 4 bytes)", native_frame(
            2, frame_msg=osc_message("/caphub/frame", ",hhhhih",
                                     struct.pack(">qqqqii", 2, 2, 0, 0, 0, 1)))),
        ("a d argument with no data", osc_message("/caphub/root", ",d")),
        ("a bundle element past the end", osc_bundle(native_frame(2))[:-8]),
        ("1000 nested bundles", deep),
        ("9 nested bundles (the limit is 8)", nine),
        ("an empty datagram", b""),
        ("not UTF-8", b"/caphub/\xff\0\0\0,\0\0\0"),
        ("bytes after the arguments",
         osc_message("/caphub/root", ",fff", floats([0, 1, 0]) + b"x")),
        ("a skeleton count as a float",
         osc_bundle(osc_message("/caphub/skeleton", ",if", count_payload + floats([21.0])))),
        ("a skeleton count as a string",
         osc_bundle(osc_message("/caphub/skeleton", ",is", count_payload + osc_string("21")))),
        ("a skeleton parent out of range (99)", native_skeleton([-1] + [99] * 20)),
        ("a skeleton parent after its child", native_skeleton([-1, 2] + PARENTS[2:])),
        ("a skeleton offset NaN", native_skeleton(offset=(0.0, nan, 0.0))),
        ("a frame of 20 quaternions", native_frame(2, unit * 20)),
        ("a frame of 22 quaternions", native_frame(2, unit * 22)),
        ("strings for the quaternions", native_frame(
            2, local_msg=osc_message("/caphub/local", ",ssss", osc_string("a") * 4))),
        ("a serial as a string", native_frame(
            2, frame_msg=osc_message("/caphub/frame", ",shhhii", osc_string("2") +
                                     struct.pack(">qqqii", 2, 0, 0, 0, 1)))),
        ("a serial as a float", native_frame(
            2, frame_msg=osc_message("/caphub/frame", ",fhhhii", struct.pack(
                ">fqqqii", 2.0, 2, 0, 0, 0, 1)))),
        ("a NaN quaternion", native_frame(2, [nan] * 4 + unit * 20)),
        ("an infinite quaternion", native_frame(2, unit * 20 + [inf, 0.0, 0.0, 0.0])),
        ("a zero quaternion", native_frame(2, unit * 20 + [0.0] * 4)),
        ("a NaN root", native_frame(2, root=(0.0, nan, 0.0))),
        ("an infinite root", native_frame(2, root=(inf, 0.9, 0.0))),
        ("a frame without its rotations", osc_bundle(osc_message(
            "/caphub/frame", ",hhhhii", struct.pack(">qqqqii", 2, 2, 0, 0, 0, 1)))),
    ]


def load_addon_receiver(addon_parent):
    """caphub_live's receiver module without Blender (its package __init__ needs bpy)."""
    import importlib.util
    import types
    folder = os.path.join(addon_parent, "caphub_live")
    package = types.ModuleType("caphub_live")
    package.__path__ = [folder]
    sys.modules["caphub_live"] = package
    for name in ("osc", "receiver"):
        spec = importlib.util.spec_from_file_location(f"caphub_live.{name}",
                                                      os.path.join(folder, name + ".py"))
        module = importlib.util.module_from_spec(spec)
        sys.modules[spec.name] = module
        spec.loader.exec_module(module)
    return sys.modules["caphub_live.receiver"]


def poll_for(rx, serial, newest_only=False):
    """Polls until the frame of that serial comes (1 s at most): (frames seen, the exception)."""
    seen = []
    end = time.monotonic() + 1.0
    while time.monotonic() < end:
        try:
            seen += rx.poll(newest_only=True) if newest_only else rx.poll()
        except Exception as e:  # noqa: BLE001 - what the add-on must never let out
            return seen, e
        if any(f.serial == serial for f in seen):
            break
        time.sleep(0.002)
    return seen, None


def flood(port, datagram, seconds, python=sys.executable):
    """Another process sending the datagram to the port as fast as it can for that long."""
    code = ("import socket, sys, time\n"
            "tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)\n"
            "data, end = bytes.fromhex(sys.argv[2]), time.monotonic() + float(sys.argv[3])\n"
            "while time.monotonic() < end:\n"
            "    for _ in range(50):\n"
            "        tx.sendto(data, ('127.0.0.1', int(sys.argv[1])))\n")
    return subprocess.Popen([python, "-c", code, str(port), datagram.hex(), str(seconds)])


def check_addon_receiver(addon_parent):
    receiver = load_addon_receiver(addon_parent)
    rx = receiver.Receiver(0, "127.0.0.1")
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    tx.sendto(native_skeleton(), ("127.0.0.1", rx.port))
    tx.sendto(native_frame(1), ("127.0.0.1", rx.port))
    seen, error = poll_for(rx, 1)
    check(error is None and [f.serial for f in seen] == [1] and rx.bad_packets == 0,
          f"add-on receiver: the good skeleton and frame gave {len(seen)} frames ({error!r})")
    serial = 1
    for what, data in bad_datagrams():
        serial += 1
        bad = rx.bad_packets
        tx.sendto(data, ("127.0.0.1", rx.port))
        tx.sendto(native_frame(serial), ("127.0.0.1", rx.port))
        seen, error = poll_for(rx, serial)
        got = [f.serial for f in seen]
        ok = (error is None and got == [serial] and rx.bad_packets == bad + 1 and
              rx.skeleton is not None and rx.skeleton.parents == PARENTS and
              angle_deg(seen[0].local[0], pelvis_rotation(serial)) < 0.01)
        check(ok, f"add-on receiver, {what}: {error!r}, frames {got}, "
                  f"bad datagrams {bad} -> {rx.bad_packets}")
    print(f"add-on receiver: {serial - 1} kinds of bad datagram sent, each followed by a good "
          f"frame; {rx.bad_packets} counted bad")

    # A burst larger than one poll() may read: at most max_datagrams a call, the rest kept by the
    # socket for the next; newest_only gives one frame, the newest read.
    rx.max_datagrams, rx.budget_s = 64, 10.0  # the count bound alone (the time one: below)
    for k in range(200):
        tx.sendto(native_frame(1000 + k), ("127.0.0.1", rx.port))
    time.sleep(0.1)
    counts = []
    try:
        first = rx.poll()
        counts.append(len(first))
        newest = rx.poll(newest_only=True)
        counts.append(len(newest))
        while len(counts) < 10:
            counts.append(len(rx.poll()))
    except Exception as e:  # noqa: BLE001
        check(False, f"add-on receiver, a burst: {e!r}")
    else:
        check(counts[0] == 64 and [f.serial for f in first] == list(range(1000, 1064)),
              f"add-on receiver: a burst of 200 gave {counts[0]} frames to one poll(), not 64")
        check(len(newest) == 1 and newest[0].serial == 1127,
              f"add-on receiver: newest_only gave {[f.serial for f in newest]}, not [1127]")
        check(sum(counts) == 200 - 63, f"add-on receiver: the burst's polls gave {counts}")
    rx.close()

    # Another machine on the network sending a well-formed stream of its own (here from
    # 127.0.0.2): its skeleton does not replace the hub's nor its frames pose anything; they are
    # counted as foreign. A receiver given the hub's address takes nothing from anyone else, even
    # first.
    rx = receiver.Receiver(0, "127.0.0.1")
    other = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    other.bind(("127.0.0.2", 0))
    tx.sendto(native_skeleton(), ("127.0.0.1", rx.port))
    tx.sendto(native_frame(7000), ("127.0.0.1", rx.port))
    seen, error = poll_for(rx, 7000)
    check(error is None and rx.hub == "127.0.0.1", f"add-on receiver: the hub is {rx.hub}")
    foreign_parents = [-1] + [0] * 20
    other.sendto(native_skeleton(foreign_parents), ("127.0.0.1", rx.port))
    other.sendto(native_frame(7001), ("127.0.0.1", rx.port))
    tx.sendto(native_frame(7002), ("127.0.0.1", rx.port))
    seen, error = poll_for(rx, 7002)
    check(error is None and [f.serial for f in seen] == [7002] and rx.skeleton.parents == PARENTS
          and rx.foreign_packets == 2 and rx.bad_packets == 0,
          f"add-on receiver, another sender: frames {[f.serial for f in seen]}, foreign "
          f"{rx.foreign_packets}, skeleton kept {rx.skeleton.parents == PARENTS}")
    rx.close()
    rx = receiver.Receiver(0, "127.0.0.1", hub="127.0.0.1")
    other.sendto(native_skeleton(foreign_parents), ("127.0.0.1", rx.port))
    other.sendto(native_frame(7003), ("127.0.0.1", rx.port))
    tx.sendto(native_skeleton(), ("127.0.0.1", rx.port))
    tx.sendto(native_frame(7004), ("127.0.0.1", rx.port))
    seen, error = poll_for(rx, 7004)
    check(error is None and [f.serial for f in seen] == [7004] and rx.skeleton.parents == PARENTS
          and rx.foreign_packets == 2,
          f"add-on receiver, the hub given: frames {[f.serial for f in seen]}, foreign "
          f"{rx.foreign_packets}")
    print(f"add-on receiver: another sender's skeleton and frame skipped ({rx.foreign_packets} "
          f"foreign datagrams), the hub's kept")
    other.close()
    rx.close()

    # A flood (a sender as fast as it can for 2 s): every poll() returns within a small time
    # with at most 256 frames (MAX_DATAGRAMS; one with newest_only), and the receiver still works.
    rx = receiver.Receiver(0, "127.0.0.1")
    tx.sendto(native_skeleton(), ("127.0.0.1", rx.port))
    sender = flood(rx.port, native_frame(5000), 2.0)
    time.sleep(0.2)
    worst_s, most, most_newest, polls = 0.0, 0, 0, 0
    try:
        while sender.poll() is None:  # every frame (recording), then the newest (live), in turn
            newest_only = polls % 2 == 1
            t = time.monotonic()
            n = len(rx.poll(newest_only=True) if newest_only else rx.poll())
            worst_s = max(worst_s, time.monotonic() - t)
            if newest_only:
                most_newest = max(most_newest, n)
            else:
                most = max(most, n)
            polls += 1
    except Exception as e:  # noqa: BLE001
        check(False, f"add-on receiver, a flood: {e!r}")
    sender.wait()
    print(f"add-on receiver under a flood: {polls} polls, the longest {worst_s * 1000:.1f} ms, "
          f"at most {most} frames from one ({most_newest} with newest_only)")
    check(polls >= 10 and worst_s < 0.25, f"add-on receiver: a poll() under a flood took "
          f"{worst_s:.2f} s ({polls} polls)")
    check(0 < most <= 256 and most_newest == 1,
          f"add-on receiver: {most} frames from one poll() under a flood")
    while rx.poll():
        pass
    tx.sendto(native_frame(6000), ("127.0.0.1", rx.port))
    seen, error = poll_for(rx, 6000)
    check(error is None and [f.serial for f in seen] == [6000],
          "add-on receiver: no good frame after the flood")
    tx.close()
    rx.close()


def main():
    caphub, work = sys.argv[1], sys.argv[2]
    addon_parent = sys.argv[3] if len(sys.argv) > 3 else os.path.join(
        os.path.dirname(os.path.abspath(__file__)), "..", "..", "firmware", "stream", "blender")
    check_addon_receiver(addon_parent)
    os.makedirs(work, exist_ok=True)
    for f in os.listdir(work):
        os.remove(os.path.join(work, f))
    vmc, vrchat, native = Receiver(), Receiver(), Receiver()
    closed = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    closed.bind(("127.0.0.1", 0))
    closed_port = closed.getsockname()[1]
    closed.close()  # nobody listens there: the kernel answers ICMP port unreachable
    out = run_capture(caphub, work, "streamed", [
        f"vmc:127.0.0.1:{vmc.port}@60", f"vrchat:127.0.0.1:{vrchat.port}@30",
        f"caphub:127.0.0.1:{native.port}@60", f"vmc:127.0.0.1:{closed_port}@60"])
    for r in (vmc, vrchat, native):
        r.stop()
    plain = run_capture(caphub, work, "plain", [])

    export = subprocess.run([caphub, "export", os.path.join(work, "streamed.cap"), "--format",
                             "csv", "-o", os.path.join(work, "streamed.csv")],
                            capture_output=True, text=True, timeout=300)
    print(export.stdout, export.stderr)
    check(export.returncode == 0, "caphub export failed")
    _, rows = read_csv(os.path.join(work, "streamed.csv"))
    print(f"recording: {len(rows)} poses")

    check_vmc(vmc.packets, rows, 60)
    check_vrchat(vrchat.packets, rows, 30)
    check_caphub(native.packets, rows, 60)

    # The refusing destination: its sends fail and are counted; the capture loses nothing.
    refused = re.search(rf"stream vmc:127.0.0.1:{closed_port}@60: (\d+) frames sent "
                        rf"\(\d+ datagrams\), (\d+) failed", out)
    if check(refused is not None, "no line for the refusing destination"):
        print(f"refusing destination: {refused.group(1)} frames sent, {refused.group(2)} failed")
        check(int(refused.group(2)) > 0, "the refused sends were not counted")
    rates = []
    for name, text in (("with streams", out), ("without", plain)):
        samples, seconds, dropped, losses, recorded = summary(
            caphub, text, os.path.join(work, ("streamed" if text is out else "plain") + ".cap"))
        print(f"{name}: {samples} samples in {seconds} s ({samples / seconds:.1f}/s), "
              f"{dropped} dropped, {losses} losses, {recorded} recorded")
        check(dropped == 0 and losses == 0, f"{name}: samples dropped or sensors lost")
        check(recorded == samples and samples > 0, f"{name}: {samples} taken, {recorded} recorded")
        rates.append(samples / seconds)
    # The samples a second are printed, not compared: the virtual suit computes its chips in the
    # same process, so on a loaded machine (or under the sanitizers) it makes fewer samples
    # whatever the streams do; what the streams must not cause is a sample dropped or unrecorded.
    poses = re.search(r"\n(\d+) poses;", out)
    check(poses is not None and int(poses.group(1)) == len(rows), "poses printed != exported")

    if failures:
        print(f"{len(failures)} failures")
        return 1
    print("all streams received as recorded")
    return 0


if __name__ == "__main__":
    sys.exit(main())

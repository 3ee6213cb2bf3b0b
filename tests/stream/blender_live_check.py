"""Blender, headless, with the caphub live add-on, receiving a live stream from `caphub run` on the
virtual suit: the armature's bones move, and each pose shown equals the recording's pose of the
same serial within 1 deg (every bone's orientation in the armature, brought back to caphub's
frame). Then the recording's glb export, imported with the add-on's one-click import, is bound
by the name map of caphub's exports and posed by the stream's last frame, and rendered with
Workbench into a PNG. Also checks that recording keyframes an action, and that malformed
datagrams and a flood reach the add-on's timer without stopping it or posing anything bad.

blender -b --factory-startup --python blender_live_check.py -- CAPHUB WORKDIR ADDON_PARENT PNG
"""
import csv
import math
import os
import shutil
import socket
import subprocess
import sys
import time

import bpy
from mathutils import Matrix, Quaternion, Vector

argv = sys.argv[sys.argv.index("--") + 1:]
CAPHUB, WORK, ADDON_PARENT, PNG = argv[:4]
sys.path.insert(0, ADDON_PARENT)
import caphub_live  # noqa: E402
from caphub_live.receiver import Receiver  # noqa: E402

failures = []


def check(ok, what):
    if not ok:
        failures.append(what)
        print("FAIL:", what)
    return ok


def angle_deg(a, b):
    d = abs(a.normalized().dot(b.normalized()))
    return math.degrees(2 * math.acos(min(1.0, d)))


os.makedirs(WORK, exist_ok=True)
bpy.ops.wm.read_factory_settings(use_empty=True)
caphub_live.register()
scene = bpy.context.scene
settings = scene.caphub_live
rx = Receiver(0, "127.0.0.1")
caphub_live._state["receiver"] = rx
cap = os.path.join(WORK, "blender.cap")
if os.path.exists(cap):
    os.remove(cap)
cmd = [CAPHUB, "run", "--board", "sim-suit", "--duration", "5", "--realtime", "0",
       # Ideal chips: with the typical ones and no sensor calibration the magnetometers' hard
       # iron turns the headings and the avatar looks broken (issue 23); the stream is the same.
       "--profile", "ideal",
       "--no-preview", "--record", cap, "--status-file", os.path.join(WORK, "status.json"),
       "--stream", f"caphub:127.0.0.1:{rx.port}@60"]
print("$", " ".join(cmd))
proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)

C_inv = caphub_live.C_Q.inverted()
samples = []  # (serial, {segment: caphub-frame world rotation read back from the armature})
started = time.monotonic()
while proc.poll() is None and time.monotonic() - started < 300:
    frame = caphub_live.step(bpy.context)
    if frame is None:
        time.sleep(0.003)
        continue
    obj = bpy.data.objects[settings.target]
    bpy.context.view_layer.update()
    world = {}
    for pb in obj.pose.bones:
        g = pb.matrix.to_quaternion() @ pb.bone.matrix_local.to_quaternion().inverted()
        world[pb.name] = C_inv @ g @ caphub_live.C_Q
    samples.append((frame.serial, world))
    # From the 41st pose on, every frame is recorded into an action.
    settings.record = len(samples) > 40
out = proc.communicate()[0]
print(out)
check(proc.returncode == 0, f"caphub run exited {proc.returncode}")

csv_path = os.path.join(WORK, "blender.csv")
subprocess.run([CAPHUB, "export", cap, "--format", "csv", "-o", csv_path], check=True)
rows = []
with open(csv_path, newline="") as f:
    reader = csv.reader(f)
    header = next(reader)
    segments = [h[:-3] for h in header if h.endswith("_qw")]
    for r in reader:
        v = [float(x) for x in r[:1 + 7 * len(segments)]]  # not the not_measured column
        rows.append({s: Quaternion(v[1 + 7 * k:5 + 7 * k]) for k, s in enumerate(segments)})

print(f"{rx.frames_received} frames received, {len(samples)} poses shown, "
      f"{len(rows)} recorded")
check(len(samples) >= 50, f"only {len(samples)} poses shown")
worst = 0.0
for serial, world in samples:
    row = rows[serial - 1]
    for seg, q in world.items():
        worst = max(worst, angle_deg(q, row[seg]))
print(f"worst bone against the recording's pose of the same serial: {worst:.4f} deg")
check(worst < 1.0, f"bones off the recording by {worst:.3f} deg")
moved = max(angle_deg(samples[0][1][s], samples[-1][1][s]) for s in samples[0][1])
thigh = [angle_deg(samples[0][1]["l_thigh"], w["l_thigh"]) for _, w in samples]
print(f"most a bone turned from the first pose to the last: {moved:.1f} deg; "
      f"the left thigh over the run: up to {max(thigh):.1f} deg")
check(max(thigh) > 10, "the thigh did not move")

obj = bpy.data.objects[settings.target]
action = obj.animation_data.action if obj.animation_data else None
keys = len(action.fcurves[0].keyframe_points) if action and action.fcurves else 0
print(f"recorded action: {len(action.fcurves) if action else 0} curves, {keys} keys each")
check(keys >= 20, f"recording made only {keys} keyframes")

# The avatar: caphub's glb export, imported in one click, bound by the exports' joint names and
# posed by the last frame received.
glb = os.path.join(WORK, "blender.glb")
subprocess.run([CAPHUB, "export", cap, "--format", "glb", "-o", glb], check=True)
obj.hide_render = True
bpy.ops.caphub.import_glb(filepath=glb)
avatar = next(o for o in bpy.data.objects if o.type == "ARMATURE" and o is not obj)
if avatar.animation_data:
    avatar.animation_data.action = None
for pb in avatar.pose.bones:
    pb.rotation_mode = "QUATERNION"
last = caphub_live._state["last"]
driven = caphub_live.apply_frame(avatar, rx.skeleton, last, caphub_live.HANIM_JOINTS)
print(f"glb avatar '{avatar.name}': {driven} bones bound by name")
check(driven == 21, f"only {driven} bones of the glb bound")
bpy.context.view_layer.update()
worst_glb = 0.0
for s, seg in enumerate(rx.skeleton.names):
    pb = avatar.pose.bones[caphub_live.HANIM_JOINTS[seg]]
    g = avatar.matrix_world.to_quaternion() @ pb.matrix.to_quaternion() @ \
        pb.bone.matrix_local.to_quaternion().inverted()
    worst_glb = max(worst_glb, angle_deg(C_inv @ g @ caphub_live.C_Q, rows[last.serial - 1][seg]))
print(f"glb avatar against the recording: worst bone {worst_glb:.4f} deg")
check(worst_glb < 1.0, f"glb avatar off by {worst_glb:.3f} deg")

# Workbench, from the front and a little to the side.
scene.render.engine = "BLENDER_WORKBENCH"
scene.render.resolution_x, scene.render.resolution_y = 640, 480
scene.display.shading.light = "STUDIO"
scene.display.shading.color_type = "OBJECT"
cam_data = bpy.data.cameras.new("cam")
cam = bpy.data.objects.new("cam", cam_data)
scene.collection.objects.link(cam)
root = avatar.matrix_world @ avatar.pose.bones[caphub_live.HANIM_JOINTS["pelvis"]].head
cam.location = root + Vector((1.6, -3.2, 0.3))
cam.rotation_euler = (Vector(root) + Vector((0, 0, 0.0)) - cam.location).to_track_quat(
    "-Z", "Y").to_euler()
scene.camera = cam
scene.render.filepath = PNG
bpy.ops.render.render(write_still=True)
check(os.path.exists(PNG), "no render")

rx.close()

# Hostile datagrams through the add-on's timer, called as Blender calls it (Blender drops a timer
# that raises): each kind (stream_receive_check.py's) is refused and counted, the timer goes on
# and the next good frame poses the armature; NaN is never posed nor keyframed; under a flood
# each call returns soon, live (the newest frame) and recording.
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import stream_receive_check as datagrams  # noqa: E402

PYTHON = shutil.which("python3") or "/usr/bin/python3"  # Blender's sys.executable may be none

hostile = Receiver(0, "127.0.0.1")
caphub_live._state.update(receiver=hostile, rest_root=None, t0_ns=None, last=None)
obj.animation_data_clear()
settings.record = True
tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)


def tick_until(serial, limit_s=1.0):
    """Calls the timer until the frame of that serial is posed: the timer's error, if any."""
    end = time.monotonic() + limit_s
    while time.monotonic() < end:
        try:
            if caphub_live._timer() is None:
                return "the timer stopped"
        except Exception as e:  # noqa: BLE001 - Blender would drop the timer
            return repr(e)
        last = caphub_live._state["last"]
        if last is not None and last.serial == serial:
            return None
        time.sleep(0.002)
    return f"frame {serial} never posed"


def pelvis_off_deg(serial):
    bpy.context.view_layer.update()
    pb = obj.pose.bones["pelvis"]
    g = pb.matrix.to_quaternion() @ pb.bone.matrix_local.to_quaternion().inverted()
    return angle_deg(C_inv @ g @ caphub_live.C_Q, Quaternion(datagrams.pelvis_rotation(serial)))


tx.sendto(datagrams.native_skeleton(), ("127.0.0.1", hostile.port))
tx.sendto(datagrams.native_frame(1), ("127.0.0.1", hostile.port))
error = tick_until(1)
check(error is None and pelvis_off_deg(1) < 0.05, f"hostile: the first good frame: {error}")
serial = 1
for what, data in datagrams.bad_datagrams():
    serial += 1
    bad = hostile.bad_packets
    tx.sendto(data, ("127.0.0.1", hostile.port))
    tx.sendto(datagrams.native_frame(serial), ("127.0.0.1", hostile.port))
    error = tick_until(serial)
    check(error is None and hostile.bad_packets == bad + 1 and pelvis_off_deg(serial) < 0.05,
          f"hostile, {what}: {error}, bad datagrams {bad} -> {hostile.bad_packets}")
values = [v for pb in obj.pose.bones for v in tuple(pb.rotation_quaternion) + tuple(pb.location)]
keys = [kp.co[1] for fc in obj.animation_data.action.fcurves for kp in fc.keyframe_points] \
    if obj.animation_data and obj.animation_data.action else []
print(f"hostile: {serial - 1} kinds of bad datagram, {hostile.bad_packets} counted bad; "
      f"{len(keys)} keys recorded")
check(all(math.isfinite(v) for v in values + keys) and len(keys) > 0,
      "hostile: a pose or keyframe value not finite (or none recorded)")
check(caphub_live._state.get("errors", 0) == 0, "hostile: the timer caught an error")

for record in (False, True):
    settings.record = record
    sender = datagrams.flood(hostile.port, datagrams.native_frame(7000), 1.5, PYTHON)
    worst_s, calls, timer_error, received = 0.0, 0, None, hostile.frames_received
    while sender.poll() is None and timer_error is None:
        t = time.monotonic()
        try:
            caphub_live._timer()
        except Exception as e:  # noqa: BLE001
            timer_error = repr(e)
        worst_s, calls = max(worst_s, time.monotonic() - t), calls + 1
    sender.wait()
    received = hostile.frames_received - received
    while hostile.poll():
        pass
    print(f"flood, {'recording' if record else 'live'}: {calls} timer calls, the longest "
          f"{worst_s * 1000:.1f} ms, {received} frames taken")
    # Frames taken: the timer keeps reading through the flood. How many depends on how fast the
    # flooding process runs beside Blender, not on the add-on: 873 in 1.5 s while recording on
    # a 2-core machine busy with two other test processes and a build (a CI run, 2026-11-28),
    # several thousand on a quiet one; a timer that stopped reading takes none.
    check(timer_error is None and calls >= 5 and worst_s < 0.5 and received > 100,
          f"flood ({'recording' if record else 'live'}): {calls} calls, the longest "
          f"{worst_s:.2f} s, {timer_error}")
    serial += 1
    tx.sendto(datagrams.native_frame(serial), ("127.0.0.1", hostile.port))
    error = tick_until(serial)
    check(error is None and pelvis_off_deg(serial) < 0.05, f"after the flood: {error}")
settings.record = False
tx.close()
hostile.close()
print(f"{len(failures)} failures" if failures else "blender: the live stream drives the armature")
sys.exit(1 if failures else 0)

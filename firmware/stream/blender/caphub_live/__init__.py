"""caphub live: drives an armature in Blender from a caphub hub's live stream (the `caphub`
protocol of docs/streams.md), records it into an action, and imports caphub's BVH and glb exports
with the right options. Start the hub with `caphub run --stream caphub:BLENDER_HOST:39600`."""

bl_info = {
    "name": "caphub live",
    "author": "caphub",
    "version": (1, 0, 0),
    "blender": (3, 4, 0),
    "location": "3D Viewport > Sidebar > caphub",
    "description": "Live motion from a caphub inertial capture hub; caphub BVH/glb import",
    "category": "Animation",
}

import ipaddress
import traceback

import bpy
from bpy.props import BoolProperty, EnumProperty, IntProperty, StringProperty
from mathutils import Matrix, Quaternion, Vector

from .receiver import Receiver

# caphub's world (Y up, the subject facing +Z) to Blender's (Z up, the subject facing -Y, towards
# the Front view): +90 deg about X, a proper rotation (no mirror), as Blender's glTF importer does.
C = Matrix.Rotation(1.5707963267948966, 4, "X")
C3 = C.to_3x3()
C_Q = C.to_quaternion()

# caphub segment -> the joint names of caphub's exports (`caphub export --names hanim`), for
# binding the armature a glb or BVH import made.
HANIM_JOINTS = {
    "pelvis": "humanoid_root", "l5": "vl5", "t12": "vt12", "c7": "vc7", "skull": "skullbase",
    "l_clavicle": "l_sternoclavicular", "l_upperarm": "l_shoulder", "l_forearm": "l_elbow",
    "l_hand": "l_radiocarpal", "r_clavicle": "r_sternoclavicular", "r_upperarm": "r_shoulder",
    "r_forearm": "r_elbow", "r_hand": "r_radiocarpal", "l_thigh": "l_hip", "l_calf": "l_knee",
    "l_hindfoot": "l_talocrural", "l_middistal": "l_metatarsophalangeal", "r_thigh": "r_hip",
    "r_calf": "r_knee", "r_hindfoot": "r_talocrural", "r_middistal": "r_metatarsophalangeal",
}

_state = {"receiver": None, "rest_root": None, "t0_ns": None, "last": None, "errors": 0}


def to_blender(v):
    return C3 @ Vector(v)


def caphub_rotation(q):
    """A rotation of caphub's frame, (w, x, y, z), as the same rotation in Blender's frame."""
    return C_Q @ Quaternion(q) @ C_Q.inverted()


def name_map(settings):
    """caphub segment -> bone name in the target armature."""
    if settings.names == "HANIM":
        return dict(HANIM_JOINTS)
    if settings.names == "FILE" and settings.names_text in bpy.data.texts:
        out = {}
        for line in bpy.data.texts[settings.names_text].as_string().splitlines():
            line = line.split("#", 1)[0].strip()
            if "=" in line:
                k, v = (s.strip().strip('"') for s in line.split("=", 1))
                out[k] = v
        return out
    return None  # the segment names themselves (an armature this add-on created)


def create_armature(skeleton, name="caphub"):
    """caphub's skeleton as an armature in the T-pose: one bone per segment from its joint to its
    first child's (a leaf: 10 cm on along its parent's direction)."""
    heads = []
    for s, offset in enumerate(skeleton.offsets):
        p = skeleton.parents[s]
        heads.append(Vector(offset) if p < 0 else heads[p] + Vector(offset))
    arm = bpy.data.armatures.new(name)
    obj = bpy.data.objects.new(name, arm)
    bpy.context.scene.collection.objects.link(obj)
    bpy.context.view_layer.objects.active = obj
    bpy.ops.object.mode_set(mode="EDIT")
    bones = []
    for s, seg in enumerate(skeleton.names):
        b = arm.edit_bones.new(seg)
        head = heads[s]
        children = [c for c in range(len(skeleton.names)) if skeleton.parents[c] == s]
        if s == 0:
            tail = head + Vector((0, 0.12, 0))  # the pelvis points up the spine
        elif children:
            tail = heads[children[0]]
        else:
            p = skeleton.parents[s]
            direction = (head - heads[p]).normalized() if (head - heads[p]).length > 1e-6 \
                else Vector((0, -1, 0))
            tail = head + 0.1 * direction
        if (tail - head).length < 0.02:
            tail = head + Vector((0, -0.05, 0))
        b.head, b.tail = to_blender(head), to_blender(tail)
        bones.append(b)
    for s, b in enumerate(bones):
        if skeleton.parents[s] >= 0:
            b.parent = bones[skeleton.parents[s]]
    bpy.ops.object.mode_set(mode="OBJECT")
    for pb in obj.pose.bones:
        pb.rotation_mode = "QUATERNION"
    return obj


def apply_frame(obj, skeleton, frame, names=None, rest_root=None):
    """Poses obj from a frame: each bone's armature-space orientation becomes its segment's world
    rotation times the bone's rest orientation (the rest pose is the T-pose). Returns the bones
    driven."""
    world = []
    for s, q in enumerate(frame.local):
        p = skeleton.parents[s]
        g = caphub_rotation(q)
        world.append(g if p < 0 else world[p] @ g)
    driven = 0
    for s, seg in enumerate(skeleton.names):
        bone_name = names.get(seg, seg) if names else seg
        pb = obj.pose.bones.get(bone_name)
        if pb is None:
            continue
        rest = pb.bone.matrix_local.to_quaternion()
        p = skeleton.parents[s]
        # The basis rotation R with  G_s B_s = G_p B_s R  (Blender's pose = parent pose x rest
        # offset x basis):  R = B_s^-1 G_p^-1 G_s B_s.
        parent_world = world[p] if p >= 0 else Quaternion()
        r = rest.inverted() @ parent_world.inverted() @ world[s] @ rest
        if pb.rotation_mode != "QUATERNION":
            pb.rotation_mode = "QUATERNION"
        pb.rotation_quaternion = r
        if p < 0 and rest_root is not None:
            d = to_blender(frame.root) - to_blender(rest_root)
            pb.location = rest.inverted() @ d
        driven += 1
    return driven


def keyframe(obj, frame_number):
    for pb in obj.pose.bones:
        pb.keyframe_insert("rotation_quaternion", frame=frame_number, group=pb.name)
        if pb.parent is None:
            pb.keyframe_insert("location", frame=frame_number, group=pb.name)


def step(context):
    """Takes what arrived and poses the target; returns the newest frame applied (or None)."""
    settings = context.scene.caphub_live
    rx = _state["receiver"]
    if rx is None:
        return None
    # Recording keyframes every frame (at most the receiver's datagrams per call); live posing
    # needs only the newest.
    frames = rx.poll(newest_only=not settings.record)
    skeleton = rx.skeleton
    if not frames or skeleton is None:
        return None
    obj = bpy.data.objects.get(settings.target) if settings.target else None
    if obj is None or obj.type != "ARMATURE":
        obj = create_armature(skeleton)
        settings.target = obj.name
    if _state["rest_root"] is None:
        _state["rest_root"] = frames[0].root
    names = name_map(settings)
    fps = context.scene.render.fps / context.scene.render.fps_base
    for f in frames if settings.record else frames[-1:]:
        apply_frame(obj, skeleton, f, names, _state["rest_root"] if settings.root_motion else None)
        if settings.record:
            if _state["t0_ns"] is None:
                _state["t0_ns"] = f.t_ns
            keyframe(obj, context.scene.frame_start + (f.t_ns - _state["t0_ns"]) * 1e-9 * fps)
    _state["last"] = frames[-1]
    return frames[-1]


def _timer():
    if _state["receiver"] is None:
        return None
    try:
        step(bpy.context)
    except Exception:
        # The receiver refuses malformed datagrams itself; this is for anything else (an odd
        # target armature, say): printed, and the timer goes on (Blender drops one that raises).
        _state["errors"] += 1
        if _state["errors"] <= 10:
            traceback.print_exc()
    return 1.0 / 120.0


class CaphubLiveSettings(bpy.types.PropertyGroup):
    port: IntProperty(name="Port", default=39600, min=1, max=65535,
                      description="UDP port the hub streams to (caphub run --stream caphub:HOST:PORT)")
    hub: StringProperty(name="Hub",
                        description="The hub's IP address: datagrams from any other are "
                                    "skipped (empty: the first address that sends the stream)")
    target: StringProperty(name="Armature",
                           description="The armature to drive (empty: create caphub's)")
    names: EnumProperty(name="Bone names", items=[
        ("SEGMENTS", "caphub segments", "Bones named after caphub's segments (pelvis, l_thigh, ...)"),
        ("HANIM", "caphub exports (H-Anim joints)", "An armature imported from caphub's glb/BVH"),
        ("FILE", "Name map (text block)", "segment = \"bone\" lines in a text block")],
        default="SEGMENTS")
    names_text: StringProperty(name="Name map", description="Text block with segment = \"bone\"")
    record: BoolProperty(name="Record", default=False,
                         description="Insert a keyframe for every frame received into the action")
    root_motion: BoolProperty(name="Root motion", default=True,
                              description="Move the root with the capture's root position")


class CAPHUB_OT_connect(bpy.types.Operator):
    bl_idname = "caphub.connect"
    bl_label = "Connect"
    bl_description = "Listen for the hub's caphub stream on the port"

    def execute(self, context):
        disconnect()
        s = context.scene.caphub_live
        hub = s.hub.strip() or None
        if hub is not None:
            try:
                hub = str(ipaddress.IPv4Address(hub))
            except ValueError:
                self.report({"ERROR"}, f"hub '{hub}': expected an IPv4 address (or nothing)")
                return {"CANCELLED"}
        try:
            _state["receiver"] = Receiver(s.port, hub=hub)
        except OSError as e:
            self.report({"ERROR"}, f"port {s.port}: {e}")
            return {"CANCELLED"}
        _state["rest_root"], _state["t0_ns"], _state["errors"] = None, None, 0
        bpy.app.timers.register(_timer)
        return {"FINISHED"}


def disconnect():
    if _state["receiver"] is not None:
        _state["receiver"].close()
        _state["receiver"] = None


class CAPHUB_OT_disconnect(bpy.types.Operator):
    bl_idname = "caphub.disconnect"
    bl_label = "Disconnect"

    def execute(self, context):
        disconnect()
        return {"FINISHED"}


class CAPHUB_OT_import_bvh(bpy.types.Operator):
    bl_idname = "caphub.import_bvh"
    bl_label = "Import caphub BVH"
    bl_description = "A caphub BVH export: metres, Y up, the subject facing the Front view"
    filepath: StringProperty(subtype="FILE_PATH")
    filter_glob: StringProperty(default="*.bvh", options={"HIDDEN"})

    def execute(self, context):
        bpy.ops.import_anim.bvh(filepath=self.filepath, axis_forward="-Z", axis_up="Y",
                                global_scale=1.0, rotate_mode="NATIVE", use_fps_scale=True,
                                update_scene_fps=False, update_scene_duration=True)
        return {"FINISHED"}

    def invoke(self, context, event):
        context.window_manager.fileselect_add(self)
        return {"RUNNING_MODAL"}


class CAPHUB_OT_import_glb(bpy.types.Operator):
    bl_idname = "caphub.import_glb"
    bl_label = "Import caphub glb"
    bl_description = "A caphub glb export: the skinned avatar and its animation"
    filepath: StringProperty(subtype="FILE_PATH")
    filter_glob: StringProperty(default="*.glb", options={"HIDDEN"})

    def execute(self, context):
        try:
            import numpy
            # Blender 3.4's glTF importer uses numpy.bool, which numpy 1.24 (Debian 12's) removed.
            if "bool" not in numpy.__dict__:
                numpy.bool = bool
        except ImportError:
            pass
        bpy.ops.import_scene.gltf(filepath=self.filepath)
        return {"FINISHED"}

    def invoke(self, context, event):
        context.window_manager.fileselect_add(self)
        return {"RUNNING_MODAL"}


class CAPHUB_PT_live(bpy.types.Panel):
    bl_label = "caphub live"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "caphub"

    def draw(self, context):
        s = context.scene.caphub_live
        col = self.layout.column()
        col.prop(s, "port")
        col.prop(s, "hub")
        col.prop_search(s, "target", bpy.data, "objects")
        col.prop(s, "names")
        if s.names == "FILE":
            col.prop_search(s, "names_text", bpy.data, "texts")
        col.prop(s, "root_motion")
        col.prop(s, "record")
        rx = _state["receiver"]
        if rx is None:
            col.operator("caphub.connect")
        else:
            col.operator("caphub.disconnect")
            last = _state["last"]
            col.label(text=f"{rx.frames_received} frames" +
                      (f", pose {last.serial}" if last else ", waiting"))
            if rx.hub:
                col.label(text=f"from {rx.hub}")
            if rx.bad_packets:
                col.label(text=f"{rx.bad_packets} bad datagrams skipped")
            if rx.foreign_packets:
                col.label(text=f"{rx.foreign_packets} datagrams from other addresses skipped")
        col.separator()
        col.operator("caphub.import_bvh")
        col.operator("caphub.import_glb")


classes = (CaphubLiveSettings, CAPHUB_OT_connect, CAPHUB_OT_disconnect, CAPHUB_OT_import_bvh,
           CAPHUB_OT_import_glb, CAPHUB_PT_live)


def register():
    for c in classes:
        bpy.utils.register_class(c)
    bpy.types.Scene.caphub_live = bpy.props.PointerProperty(type=CaphubLiveSettings)


def unregister():
    disconnect()
    del bpy.types.Scene.caphub_live
    for c in reversed(classes):
        bpy.utils.unregister_class(c)

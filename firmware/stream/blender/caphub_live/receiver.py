"""caphub's native stream (docs/streams.md) received on a UDP port: the newest frame and the
skeleton's description. No bpy here: the add-on polls it from a timer.

Anything may arrive on the port (it listens on every interface). A datagram that is not a
well-formed caphub bundle, or whose frame does not fit the skeleton, is counted in bad_packets
and skipped whole; one poll() reads a bounded number of datagrams in a bounded time. The hub is
one address: the one given, or else the first to send a well-formed datagram; datagrams from
any other address are counted in foreign_packets and skipped (another machine's skeleton would
otherwise replace the hub's, and its frames pose the armature)."""
import math
import socket
import time

from . import osc

# One poll(): at most this many datagrams, and no new one read after this long (a flood must not
# hold Blender's UI; what is left waits in the socket's buffer, and the kernel drops beyond it).
MAX_DATAGRAMS = 256
BUDGET_S = 0.005
# Values a receiver can use: positions and offsets in metres within this (mathutils holds
# 32-bit floats), quaternions within 10 % of unit length.
MAX_METRES = 1.0e4


class Frame:
    __slots__ = ("serial", "t_ns", "newest_ns", "sent_ns", "not_measured", "calibrated", "root",
                 "local")


def _int(v):
    if type(v) is not int:
        raise ValueError("an integer expected")
    return v


def _metres(v):
    if type(v) not in (float, int) or not math.isfinite(v) or abs(v) > MAX_METRES:
        raise ValueError("a finite position expected")
    return float(v)


def _quaternion(args):
    if any(type(v) not in (float, int) or not math.isfinite(v) for v in args):
        raise ValueError("a finite quaternion expected")
    if abs(math.sqrt(sum(v * v for v in args)) - 1.0) > 0.1:
        raise ValueError("not a unit quaternion")
    return tuple(float(v) for v in args)


class Skeleton:
    def __init__(self, args):
        """ValueError unless args are version 1's: a count, then per segment a name, a parent
        before it (or -1) and a finite offset."""
        if len(args) < 2 or type(args[0]) is not int or args[0] != 1:
            raise ValueError("unknown /caphub/skeleton version")
        count = _int(args[1])
        if count < 1 or len(args) != 2 + 5 * count:
            raise ValueError("/caphub/skeleton: count and arguments differ")
        self.names, self.parents, self.offsets = [], [], []
        for k in range(count):
            name, parent, x, y, z = args[2 + 5 * k:7 + 5 * k]
            if type(name) is not str or not -1 <= _int(parent) < k:
                raise ValueError("/caphub/skeleton: a bad name or parent")
            self.names.append(name)
            self.parents.append(parent)
            self.offsets.append((_metres(x), _metres(y), _metres(z)))

    def same_as(self, other):
        return other is not None and self.names == other.names and self.parents == other.parents


class Receiver:
    def __init__(self, port, host="0.0.0.0", hub=None):
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
        self.sock.bind((host, port))
        self.sock.setblocking(False)
        self.port = self.sock.getsockname()[1]
        self.skeleton = None
        self.frames_received = 0  # good frames read (whether returned or superseded)
        self.frames_skipped = 0  # good frames not returned: a newer one came in the same poll()
        self.bad_packets = 0  # datagrams refused whole (malformed, or not fitting the skeleton)
        self.hub = hub or None  # the sender's IP address (None: the first well-formed one)
        self.foreign_packets = 0  # datagrams from another address than the hub's
        self.max_datagrams, self.budget_s = MAX_DATAGRAMS, BUDGET_S

    def close(self):
        self.sock.close()

    def poll(self, newest_only=False):
        """The frames that arrived since the last call, oldest first, or only the newest one;
        every one fits self.skeleton (frames before any skeleton are not kept). Reads at most
        max_datagrams datagrams, and none after budget_s: the rest waits for the next call."""
        frames = []
        deadline = time.monotonic() + self.budget_s
        for _ in range(self.max_datagrams):
            try:
                data, sender = self.sock.recvfrom(65536)
            except (BlockingIOError, InterruptedError):
                break
            if self.hub is not None and sender[0] != self.hub:
                self.foreign_packets += 1
                continue
            try:
                skeleton, frame = self._datagram(data)
            except ValueError:  # also UnicodeDecodeError
                self.bad_packets += 1
            else:
                self.hub = sender[0]
                if skeleton is not None:
                    if not skeleton.same_as(self.skeleton):
                        self.frames_skipped += len(frames)
                        frames = []  # the frames before were another skeleton's
                    self.skeleton = skeleton
                if frame is not None:
                    self.frames_received += 1
                    if newest_only and frames:
                        self.frames_skipped += len(frames)
                        frames = []
                    frames.append(frame)
            if time.monotonic() > deadline:
                break
        return frames

    def _datagram(self, data):
        """(the skeleton it carries or None, its frame or None); ValueError if any of it is
        malformed, or the frame does not fit the skeleton in force."""
        msgs = []
        try:
            osc.decode(data, msgs)
        except (IndexError, TypeError) as e:
            raise ValueError(str(e)) from e
        skeleton, frame = None, None
        for address, args in msgs:
            if address == "/caphub/skeleton":
                skeleton = Skeleton(args)
            elif address == "/caphub/frame":
                if len(args) != 6:
                    raise ValueError("/caphub/frame: 6 arguments expected")
                frame = Frame()
                (frame.serial, frame.t_ns, frame.newest_ns, frame.sent_ns,
                 frame.not_measured, frame.calibrated) = (_int(a) for a in args)
                frame.root, frame.local = None, None
            elif address == "/caphub/root":
                if frame is None or frame.root is not None or len(args) != 3:
                    raise ValueError("/caphub/root: 3 arguments after /caphub/frame expected")
                frame.root = tuple(_metres(a) for a in args)
            elif address == "/caphub/local":
                if frame is None or frame.local is not None or len(args) % 4 != 0:
                    raise ValueError("/caphub/local: quaternions after /caphub/frame expected")
                frame.local = [_quaternion(args[4 * k:4 * k + 4]) for k in range(len(args) // 4)]
        if frame is None:
            return skeleton, None
        if frame.root is None or frame.local is None:
            raise ValueError("a frame without its root or rotations")
        against = skeleton if skeleton is not None else self.skeleton
        if against is None:
            return skeleton, None  # nothing to pose it with yet: the skeleton comes once a second
        if len(frame.local) != len(against.names):
            raise ValueError("a frame's rotations do not match the skeleton's segments")
        return skeleton, frame

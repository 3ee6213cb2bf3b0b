"""caphub's native stream (docs/streams.md) received on a UDP port: the newest frame and the
skeleton's description. No bpy here: the add-on polls it from a timer."""
import socket

from . import osc


class Frame:
    __slots__ = ("serial", "t_ns", "newest_ns", "sent_ns", "not_measured", "calibrated", "root",
                 "local")


class Skeleton:
    def __init__(self, args):
        if len(args) < 2 or args[0] != 1:
            raise ValueError("unknown /caphub/skeleton version")
        count = args[1]
        self.names, self.parents, self.offsets = [], [], []
        for k in range(count):
            name, parent, x, y, z = args[2 + 5 * k:7 + 5 * k]
            self.names.append(name)
            self.parents.append(parent)
            self.offsets.append((x, y, z))


class Receiver:
    def __init__(self, port, host="0.0.0.0"):
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
        self.sock.bind((host, port))
        self.sock.setblocking(False)
        self.port = self.sock.getsockname()[1]
        self.skeleton = None
        self.frames_received = 0
        self.bad_packets = 0

    def close(self):
        self.sock.close()

    def poll(self):
        """Every frame that arrived since the last call, oldest first (the skeleton is kept)."""
        frames = []
        while True:
            try:
                data = self.sock.recv(65536)
            except (BlockingIOError, InterruptedError):
                break
            msgs = []
            try:
                osc.decode(data, msgs)
            except (ValueError, IndexError, UnicodeDecodeError):
                self.bad_packets += 1
                continue
            frame = None
            for address, args in msgs:
                if address == "/caphub/skeleton":
                    try:
                        self.skeleton = Skeleton(args)
                    except (ValueError, IndexError):
                        self.bad_packets += 1
                elif address == "/caphub/frame" and len(args) == 6:
                    frame = Frame()
                    (frame.serial, frame.t_ns, frame.newest_ns, frame.sent_ns,
                     frame.not_measured, frame.calibrated) = args
                    frame.root, frame.local = None, None
                elif address == "/caphub/root" and frame is not None and len(args) == 3:
                    frame.root = tuple(args)
                elif address == "/caphub/local" and frame is not None and len(args) % 4 == 0:
                    frame.local = [tuple(args[4 * k:4 * k + 4]) for k in range(len(args) // 4)]
            if frame is not None and frame.root is not None and frame.local is not None:
                frames.append(frame)
                self.frames_received += 1
        return frames

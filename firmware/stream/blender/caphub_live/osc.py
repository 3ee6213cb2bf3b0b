"""A small OSC 1.0 decoder (messages and bundles; the types caphub sends): Blender ships no OSC
library, and the add-on must run in any Blender's own Python."""
import struct


def _string(data, i):
    end = data.index(b"\0", i)
    return data[i:end].decode("utf-8"), (end + 4) & ~3


def decode(data, out):
    """Appends (address, args) for every message in the packet; ValueError on a malformed one."""
    if data.startswith(b"#bundle\0"):
        i = 16
        while i + 4 <= len(data):
            (n,) = struct.unpack_from(">i", data, i)
            i += 4
            if n < 0 or i + n > len(data):
                raise ValueError("bundle element past the end")
            decode(data[i:i + n], out)
            i += n
        return
    address, i = _string(data, 0)
    tags, i = _string(data, i)
    if not tags.startswith(","):
        raise ValueError("no type tags")
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
        elif t == "d":
            args.append(struct.unpack_from(">d", data, i)[0])
            i += 8
        elif t == "s":
            s, i = _string(data, i)
            args.append(s)
        else:
            raise ValueError(f"type '{t}' not supported")
    out.append((address, args))

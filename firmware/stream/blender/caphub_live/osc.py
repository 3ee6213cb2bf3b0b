"""A small OSC 1.0 decoder (messages and bundles; the types caphub sends): Blender ships no OSC
library, and the add-on must run in any Blender's own Python. Whatever arrives on the port may
be malformed or hostile: every fault is a ValueError (no struct.error, no deep recursion)."""
import struct

# Bundles inside bundles: caphub sends one level; deeper than this is refused, not recursed.
MAX_BUNDLE_DEPTH = 8

_ARGS = {"f": (">f", 4), "i": (">i", 4), "h": (">q", 8), "d": (">d", 8)}


def _string(data, i):
    end = data.index(b"\0", i)
    return data[i:end].decode("utf-8"), (end + 4) & ~3


def decode(data, out, depth=0):
    """Appends (address, args) for every message in the packet; ValueError on a malformed one
    (an argument or element past the end, bytes left over, bundles nested too deep)."""
    if data.startswith(b"#bundle\0"):
        if depth >= MAX_BUNDLE_DEPTH:
            raise ValueError("bundles nested too deep")
        if len(data) < 16:
            raise ValueError("bundle without its time tag")
        i = 16
        while i < len(data):
            if i + 4 > len(data):
                raise ValueError("bundle element size past the end")
            (n,) = struct.unpack_from(">i", data, i)
            i += 4
            if n < 0 or i + n > len(data):
                raise ValueError("bundle element past the end")
            decode(data[i:i + n], out, depth + 1)
            i += n
        return
    address, i = _string(data, 0)
    tags, i = _string(data, i)
    if not tags.startswith(","):
        raise ValueError("no type tags")
    args = []
    for t in tags[1:]:
        if t == "s":
            s, i = _string(data, i)
            args.append(s)
            continue
        if t not in _ARGS:
            raise ValueError(f"type '{t}' not supported")
        fmt, size = _ARGS[t]
        if i + size > len(data):
            raise ValueError(f"argument '{t}' past the end")
        args.append(struct.unpack_from(fmt, data, i)[0])
        i += size
    if i != len(data):
        raise ValueError("bytes after the arguments")
    out.append((address, args))

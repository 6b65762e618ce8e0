#!/usr/bin/env python3
"""Writes tests/data/mitsuba/two-meshes.serialized, a Mitsuba `.serialized` file (format 4)
holding two meshes, for the serialized reader's tests and the validation scene
r-serialized.xml: mesh 0 an octahedron (single precision, no normals or texture
coordinates), mesh 1 a quad with vertex normals and texture coordinates that are not
symmetric in v (double precision). The layout is Mitsuba's documented one: per mesh the header
0x041C, 4 and a zlib stream; the meshes' offsets (uint64) and their count (uint32) at the end.

Usage: python3 tools/make-serialized-test-data.py
"""

import os
import struct
import zlib

HAS_NORMALS, HAS_TEXCOORDS, SINGLE, DOUBLE = 0x0001, 0x0002, 0x1000, 0x2000


def mesh(name, positions, triangles, normals=None, uvs=None, double=False):
    flags = (DOUBLE if double else SINGLE) | (HAS_NORMALS if normals else 0) | (HAS_TEXCOORDS if uvs else 0)
    fmt = "<d" if double else "<f"
    body = struct.pack("<I", flags) + name.encode() + b"\0"
    body += struct.pack("<QQ", len(positions), len(triangles))
    for group in [positions, normals or [], uvs or []]:
        for v in group:
            body += b"".join(struct.pack(fmt, x) for x in v)
    body += b"".join(struct.pack("<III", *t) for t in triangles)
    return struct.pack("<HH", 0x041C, 4) + zlib.compress(body)


def main():
    octahedron = [(1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1)]
    faces = [(0, 2, 4), (2, 1, 4), (1, 3, 4), (3, 0, 4), (2, 0, 5), (1, 2, 5), (3, 1, 5), (0, 3, 5)]
    quad = [(-1, 0, -1), (1, 0, -1), (1, 0, 1), (-1, 0, 1)]
    up = [(0, 1, 0)] * 4
    uvs = [(0, 0.1), (0.8, 0.1), (0.8, 0.65), (0, 0.65)]
    blobs = [mesh("octahedron", octahedron, faces), mesh("quad", quad, [(0, 3, 2), (0, 2, 1)], up, uvs, True)]
    data, offsets = b"", []
    for b in blobs:
        offsets.append(len(data))
        data += b
    data += b"".join(struct.pack("<Q", o) for o in offsets) + struct.pack("<I", len(blobs))
    out = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests", "data", "mitsuba", "two-meshes.serialized")
    with open(out, "wb") as f:
        f.write(data)
    print(f"wrote {len(data)} bytes to {os.path.relpath(out)}")


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""Writes the small OpenVDB files the tests and the example scene read, with OpenVDB itself.

Needs the OpenVDB Python module (Debian: `apt-get install python3-openvdb`, then run this with
/usr/bin/python3) and numpy. The outputs are committed, so tests and CI never run this; it
exists so the files can be checked and regenerated. Each `.vdb` that a test compares with a
`.vol` is written next to that `.vol` from the same array, so any difference is the reader's.

    /usr/bin/python3 tools/make-vdb-test-data.py
"""

import struct
import subprocess
import tempfile
from pathlib import Path

import numpy as np
import pyopenvdb as vdb

ROOT = Path(__file__).resolve().parent.parent
TESTS = ROOT / "tests" / "data" / "vdb"
SCENES = ROOT / "scenes" / "data"


def write_vol(path, density):
    """Mitsuba's .vol: `density` is indexed [x, y, z]; the file stores x fastest."""
    nx, ny, nz = density.shape
    header = b"VOL" + bytes([3]) + struct.pack("<5i", 1, nx, ny, nz, 1)
    header += struct.pack("<6f", 0, 0, 0, 1, 1, 1)
    path.write_bytes(header + density.astype("<f4").transpose(2, 1, 0).tobytes())


def read_vol(path):
    b = path.read_bytes()
    nx, ny, nz, c = struct.unpack("<4i", b[8:24])
    assert c == 1
    data = np.frombuffer(b[48:], dtype="<f4", count=nx * ny * nz)
    return data.reshape(nz, ny, nx).transpose(2, 1, 0).copy()


def recompress(src, flags, dst):
    """Rewrites `src` with OpenVDB's compression `flags` by tools/vdb-recompress.cpp, which
    needs libopenvdb-dev, libboost-dev, libtbb-dev and g++ (Debian's OpenVDB writes no zip:
    it is built without zlib, so only blosc, active-mask and no compression are reachable)."""
    with tempfile.TemporaryDirectory() as tmp:
        exe = Path(tmp) / "vdb-recompress"
        subprocess.run(
            ["g++", "-O1", "-std=c++17", str(ROOT / "tools" / "vdb-recompress.cpp"), "-o", str(exe),
             "-lopenvdb", "-ltbb"],
            check=True,
        )
        subprocess.run([str(exe), str(src), str(flags), str(dst)], check=True)


def float_grid(name, density, ijk, voxel, translation=(0, 0, 0)):
    g = vdb.FloatGrid()
    g.name = name
    # copyFromArray indexes the array [x, y, z], like `density`; zeros stay inactive.
    g.copyFromArray(density.astype(np.float32), ijk=ijk)
    g.transform = vdb.createLinearTransform(voxelSize=voxel)
    if any(translation):
        g.transform.translate(translation)
    g.gridClass = vdb.GridClass.FOG_VOLUME
    return g


def blob(shape):
    """A smooth positive density, non-zero in every voxel so the active box is the array."""
    axes = [np.linspace(-1, 1, n) for n in shape]
    x, y, z = np.meshgrid(*axes, indexing="ij")
    r2 = x * x + 1.5 * y * y + 2 * z * z
    return (0.05 + 3.0 * np.exp(-3 * r2) + 0.5 * np.sin(5 * x) ** 2).astype(np.float32)


def main():
    TESTS.mkdir(parents=True, exist_ok=True)

    # 16 x 12 x 8 voxels of 1/8 from index (-8, -6, -4), shifted by half a voxel: the box of
    # voxel faces is exactly [-1, 1] x [-0.75, 0.75] x [-0.5, 0.5].
    d = blob((16, 12, 8))
    vdb.write(str(TESTS / "blob.vdb"), [float_grid("density", d, (-8, -6, -4), 0.125, (0.0625,) * 3)])
    # The .vol holds the dense grid zerovar makes of it: the array with a border of zeros.
    write_vol(TESTS / "blob.vol", np.pad(d, 1))

    # The same file without blosc: active-mask compression only, values stored raw.
    recompress(TESTS / "blob.vdb", 2, TESTS / "blob-raw.vdb")

    # The same array saved as half floats.
    g = float_grid("density", d, (-8, -6, -4), 0.125, (0.0625,) * 3)
    g.saveFloatAsHalf = True
    vdb.write(str(TESTS / "half.vdb"), [g])

    # A 4^3 block of density 2 at index 0..3, voxels of 1/4, moved by (3, 0, 0): it fills world
    # [2.875, 3.875] x [-0.125, 0.875] x [-0.125, 0.875], nowhere near the origin.
    block = np.full((4, 4, 4), 2.0, dtype=np.float32)
    vdb.write(str(TESTS / "offset.vdb"), [float_grid("density", block, (0, 0, 0), 0.25, (3, 0, 0))])

    # Two active tiles (aligned 8^3 regions that OpenVDB stores as one value each) and a voxel.
    g = vdb.FloatGrid()
    g.name = "density"
    g.fill((0, 0, 0), (15, 7, 7), 1.0, True)
    g.prune()
    g.getAccessor().setValueOn((20, 3, 3), 2.0)
    vdb.write(str(TESTS / "tiles.vdb"), [g])

    # No `density`: two float grids, a vector grid and a boolean grid.
    smoke = float_grid("smoke", block, (0, 0, 0), 1.0)
    temperature = float_grid("temperature", 0.5 * block, (0, 0, 0), 1.0)
    vel = vdb.Vec3SGrid()
    vel.name = "vel"
    vel.getAccessor().setValueOn((1, 2, 3), (1.0, 0.0, 0.0))
    mask = vdb.BoolGrid()
    mask.name = "mask"
    mask.getAccessor().setValueOn((1, 2, 3), True)
    vdb.write(str(TESTS / "multi.vdb"), [smoke, temperature, vel, mask])

    # Two voxels a thousand voxels apart: a billion-voxel box from a tiny file.
    g = vdb.FloatGrid()
    g.name = "density"
    g.getAccessor().setValueOn((0, 0, 0), 1.0)
    g.getAccessor().setValueOn((1000, 1000, 1000), 1.0)
    vdb.write(str(TESTS / "huge.vdb"), [g])

    # A negative density.
    neg = np.full((2, 2, 2), 1.0, dtype=np.float32)
    neg[1, 0, 1] = -1.0
    vdb.write(str(TESTS / "negative.vdb"), [float_grid("density", neg, (0, 0, 0), 1.0)])

    # The example scene's cloud: scenes/data/cloud.vol as a VDB of unit voxels at the origin.
    cloud = read_vol(SCENES / "cloud.vol")
    cloud = np.where(cloud > 0, cloud, 0).astype(np.float32)
    vdb.write(str(SCENES / "cloud.vdb"), [float_grid("density", cloud, (0, 0, 0), 1.0)])

    for f in sorted(TESTS.glob("*")) + [SCENES / "cloud.vdb"]:
        print(f"{f.relative_to(ROOT)}: {f.stat().st_size} bytes")


if __name__ == "__main__":
    main()

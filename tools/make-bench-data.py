#!/usr/bin/env python3
"""Writes the data files of the held-out bench scenes (run once; the files are committed):

    scenes/data/puff.vol      a 64^3 cumulus puff (one channel): a noisy, lumpy blob with
                              wisps, values in [0, 1]
    scenes/data/dye.vol       the same shape at 48^3 with three proportional channels (a
                              density times a colour), for a chromatic heterogeneous medium
    scenes/data/haze.vol      a 32 x 20 x 64 haze (one channel, x y z): smooth noise in about
                              [0.2, 1], for a heterogeneous fog room
    scenes/data/sunset.exr    a 512 x 256 lat-long sky: a gradient from blue overhead to a
                              warm horizon, a dark ground and a small, bright sun (about
                              1.5 degrees wide, 25 degrees above the horizon)

Needs numpy and OpenEXR (pip install numpy OpenEXR). Deterministic: the same files each run.
"""

import pathlib
import struct

import numpy as np
import OpenEXR

OUT = pathlib.Path(__file__).resolve().parent.parent / "scenes" / "data"


def value_noise(n, cells, rng):
    """Smooth noise on an n^3 grid with `cells` lattice cells along each axis (box_noise)."""
    return box_noise((n, n, n), (cells, cells, cells), rng)


def puff(n, seed):
    """Density in [0, 1] on an n^3 grid indexed [z, y, x]."""
    rng = np.random.default_rng(seed)
    noise = sum(value_noise(n, c, rng) / (k + 1) for k, c in enumerate((3, 6, 12, 24)))
    noise /= sum(1 / (k + 1) for k in range(4))
    c = (np.arange(n) + 0.5) / n - 0.5
    z, y, x = np.meshgrid(c, c, c, indexing="ij")
    # A flattened blob, flatter at the bottom, with two lobes on top.
    r = np.sqrt(x**2 + (1.4 * (y + 0.08)) ** 2 + z**2)
    lobes = np.exp(-((x - 0.12) ** 2 + (y - 0.12) ** 2 + z**2) / 0.02)
    lobes += np.exp(-((x + 0.14) ** 2 + (y - 0.08) ** 2 + (z - 0.05) ** 2) / 0.015)
    d = 1.0 - r / 0.38 + 0.25 * lobes + 0.9 * (noise - 0.5)
    d[y < -0.3] = 0.0
    return np.clip(d * 2.0, 0.0, 1.0).astype(np.float32)


def box_noise(shape, cells, rng):
    """Smooth noise on a grid of `shape` [z, y, x]: random values on a lattice of `cells`
    [z, y, x] cells, interpolated by a smoothstep."""
    lattice = rng.random(tuple(c + 1 for c in cells))
    axes = []
    for n, c in zip(shape, cells):
        x = np.linspace(0, c, n, endpoint=False) + 0.5 * c / n
        i = np.minimum(x.astype(int), c - 1)
        f = x - i
        axes.append((i, f * f * (3 - 2 * f)))
    (iz, fz), (iy, fy), (ix, fx) = axes
    out = np.zeros(shape)
    for dz in (0, 1):
        wz = fz if dz else 1 - fz
        for dy in (0, 1):
            wy = fy if dy else 1 - fy
            for dx in (0, 1):
                wx = fx if dx else 1 - fx
                v = lattice[np.ix_(iz + dz, iy + dy, ix + dx)]
                out += v * wz[:, None, None] * wy[None, :, None] * wx[None, None, :]
    return out


def haze(shape, seed):
    """Haze density in about [0.2, 1] on a grid of `shape` [z, y, x]: three octaves of smooth
    noise, denser towards the floor, so that it varies about fivefold."""
    rng = np.random.default_rng(seed)
    nz, ny, nx = shape
    octaves = [(max(2, nz // 8 * k), max(2, ny // 10 * k), max(2, nx // 8 * k)) for k in (1, 2, 4)]
    noise = sum(box_noise(shape, c, rng) / (k + 1) for k, c in enumerate(octaves))
    noise /= sum(1 / (k + 1) for k in range(len(octaves)))
    height = (np.arange(ny) + 0.5) / ny
    d = 0.2 + 0.8 * np.clip((noise - 0.25) / 0.5, 0, 1) ** 1.5 * (1.1 - 0.5 * height)[None, :, None]
    return np.clip(d, 0.0, 1.0).astype(np.float32)


def write_vol(path, grid, colour=None):
    """A Mitsuba .vol file (float32, x fastest) of `grid` [z, y, x], times `colour` per
    channel when given."""
    nz, ny, nx = grid.shape
    data = grid[..., None] * np.asarray(colour, np.float32) if colour else grid[..., None]
    channels = data.shape[-1]
    header = b"VOL" + bytes([3]) + struct.pack("<iiiii", 1, nx, ny, nz, channels)
    header += struct.pack("<6f", 0, 0, 0, 1, 1, 1)
    path.write_bytes(header + data.astype("<f4").tobytes())


def sunset(w, h):
    """A lat-long sky [row, column, rgb]: row 0 looks straight up."""
    theta = (np.arange(h) + 0.5) / h * np.pi  # from +y
    phi = (np.arange(w) + 0.5) / w * 2 * np.pi
    elevation = np.pi / 2 - theta[:, None]
    up = np.clip(np.sin(elevation), 0, 1)
    zenith = np.array([0.10, 0.18, 0.45])
    horizon = np.array([0.85, 0.45, 0.25])
    sky = zenith * up[..., None] + horizon * (1 - up[..., None]) ** 3
    ground = np.array([0.06, 0.05, 0.04])
    sky = np.where(elevation[..., None] < 0, ground, sky) * np.ones((h, w, 3))
    # The sun: 25 degrees up at phi = 1.2 rad, a disk of 0.75 degrees radius.
    s_el, s_phi = np.radians(25), 1.2
    d = np.stack(np.broadcast_arrays(np.cos(elevation) * np.cos(phi[None, :]),
                                     np.sin(elevation) * np.ones_like(phi[None, :]),
                                     np.cos(elevation) * np.sin(phi[None, :])), -1)
    s = np.array([np.cos(s_el) * np.cos(s_phi), np.sin(s_el), np.cos(s_el) * np.sin(s_phi)])
    angle = np.arccos(np.clip(d @ s, -1, 1))
    sky[angle < np.radians(0.75)] = np.array([900.0, 780.0, 600.0])
    return sky.astype(np.float32)


def main():
    OUT.mkdir(parents=True, exist_ok=True)
    write_vol(OUT / "puff.vol", puff(64, 7))
    write_vol(OUT / "dye.vol", puff(48, 11), colour=(0.25, 0.6, 1.0))
    write_vol(OUT / "haze.vol", haze((64, 20, 32), 5))
    sky = sunset(512, 256)
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with OpenEXR.File(header, {"RGB": sky}) as f:
        f.write(str(OUT / "sunset.exr"))
    print("wrote", *(OUT / f for f in ("puff.vol", "dye.vol", "haze.vol", "sunset.exr")))


if __name__ == "__main__":
    main()

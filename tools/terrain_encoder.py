"""Why `wavemesh tiles` calls quantized-mesh-encoder's writers but not its one-call encode() nor its
oct_encode: the figures docs/tiles.md quotes, measured on the Jacksboro pyramid (levels 0..12) and on
100,000 random unit vectors, each decoded by quantized-mesh-tile (an independent reader).

    .venv/bin/python tools/terrain_encoder.py
"""

import io

import matplotlib.cbook
import numpy as np
from quantized_mesh_encoder import encode
from quantized_mesh_encoder.normals import oct_encode as encoder_oct
from quantized_mesh_tile.terrain import TerrainTile
from quantized_mesh_tile.utils import octDecode
from wavemesh import api
from wavemesh.io import terrain
from wavemesh.io.heightfield import from_array
from wavemesh.refine.native import RefineParams


def decode(data: bytes, bounds, lighting: bool) -> TerrainTile:
    w, s, e, n = bounds
    t = TerrainTile(west=w, south=s, east=e, north=n)
    t.fromBytesIO(io.BytesIO(data), hasLighting=lighting)
    return t


def pyramid() -> None:
    hf = api.load_input(matplotlib.cbook.get_sample_data("jacksboro_fault_dem.npz", asfileobj=False),
                        key="elevation")
    s = terrain.sampler(hf)
    top = terrain.default_max_zoom(s)
    # u units, h steps, edges missed
    worst = {"encode()": [0.0, 0.0, 0], "wavemesh.io.terrain": [0.0, 0.0, 0]}
    tiles = edges = 0
    for level in range(top + 1):
        x0, y0, x1, y1 = terrain.tiles_at(level, s.bounds)
        for x in range(x0, x1 + 1):
            for y in range(y0, y1 + 1):
                z, _, _ = terrain.tile_grid(s, level, x, y)
                params = api.MeshParams(refine=RefineParams(zeta=terrain.tolerance(level, top, 1.0),
                                                            metric="vertical"))
                m = api.mesh(from_array(z), params).mesh
                zv = m.z(z)
                b = terrain.tile_bounds(level, x, y)
                w, so, e, n = b
                lon = w + m.xy[:, 0] / 64 * (e - w)
                lat = n - m.xy[:, 1] / 64 * (n - so)
                f = io.BytesIO()
                encode(f, np.column_stack([lon, lat, zv]), m.tris[:, ::-1].astype(np.uint32), bounds=b)
                on = (m.xy[:, 0] % 64 == 0) | (m.xy[:, 1] % 64 == 0)
                tiles += 1
                edges += int(on.sum())
                ours = terrain.encode_tile(m, zv, level, x, y)
                for name, data, lighting in (("encode()", f.getvalue(), False),
                                             ("wavemesh.io.terrain", ours, True)):
                    t = decode(data, b, lighting)
                    # decoded vertices come in another order: match them by their (u, v) to the nearest grid
                    u = np.array(t.u, float)
                    col = np.rint(u * 64 / 32767)
                    row = 64 - np.rint(np.array(t.v, float) * 64 / 32767)
                    idx = {(int(c), int(r)): i for i, (c, r) in enumerate(m.xy)}
                    k = np.array([idx[(int(c), int(r))] for c, r in zip(col, row, strict=True)])
                    lo, hi = np.float32(zv.min()), np.float32(zv.max())
                    r = worst[name]
                    r[0] = max(r[0], float(np.abs(u - m.xy[k, 0] * 32767 / 64).max()))
                    if hi > lo:
                        exact = (zv[k] - lo) / (hi - lo) * 32767
                        r[1] = max(r[1], float(np.abs(np.array(t.h) - exact).max()))
                    r[2] += int(on.sum()) - len(set(t.westI) | set(t.eastI) | set(t.southI) | set(t.northI))
    print(f"Jacksboro, levels 0..{top}: {tiles} tiles, {edges} edge vertices")
    for name, (du, dh, missed) in worst.items():
        print(f"  {name:>16}: u off the grid position by up to {du:.2f} units, h by up to {dh:.2f} steps, "
              f"{missed} edge vertices missing from the edge lists")


def normals() -> None:
    rng = np.random.default_rng(0)
    v = rng.normal(size=(100000, 3))
    v = np.concatenate([v / np.linalg.norm(v, axis=1, keepdims=True), np.eye(3), -np.eye(3)])
    for name, enc in (("oct_encode (encoder)", encoder_oct), ("terrain.oct_encode", terrain.oct_encode)):
        d = np.array([octDecode(int(a), int(b)) for a, b in enc(v)])
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        angle = np.degrees(np.arccos(np.clip(np.sum(d * v, axis=1), -1, 1)))
        print(f"  {name:>20}: worst {angle.max():.2f} deg, median {np.median(angle):.3f} deg; "
              f"(1, 0, 0) decodes as {np.round(d[-6], 3).tolist()}")


if __name__ == "__main__":
    pyramid()
    normals()

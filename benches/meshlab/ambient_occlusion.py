"""MeshLab's ambient occlusion (PyMeshLab's compute_scalar_ambient_occlusion,
Embree inside), timed, for the reference bench's side-by-side.

    python3 ambient_occlusion.py MESH RAYS SUBDIVISIONS REPEATS

Loads MESH, subdivides it SUBDIVISIONS times at edge midpoints, runs the
filter REPEATS times and prints one JSON line: vertices, faces, the filter's
seconds per run, and the rays it traced per run. The filter shoots, from
each face's barycentre, the RAYS directions of a Fibonacci sphere that lie
above the face (closest-hit rays, rtcIntersect1), so that count is computed
here from the face normals and the same directions.
"""
import json
import sys
import time

import numpy as np
import pymeshlab


def fibonacci(n):
    """vcg::GenNormal::Fibonacci's directions."""
    i = np.arange(n)
    golden = np.sqrt(5) * 0.5 + 0.5
    phi = 2 * np.pi * (i / golden - np.floor(i / golden))
    cos_theta = 1 - (2 * i + 1) / n
    sin_theta = np.sqrt(np.clip(1 - cos_theta**2, 0, 1))
    return np.stack([np.cos(phi) * sin_theta, np.sin(phi) * sin_theta, cos_theta], 1)


def main():
    path, rays, subdivisions, repeats = sys.argv[1], *map(int, sys.argv[2:5])
    seconds = []
    for _ in range(repeats):
        ms = pymeshlab.MeshSet()
        ms.load_new_mesh(path)
        if subdivisions:
            ms.meshing_surface_subdivision_midpoint(
                iterations=subdivisions, threshold=pymeshlab.PercentageValue(0)
            )
        start = time.perf_counter()
        ms.compute_scalar_ambient_occlusion(rays=rays)
        seconds.append(time.perf_counter() - start)
    mesh = ms.current_mesh()
    traced = int((mesh.face_normal_matrix() @ fibonacci(rays).T > 0).sum())
    print(json.dumps({
        "vertices": mesh.vertex_number(),
        "faces": mesh.face_number(),
        "seconds": seconds,
        "rays": traced,
    }))


if __name__ == "__main__":
    main()

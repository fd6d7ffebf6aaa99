"""Convex decomposition of a concave mesh (CoACD), cached next to the mesh.

A mesh body is its convex hull unless it asks for decomposition (as MuJoCo
and Drake make a hull of a mesh). CoACD (PyPI ``coacd``) splits the surface
into at most ``max_hulls`` convex hulls whose concavity stays below
``threshold``; its run takes seconds to minutes, so the hulls are cached in
a JSON file beside the mesh, ``<mesh file name>.<key>.hulls.json``, where
the key hashes the mesh's bytes and the settings: an edited mesh or other
settings never read a stale cache. ``collres_decompose MESH`` writes it ahead
of time; ``hulls`` writes it when it is missing, with a log line.

Units: the mesh's (m); vertices in the mesh's frame, which is the body frame.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
from pathlib import Path
from typing import Callable

import numpy as np

from collres_ros.core.config import DECOMPOSE_MAX_HULLS, DECOMPOSE_THRESHOLD, HULL_MAX_VERTICES
from collres_ros.core.shapes import hull_problem, hull_vertices, mesh_triangles

CACHE_VERSION = 1   # the cache file's layout; part of the key
SEED = 0            # CoACD's random seed: the same mesh and settings give the same hulls
LOG = logging.getLogger('collres_ros.decomposition')


def cache_key(data: bytes, threshold: float, max_hulls: int) -> str:
    """Hex key (16 digits) of a mesh's bytes and the decomposition settings."""
    digest = hashlib.sha256(data)
    digest.update(json.dumps([CACHE_VERSION, float(threshold), int(max_hulls), SEED,
                              HULL_MAX_VERTICES]).encode())
    return digest.hexdigest()[:16]


def cache_path(mesh: Path, data: bytes, threshold: float = DECOMPOSE_THRESHOLD,
               max_hulls: int = DECOMPOSE_MAX_HULLS) -> Path:
    """Where the hulls of ``mesh`` (whose bytes are ``data``) under these settings live."""
    return mesh.with_name(f'{mesh.name}.{cache_key(data, threshold, max_hulls)}.hulls.json')


def decompose(data: bytes, suffix: str, threshold: float = DECOMPOSE_THRESHOLD,
              max_hulls: int = DECOMPOSE_MAX_HULLS, name: str = 'mesh') -> list[np.ndarray]:
    """Convex hulls (each (K, 3) m, at most HULL_MAX_VERTICES vertices) of the surface of an
    OBJ/STL file's bytes, by CoACD. ValueError when the file has no surface or CoACD gives
    no usable hull."""
    import coacd
    vertices, triangles = mesh_triangles(data, suffix, name)
    coacd.set_log_level('error')
    parts = coacd.run_coacd(coacd.Mesh(vertices, triangles), threshold=float(threshold),
                            max_convex_hull=int(max_hulls), max_ch_vertex=HULL_MAX_VERTICES,
                            seed=SEED)
    hulls = [hull_vertices(np.asarray(points, dtype=float)) for points, _ in parts]
    hulls = [h for h in hulls if not hull_problem(h)]
    if not hulls:
        raise ValueError(f'{name}: CoACD found no convex hull with a volume')
    return hulls


def write_cache(path: Path, hulls: list[np.ndarray], key: str) -> None:
    """Write the hulls atomically (a reader never sees half a file)."""
    text = json.dumps({'version': CACHE_VERSION, 'key': key,
                       'hulls': [h.reshape(-1).tolist() for h in hulls]})
    partial = path.with_name(path.name + f'.{os.getpid()}.partial')
    partial.write_text(text)
    os.replace(partial, path)


def read_cache(path: Path, key: str) -> list[np.ndarray] | None:
    """The hulls of a cache file, or None when it is missing, of another key, or not a list
    of hulls that can be built (a damaged cache is made again, never trusted)."""
    try:
        document = json.loads(path.read_text())
        if document.get('version') != CACHE_VERSION or document.get('key') != key:
            return None
        hulls = [np.array(flat, dtype=float).reshape(-1, 3) for flat in document['hulls']]
    except (OSError, ValueError, TypeError, KeyError, AttributeError):
        return None
    if not hulls or any(hull_problem(h) for h in hulls):
        return None
    return hulls


def hulls(mesh: Path, data: bytes, threshold: float = DECOMPOSE_THRESHOLD,
          max_hulls: int = DECOMPOSE_MAX_HULLS,
          log: Callable[[str], None] = LOG.warning) -> list[np.ndarray]:
    """The decomposition of ``mesh`` (bytes ``data``): from its cache, or made now by CoACD
    (``log`` says so first) and cached (a read-only folder only costs the cache)."""
    key = cache_key(data, threshold, max_hulls)
    path = cache_path(mesh, data, threshold, max_hulls)
    cached = read_cache(path, key)
    if cached is not None:
        return cached
    log(f'decomposing {mesh} (CoACD, threshold {threshold:g}, at most {max_hulls} hulls): no '
        f'cache at {path.name}; collres_decompose makes it ahead of time')
    made = decompose(data, mesh.suffix, threshold, max_hulls, str(mesh))
    try:
        write_cache(path, made, key)
    except OSError as error:
        log(f'cannot write {path} ({error.strerror or error}): decomposing again next time')
    return made

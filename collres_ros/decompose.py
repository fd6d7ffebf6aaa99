"""collres_decompose: the convex decomposition of a mesh, cached next to it, ahead of time.

::

    collres_decompose MESH [--threshold T] [--max-hulls N] [--force]

Runs CoACD on MESH (OBJ or STL) with the settings a body's ``decompose_threshold`` and
``decompose_max_hulls`` name (defaults 0.05 and 16) and writes the hulls to the cache
file beside the mesh that collres_node, collres_sim and collres_replay read for a body
with ``decompose: true`` (``collres_ros.core.decomposition``). A line on stderr says what
runs (on a terminal only); stdout gets the cache path and the hull count. Errors exit 1
with one ``error: ...`` line, bad flags 2.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Sequence

from collres_ros.core.config import DECOMPOSE_MAX_HULLS, DECOMPOSE_THRESHOLD
from collres_ros.ros import cli


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog='collres_decompose',
        description='Decompose a concave mesh into convex hulls (CoACD) and cache them next '
                    'to it for bodies with decompose: true.')
    p.add_argument('mesh', help='mesh file (.obj or .stl)')
    p.add_argument('--threshold', type=float, default=DECOMPOSE_THRESHOLD,
                   help=f'concavity threshold in [0.01, 1] (default {DECOMPOSE_THRESHOLD})')
    p.add_argument('--max-hulls', type=int, default=DECOMPOSE_MAX_HULLS,
                   help=f'most hulls, in [1, 256] (default {DECOMPOSE_MAX_HULLS})')
    p.add_argument('--force', action='store_true', help='decompose again even if cached')
    return p


def _run(args: argparse.Namespace) -> int:
    from collres_ros.core import decomposition
    from collres_ros.ros.console import interactive
    from collres_ros.ros.params import _mesh_bytes
    mesh = Path(args.mesh)
    data = _mesh_bytes(mesh)
    path = decomposition.cache_path(mesh, data, args.threshold, args.max_hulls)
    if args.force:
        path.unlink(missing_ok=True)

    def say(line: str) -> None:
        if interactive():
            print(line, file=sys.stderr, flush=True)
    hulls = decomposition.hulls(mesh, data, args.threshold, args.max_hulls, say)
    if not path.is_file():
        raise OSError(f'cannot write {path}')
    print(f'{path} ({len(hulls)} hulls)')
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Console script ``collres_decompose``: 0 when the cache exists, 1 with ``error: ...``."""
    args = parser().parse_args(argv)
    if not 0.01 <= args.threshold <= 1.0:
        parser().exit(2, f'error: --threshold: must be in [0.01, 1] (got {args.threshold})\n')
    if not 1 <= args.max_hulls <= 256:
        parser().exit(2, f'error: --max-hulls: must be in [1, 256] (got {args.max_hulls})\n')
    return cli.run(lambda: _run(args))


if __name__ == '__main__':
    sys.exit(main())

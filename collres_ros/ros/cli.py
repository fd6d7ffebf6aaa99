"""What every executable's ``main`` shares: ROS argument splitting and one error exit path.

A user error is printed as one line ``error: <what>`` on stderr and gives exit
code 1, never a traceback (as the ros2_tracing CLIs do).
"""

from __future__ import annotations

import sys
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Callable, Iterator, Optional, Sequence


class CliError(Exception):
    """A user error of an executable: one line, printed as ``error: ...``."""


# What a main reports as a one-line error instead of a traceback.
USER_ERRORS: tuple[type[BaseException], ...] = (CliError, ValueError, OSError)


def error(message: object, code: int = 1) -> int:
    """Print ``error: <message>`` (first line only) on stderr; return ``code``."""
    text = str(message).strip().splitlines()
    print(f'error: {text[0] if text else type(message).__name__}', file=sys.stderr)
    return code


def run(body: Callable[[], int], errors: tuple[type[BaseException], ...] = USER_ERRORS) -> int:
    """``body()``, with ``errors`` turned into the one-line ``error: ...`` exit (code 1)."""
    try:
        return body()
    except errors as failure:
        return error(failure)


def split_ros_args(argv: Sequence[str]) -> tuple[list[str], list[str]]:
    """(own arguments, ROS arguments from ``--ros-args`` on)."""
    argv = list(argv)
    if '--ros-args' in argv:
        i = argv.index('--ros-args')
        return argv[:i], argv[i:]
    return argv, []


def params_files(argv: Sequence[str]) -> list[str]:
    """Every ``--params-file FILE`` of ``argv``, in order (rcl: later files win)."""
    return [argv[k + 1] for k, arg in enumerate(argv[:-1]) if arg == '--params-file']


def last_params_file(argv: Sequence[str]) -> Optional[Path]:
    """The last ``--params-file`` of ``argv``, or None."""
    files = params_files(argv)
    return Path(files[-1]) if files else None


def namespace_from_ros_args(argv: Sequence[str], node: str) -> str:
    """The namespace a ``-r [node:]__ns:=NS`` remap in ROS arguments gives ('/' without)."""
    namespace = '/'
    for flag, rule in zip(argv, argv[1:]):
        if flag in ('-r', '--remap'):
            target, _, value = rule.partition(':=')
            if target in ('__ns', f'{node}:__ns') and value:
                namespace = value
    return namespace


@contextmanager
def ros_init(*, args: Optional[Sequence[str]] = None, context: Any = None,
             domain_id: Optional[int] = None,
             failure: str = 'cannot initialise ROS') -> Iterator[Any]:
    """``with ros_init(args=...):`` the ``with rclpy.init(...)`` idiom on Jazzy's rclpy.

    rclpy 7.1 (Jazzy) ``init`` returns None (the context manager it returns
    came later), so this does the same: initialise ``context`` (default: the
    global one) and shut it down on leaving, whatever happened inside. A
    failing init (rcl's argument and params-file parser) raises CliError
    ``<failure>: <rcl's first line>``.
    """
    import rclpy
    try:
        rclpy.init(args=None if args is None else list(args), context=context,
                   domain_id=domain_id)
    except (KeyboardInterrupt, CliError):
        raise
    except Exception as error:  # RCLError and friends
        lines = str(error).strip().splitlines() or [type(error).__name__]
        raise CliError(f'{failure}: {lines[0]}') from None
    try:
        yield context
    finally:
        rclpy.try_shutdown(context=context)

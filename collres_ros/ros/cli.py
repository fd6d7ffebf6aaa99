"""What every executable's ``main`` shares: ROS argument splitting and one error exit path.

A user error is printed as one line ``error: <what>`` on stderr and gives exit
code 1, never a traceback (as the ros2_tracing CLIs do).
"""

from __future__ import annotations

import argparse
import math
import signal
import sys
import threading
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Callable, Iterator, NoReturn, Optional, Sequence


class CliError(Exception):
    """A user error of an executable: one line, printed as ``error: ...``."""


# What a main reports as a one-line error instead of a traceback.
USER_ERRORS: tuple[type[BaseException], ...] = (CliError, ValueError, OSError)


def error(message: object, code: int = 1) -> int:
    """Print ``error: <message>`` (first line only) on stderr; return ``code``."""
    text = str(message).strip().splitlines()
    print(f'error: {text[0] if text else type(message).__name__}', file=sys.stderr)
    return code


_TERMINATED = threading.Event()


def terminate_as_interrupt() -> None:
    """SIGTERM ends this process as Ctrl-C does (KeyboardInterrupt: bags are finished,
    children stopped, exit 130) instead of at once. Main thread only. Python drops an
    exception a handler raises at some points (during a fork, in a finaliser): loops that
    wait call ``check_terminated``, which raises it again."""
    def interrupt(signum: int, frame: Any) -> None:
        _TERMINATED.set()
        raise KeyboardInterrupt
    signal.signal(signal.SIGTERM, interrupt)


def check_terminated() -> bool:
    """KeyboardInterrupt once SIGTERM came (see ``terminate_as_interrupt``); else False."""
    if _TERMINATED.is_set():
        raise KeyboardInterrupt
    return False


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


def param_overrides(argv: Sequence[str], node: str) -> dict[str, Any]:
    """The ``-p [node:]NAME:=VALUE`` parameters of ROS arguments, values read as rcl reads
    them (YAML, ``params_yaml``: ``true``, ``1e-05``, ``[0.0, 1.0]``); later ones win.
    CliError (one line) for a value rcl would not read either."""
    from collres_ros.ros import params_yaml
    values: dict[str, Any] = {}
    for flag, rule in zip(argv, argv[1:]):
        if flag not in ('-p', '--param'):
            continue
        name, sep, text = rule.partition(':=')
        target, _, short = name.rpartition(':')
        if not sep or not short or target not in ('', node):
            continue
        try:
            document = params_yaml.parse(f'value: {text}', f'-p {name}')
        except ValueError as error:
            raise CliError(str(error)) from None
        value = document.get('value') if isinstance(document, dict) else None
        values[short] = None if value in ([], {}) else value
    return values


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
             failure: str = 'cannot initialise ROS',
             explain: Optional[Callable[[], None]] = None) -> Iterator[Any]:
    """``with ros_init(args=...):`` the ``with rclpy.init(...)`` idiom on Jazzy's rclpy.

    rclpy 7.1 (Jazzy) ``init`` returns None (the context manager it returns
    came later), so this does the same: initialise ``context`` (default: the
    global one) and shut it down on leaving, whatever happened inside. A
    failing init (rcl's argument and params-file parser) raises CliError
    ``<failure>: <rcl's first line>``, unless ``explain()`` raises a clearer error first.
    """
    import rclpy
    from rclpy.signals import SignalHandlerOptions, install_signal_handlers
    # rcl parses the params files inside init, in C, for up to minutes on a huge file: Python's
    # SIGINT handler cannot run there, so Ctrl-C would wait for the parse to end. The OS
    # default ends the process at once (no traceback); rclpy's own handlers come after.
    main = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGINT, signal.SIG_DFL) if main else None
    try:
        rclpy.init(args=None if args is None else list(args), context=context,
                   domain_id=domain_id, signal_handler_options=SignalHandlerOptions.NO)
    except (KeyboardInterrupt, CliError):
        raise
    except Exception as error:  # RCLError and friends
        if explain is not None:
            explain()
        lines = str(error).strip().splitlines() or [type(error).__name__]
        raise CliError(f'{failure}: {lines[0]}') from None
    finally:
        if previous is not None:
            signal.signal(signal.SIGINT, previous)
    if context is None or context is rclpy.get_default_context():
        install_signal_handlers(SignalHandlerOptions.ALL)   # as rclpy.init does
    try:
        yield context
    finally:
        rclpy.try_shutdown(context=context)


# --- flags: checked when parsed, before anything is created ----------------------------------

class ArgumentParser(argparse.ArgumentParser):
    """argparse with the one-line error of every main: ``error: --flag: why``, exit 2."""

    def error(self, message: str) -> NoReturn:
        text = message[len('argument '):] if message.startswith('argument ') else message
        print(f'error: {text}', file=sys.stderr)
        raise SystemExit(2)


def number(low: float, high: float, *, above: bool = False, integer: bool = False
           ) -> Callable[[str], Any]:
    """An argparse ``type``: a finite number in [low, high] (``above``: in (low, high]).

    NaN, infinities and values outside the range are refused when the flag is
    parsed, with the range in the message.
    """
    kind = 'an integer' if integer else 'a number'
    span = f'({low:g}, {high:g}]' if above else f'[{low:g}, {high:g}]'

    def parse(text: str) -> Any:
        try:
            value = int(text) if integer else float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f'must be {kind} in {span} (got {text!r})') \
                from None
        if not math.isfinite(value) or value < low or value > high \
                or (above and value <= low):
            raise argparse.ArgumentTypeError(f'must be {kind} in {span} (got {text})')
        return value
    parse.__name__ = 'integer' if integer else 'number'
    return parse


DOMAIN_IDS = (0, 232)   # ROS_DOMAIN_ID: the range the DDS port mapping allows
domain_id_type = number(*DOMAIN_IDS, integer=True)

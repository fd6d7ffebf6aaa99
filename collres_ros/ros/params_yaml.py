"""A params file's YAML read as rcl reads it (``rcl_yaml_param_parser``), with bounds.

The one reading of a params file for collres_sim, collres_replay (a bag's
recorded params too) and the node's own file check, so that every executable
takes a file as the node's rcl does:

- no aliases (rcl refuses them: a few hundred bytes of nested aliases would
  otherwise expand to millions of values), no tags except ``!!str``;
- a scalar's type by rcl's rules: quoted or ``!!str`` is a string; else a
  bool (``true``/``yes``/``on``/``y`` and their capitalised and false forms),
  else an integer as C's ``strtol`` reads it (``010`` is 8, ``0x10`` 16), else
  a double as ``strtod`` reads it (``1e-05``, ``.inf``, ``nan``; out of range
  is a string), else a string;
- at most ``PARAMS_FILE_MAX_BYTES`` bytes and ``PARAMS_FILE_MAX_DEPTH`` levels.

Errors are ``ValueError`` with one line naming the file and the line. No ROS import.
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

from collres_ros.core.config import PARAMS_FILE_MAX_BYTES, PARAMS_FILE_MAX_DEPTH

STR_TAG = 'tag:yaml.org,2002:str'
_TRUE = {'Y', 'y', 'yes', 'Yes', 'YES', 'true', 'True', 'TRUE', 'on', 'On', 'ON'}
_FALSE = {'N', 'n', 'no', 'No', 'NO', 'false', 'False', 'FALSE', 'off', 'Off', 'OFF'}
_DOT_SPECIAL = {f'{sign}.{word}' for sign in ('', '+', '-')
                for word in ('inf', 'Inf', 'INF')} | {'.nan', '.NaN', '.NAN'}
_INT = re.compile(r'[+-]?(0[xX][0-9a-fA-F]+|0[0-7]*|[1-9][0-9]*)')
_DECIMAL = re.compile(r'[+-]?(?P<m>[0-9]+\.?[0-9]*|\.[0-9]+)([eE][+-]?[0-9]+)?')
_HEX_FLOAT = re.compile(r'[+-]?0[xX](?P<m>[0-9a-fA-F]+\.?[0-9a-fA-F]*|\.[0-9a-fA-F]+)'
                        r'([pP][+-]?[0-9]+)?')
_INF_NAN = re.compile(r'[+-]?(inf|infinity|nan(\([0-9A-Za-z_]*\))?)', re.IGNORECASE)
_INT64 = (-2 ** 63, 2 ** 63 - 1)
_SMALLEST_NORMAL = 2.2250738585072014e-308


def scalar_value(text: str, quoted: bool) -> Any:
    """The value rcl gives a scalar: bool, int, float or str (see the module docstring)."""
    if quoted:
        return text
    if text in _TRUE:
        return True
    if text in _FALSE:
        return False
    if _INT.fullmatch(text):
        value = int(text, 16) if 'x' in text.lower() else int(text, 8 if re.fullmatch(
            r'[+-]?0[0-7]+', text) else 10)
        if _INT64[0] <= value <= _INT64[1]:
            return value   # out of range: strtol says ERANGE and rcl tries a double
    if text in _DOT_SPECIAL:
        return math.nan if text.lower() == '.nan' else \
            (-math.inf if text.startswith('-') else math.inf)
    if _INF_NAN.fullmatch(text):
        return float(text.split('(')[0])
    decimal, hexadecimal = _DECIMAL.fullmatch(text), _HEX_FLOAT.fullmatch(text)
    if decimal or hexadecimal:
        value = float(text) if decimal else float.fromhex(text)
        mantissa = (decimal or hexadecimal).group('m')   # type: ignore[union-attr]
        nonzero = any(c not in '0.' for c in mantissa)
        if math.isinf(value) or (nonzero and abs(value) < _SMALLEST_NORMAL):
            return text   # strtod says ERANGE: rcl keeps the text as a string
        return value
    return text


def read_text(path: Path) -> str:
    """The text of a params file of at most ``PARAMS_FILE_MAX_BYTES`` (ValueError, OSError)."""
    with open(path, 'rb') as file:
        data = file.read(PARAMS_FILE_MAX_BYTES + 1)
    if len(data) > PARAMS_FILE_MAX_BYTES:
        raise ValueError(f'{path}: more than the limit of {PARAMS_FILE_MAX_BYTES} bytes '
                         'for a params file')
    try:
        return data.decode('utf-8')
    except UnicodeDecodeError as error:
        raise ValueError(f'{path}: not UTF-8 text (byte {error.start})') from None


def parse(text: str, source: str) -> Any:
    """The document of ``text`` as dicts, lists and rcl-typed scalars (ValueError: one line).

    Mapping keys stay the text written; an empty plain value is refused, as rcl
    refuses it. ``source`` names the file in errors.
    """
    import yaml
    if len(text.encode('utf-8', errors='replace')) > PARAMS_FILE_MAX_BYTES:
        raise ValueError(f'{source}: more than the limit of {PARAMS_FILE_MAX_BYTES} bytes '
                         'for a params file')
    loader = getattr(yaml, 'CSafeLoader', yaml.SafeLoader)   # libyaml's parser where present
    stack: list[Any] = []          # open containers: dicts and lists
    keys: list[Any] = []           # per open dict: the key waiting for its value (or None)
    documents: list[Any] = []

    def where(event: Any) -> str:
        mark = getattr(event, 'start_mark', None)
        return f'{source}: line {mark.line + 1}' if mark is not None else source

    def add(value: Any, event: Any) -> None:
        if not stack:
            documents.append(value)
            return
        top = stack[-1]
        if isinstance(top, list):
            top.append(value)
        elif keys[-1] is None:
            keys[-1] = (value,)
        else:
            top[keys[-1][0]] = value
            keys[-1] = None

    try:
        for event in yaml.parse(text, Loader=loader):
            if isinstance(event, yaml.AliasEvent):
                raise ValueError(f'{where(event)}: YAML aliases are not read (as in rcl)')
            tag = getattr(event, 'tag', None)
            if tag is not None and tag != STR_TAG and not isinstance(
                    event, (yaml.MappingEndEvent, yaml.SequenceEndEvent)):
                raise ValueError(f'{where(event)}: YAML tag {tag[:40]!r} is not read '
                                 '(only !!str, as in rcl)')
            if isinstance(event, yaml.ScalarEvent):
                key_position = bool(stack) and isinstance(stack[-1], dict) and keys[-1] is None
                quoted = event.style in ("'", '"') or tag == STR_TAG
                if key_position:
                    add(event.value, event)
                    continue
                if event.value == '' and not quoted:
                    raise ValueError(f'{where(event)}: no value (write one, or "" or [])')
                add(scalar_value(event.value, quoted), event)
            elif isinstance(event, (yaml.MappingStartEvent, yaml.SequenceStartEvent)):
                if len(stack) >= PARAMS_FILE_MAX_DEPTH:
                    raise ValueError(f'{where(event)}: nested deeper than '
                                     f'{PARAMS_FILE_MAX_DEPTH} levels')
                if stack and isinstance(stack[-1], dict) and keys[-1] is None:
                    raise ValueError(f'{where(event)}: a mapping key must be a plain name')
                container: Any = {} if isinstance(event, yaml.MappingStartEvent) else []
                stack.append(container)
                keys.append(None)
            elif isinstance(event, (yaml.MappingEndEvent, yaml.SequenceEndEvent)):
                done = stack.pop()
                keys.pop()
                add(done, event)
    except yaml.YAMLError as error:
        mark = getattr(error, 'problem_mark', None)
        line = f' line {mark.line + 1}' if mark is not None else ''
        raise ValueError(f'{source}:{line} not valid YAML '
                         f'({getattr(error, "problem", None) or error})') from None
    if len(documents) > 1:
        raise ValueError(f'{source}: more than one YAML document')
    return documents[0] if documents else None


def plain_document(text: str, source: str) -> Any:
    """YAML 1.1 ``safe_load`` of an untrusted document (a bag's metadata.yaml), bounded as a
    params file is: no aliases, at most ``PARAMS_FILE_MAX_BYTES`` (ValueError: one line)."""
    import yaml
    if len(text) > PARAMS_FILE_MAX_BYTES:
        raise ValueError(f'{source}: more than the limit of {PARAMS_FILE_MAX_BYTES} bytes')
    loader = getattr(yaml, 'CSafeLoader', yaml.SafeLoader)
    try:
        for event in yaml.parse(text, Loader=loader):
            if isinstance(event, yaml.AliasEvent):
                raise ValueError(f'{source}: line {event.start_mark.line + 1}: YAML aliases '
                                 'are not read')
        return yaml.load(text, Loader=loader)
    except yaml.YAMLError as error:
        raise ValueError(f'{source}: not valid YAML ({error})'.splitlines()[0]) from None

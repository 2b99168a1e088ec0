"""The `ptrace view` socket's messages, checked before anything acts on them.

A page's text is parsed only when it is short and shallow (so no message can make the parser
recurse or allocate much), every number must be finite and within the range of a 64-bit
integer, and every message must be an object of a known type whose fields are known and of
their kind. parse() (a socket's text) and check() (a dict, from any caller) return such a
message or raise MessageError (a PtraceError): the socket answers it with an error reply and the
session goes on unchanged. Ranges that depend on the
session (a pixel inside the image, the samples a kernel call may take) are checked where the
message is acted on (ptrace.app.view_session, ptrace.app.view_render).
"""
import json
import math
import numbers

import numpy as np

from ..errors import PtraceError

MAX_CHARS = 4096        # the page's messages are under 200 characters
MAX_DEPTH = 1           # every message is one flat object of numbers, strings and booleans
MAX_INTEGER = 2 ** 63 - 1

INTEGER, NUMBER, BOOLEAN, TEXT = "an integer", "a finite number", "true or false", "a string"
FIELDS = {              # type: {field: kind}
    "probe": {"x": INTEGER, "y": INTEGER},
    "save": {},
    "camera": {"op": TEXT, "dx": NUMBER, "dy": NUMBER, "factor": NUMBER, "moving": BOOLEAN,
               "id": INTEGER},
    "settings": {"spp": INTEGER, "max_depth": INTEGER, "light_samples": INTEGER,
                 "estimator": TEXT, "accel": TEXT, "mode": TEXT, "denoise": BOOLEAN},
    "cell": {"x": INTEGER, "y": INTEGER, "dx": INTEGER, "dy": INTEGER},
    "pause": {"paused": BOOLEAN},
    "exposure": {"stops": NUMBER},
}
REQUIRED = {"probe": ("x", "y"), "camera": ("op",), "cell": ("x", "y", "dx", "dy"),
            "pause": ("paused",), "exposure": ("stops",)}
CAMERA_OPS = {"orbit": ("dx", "dy"), "pan": ("dx", "dy"), "zoom": ("factor",), "still": ()}


class MessageError(PtraceError):
    """A page's message that is refused (the reply says why; nothing changed)."""


def _depth(text):
    """The deepest nesting of arrays and objects in JSON text (brackets inside strings do not
    count); a linear scan, so it cannot recurse however deep the text nests."""
    depth = deepest = 0
    in_string = escaped = False
    for character in text:
        if in_string:
            if escaped:
                escaped = False
            elif character == "\\":
                escaped = True
            elif character == '"':
                in_string = False
        elif character == '"':
            in_string = True
        elif character in "[{":
            depth += 1
            deepest = max(deepest, depth)
        elif character in "]}":
            depth -= 1
    return deepest


def _constant(name):
    raise MessageError(f"bad message: {name} is not a number here (numbers must be finite)")


def _float(text):
    value = float(text)
    if not math.isfinite(value):
        raise MessageError(f"bad message: {text} is not a finite number")
    return value


def _int(text):
    if len(text) > 20 or abs(int(text)) > MAX_INTEGER:
        raise MessageError(f"bad message: the integer {text[:24]}{'...' if len(text) > 24 else ''}"
                           f" is beyond 2^63 - 1")
    return int(text)


def _kind_of(value, kind):
    if kind == BOOLEAN:
        return isinstance(value, (bool, np.bool_))
    if isinstance(value, (bool, np.bool_)):
        return False
    if kind == TEXT:
        return isinstance(value, str) and len(value) <= 64
    if isinstance(value, numbers.Integral):
        return abs(int(value)) <= MAX_INTEGER
    if not isinstance(value, numbers.Real) or not math.isfinite(value):
        return False
    return kind == NUMBER or float(value).is_integer() and abs(value) <= MAX_INTEGER


def parse(text):
    """The message of a socket's text (check()'s), or MessageError saying what is wrong."""
    if not isinstance(text, str):
        raise MessageError("bad message: messages are JSON text, not binary")
    if len(text) > MAX_CHARS:
        raise MessageError(f"bad message: {len(text)} characters, more than {MAX_CHARS}")
    if (text.count("[") + text.count("{") > MAX_DEPTH) and _depth(text) > MAX_DEPTH:
        raise MessageError(f"bad message: nested more than {MAX_DEPTH} deep")
    try:
        message = json.loads(text, parse_constant=_constant, parse_float=_float,
                             parse_int=_int)
    except ValueError as error:     # json.JSONDecodeError is one
        raise MessageError(f"bad message: not JSON ({error})") from None
    return check(message)


def check(message):
    """The message itself, its integer fields as int, if it is a dict whose "type" is known and
    whose fields are known and of their kind (numbers finite, integers within 2^63 - 1), with
    the fields its type needs; else MessageError saying what is wrong."""
    if not isinstance(message, dict):
        raise MessageError("bad message: not a JSON object")
    kind = message.get("type")
    if not isinstance(kind, str) or kind not in FIELDS:
        raise MessageError(f"unknown message type {str(kind)[:64]!r}")
    fields = FIELDS[kind]
    checked = {"type": kind}
    for name, value in message.items():
        if name == "type":
            continue
        if name not in fields:
            raise MessageError(f"bad {kind} message: unknown field {str(name)[:64]!r}")
        if not _kind_of(value, fields[name]):
            raise MessageError(f"bad {kind} message: {name} must be {fields[name]}")
        checked[name] = int(value) if fields[name] == INTEGER else \
            float(value) if fields[name] == NUMBER else \
            bool(value) if fields[name] == BOOLEAN else value
    required = REQUIRED.get(kind, ())
    if kind == "camera" and "op" in checked:
        if checked["op"] not in CAMERA_OPS:
            raise MessageError(f"unknown camera operation {checked['op']!r}")
        required = required + CAMERA_OPS[checked["op"]]
    missing = [name for name in required if name not in checked]
    if missing:
        raise MessageError(f"bad {kind} message: {', '.join(missing)} missing")
    return checked

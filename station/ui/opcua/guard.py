"""What a Call must be before it reaches the station, and what the server may write to its log.

asyncua's method service hands a callback the request's ObjectId and arguments as they came
(address_space.MethodService._call): a method called on another object runs (StartRecheck on
the ResultManagement object started a run), extra arguments raise a TypeError that asyncua logs
with the whole request and answers BadUnexpectedError, and argument types are not checked. Every
station method is linked through :func:`guarded`, which answers first with the status codes OPC
10000-4 §5.11.2.4 lists for Call:

* Bad_MethodInvalid: the method is not a method of the object called (only where the companion
  specification puts it: the station's six on CalibrationStation, the Machinery Result ones on
  its ResultManagement, OPC 40001-101 §8.3);
* Bad_ArgumentsMissing / Bad_TooManyArguments: fewer / more arguments than the method declares;
* Bad_InvalidArgument with, per argument, Bad_TypeMismatch (not the declared DataType) or
  Bad_OutOfRange (a string longer than :data:`MAX_STRING`): the request is never logged.

:class:`BoundedLog` caps every log record's length and how many records a logger may write per
minute, so that no client can fill the station's disk through the server's log.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Awaitable, Callable, Collection
from dataclasses import dataclass, field
from typing import Any

from asyncua import ua

#: the longest string argument a station method takes (a ResultId "run-N" is 24 characters at most)
MAX_STRING = 256


@dataclass(frozen=True)
class Signature:
    """A method's declared input arguments (their VariantTypes, in order) and the objects it may
    be called on."""

    objects: frozenset[ua.NodeId]
    inputs: tuple[ua.VariantType, ...] = ()


def _code(code: int) -> ua.StatusCode:
    return ua.StatusCode(ua.UInt32(code))


def check_call(sig: Signature, parent: ua.NodeId, args: tuple[Any, ...]) -> ua.CallMethodResult | None:
    """None when the call is well formed; else the CallMethodResult to answer with."""
    res = ua.CallMethodResult()
    if parent not in sig.objects:
        res.StatusCode = _code(ua.StatusCodes.BadMethodInvalid)
        return res
    if len(args) < len(sig.inputs):
        res.StatusCode = _code(ua.StatusCodes.BadArgumentsMissing)
        return res
    if len(args) > len(sig.inputs):
        res.StatusCode = _code(ua.StatusCodes.BadTooManyArguments)
        return res
    results = [_argument(want, arg) for want, arg in zip(sig.inputs, args)]
    if any(r != ua.StatusCodes.Good for r in results):
        res.StatusCode = _code(ua.StatusCodes.BadInvalidArgument)
        res.InputArgumentResults = [_code(r) for r in results]
        return res
    return None


def _argument(want: ua.VariantType, arg: Any) -> int:
    if not isinstance(arg, ua.Variant) or arg.VariantType != want or arg.is_array:
        return ua.StatusCodes.BadTypeMismatch
    if want in (ua.VariantType.String, ua.VariantType.ByteString) and arg.Value is not None \
            and len(arg.Value) > MAX_STRING:
        return ua.StatusCodes.BadOutOfRange
    return ua.StatusCodes.Good


def guarded(handler: Callable[..., Awaitable[Any]], sig: Signature) -> Callable[..., Awaitable[Any]]:
    """``handler`` behind :func:`check_call`: it runs only for a well-formed call."""

    async def call(parent: ua.NodeId, *args: Any) -> Any:
        refused = check_call(sig, parent, args)
        return refused if refused is not None else await handler(parent, *args)

    call.__name__ = getattr(handler, "__name__", "call")
    return call


def signatures(station: ua.NodeId, results: ua.NodeId, operator_methods: Collection[str]) -> dict[str, Signature]:
    """Per method name: where it may be called and what it takes (Station.NodeSet2.xml; OPC
    40001-101 §8.3.2 GetLatestResult(Timeout Int32), §8.3.3 GetResultById(ResultId String,
    Timeout Int32))."""
    out = {name: Signature(frozenset({station})) for name in operator_methods}
    out["GetLatestResult"] = Signature(frozenset({results}), (ua.VariantType.Int32,))
    out["GetResultById"] = Signature(frozenset({results}), (ua.VariantType.String, ua.VariantType.Int32))
    return out


@dataclass
class BoundedLog(logging.Filter):
    """A handler's filter: each record at most ``max_chars`` (its message and its traceback), and
    at most ``per_minute`` records per logger per minute; the next record after a quiet spell
    says how many were left out. ``clock``: seconds (monotonic; a test's simulated clock)."""

    max_chars: int = 2000
    per_minute: int = 30
    clock: Callable[[], float] = time.monotonic
    _windows: dict[str, tuple[float, int, int]] = field(default_factory=dict)  # logger -> (start, kept, dropped)

    def filter(self, record: logging.LogRecord) -> bool:
        now = self.clock()
        start, kept, dropped = self._windows.get(record.name, (now, 0, 0))
        if now - start >= 60.0:
            start, kept = now, 0
        if kept >= self.per_minute:
            self._windows[record.name] = (start, kept, dropped + 1)
            return False
        self._windows[record.name] = (start, kept + 1, 0)
        text = record.getMessage()
        if record.exc_info:  # the traceback stays, within the same bound (its text may hold the request)
            text += "\n" + logging.Formatter().formatException(record.exc_info)
            record.exc_info, record.exc_text = None, None
        if len(text) > self.max_chars:
            text = text[:self.max_chars] + f"… [{len(text) - self.max_chars} characters left out]"
        if dropped:
            text += f" [{dropped} earlier records of {record.name} left out: more than {self.per_minute} a minute]"
        record.msg, record.args = text, None
        return True


def bound_logging(filt: BoundedLog | None = None) -> BoundedLog:
    """Install :class:`BoundedLog` on every handler the server's records reach (the root logger's,
    or Python's last-resort handler when none is configured)."""
    filt = filt or BoundedLog()
    root = logging.getLogger()
    for handler in root.handlers or [h for h in (logging.lastResort,) if h is not None]:
        if filt not in handler.filters:
            handler.addFilter(filt)
    return filt

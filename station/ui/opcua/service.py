"""The station behind the address space: one cell, one run at a time, the same sessions as the
terminal.

A start method runs ``run_calibration_session`` / ``run_recheck_session`` (exactly what
``station calibrate`` / ``station recheck`` and the TUI run: the run database's run lock, the
pre-motion checks, the same runner) in a worker thread. The session's events come back into the
server's event loop through ``loop.call_soon_threadsafe`` onto a queue; one task writes them into
the address space in order. The run's thread never waits on the server: a slow or dead client
cannot hold the robot.

State (``CalibrationStation/State``): ``Idle`` → (Start…) ``Running`` (``Paused`` while the
runner stands at a paused safe point) → the outcome's name (``SUCCESS``, ``DRIFTED``, …) with a
ResultReady event → (Acknowledge) ``Idle``. A start is refused unless the state is ``Idle``.

The service subscribes to the session's stream of run facts (issue 42,
:class:`~station.cell.run.facts.stream.RunStream`): the axes' identified offsets come from the
``Identified`` event, the active table's CRC from ``Uploaded`` and the run's end, and
LastCalibration from the ``RunEnded`` event's summary, the figures the run stores and the CLI's
JSON prints. The run database is read only for what happened before this server started (and
for LastRecheck, whose drift figures the recheck does not stream yet).
"""

from __future__ import annotations

import asyncio
import datetime as dt
import json
import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from asyncua import Server, ua

from station.cell.pipeline.outcomes import failure_summary
from station.cell.recheck.measure import RecheckOptions
from station.cell.recheck.session import run_recheck_session
from station.cell.records.certificates import stored_certificate
from station.cell.records.reading.run_list import RunInfo, list_runs
from station.cell.records.rundb import RunDB
from station.cell.records.summary import RunSummary
from station.cell.run.facts.events import (
    Event,
    Identified,
    Notice,
    Paused,
    PhaseChanged,
    Progress,
    Resumed,
    RunEnded,
    RunStarted,
    StepStarted,
    Uploaded,
)
from station.cell.run.facts.stream import RunStream
from station.cell.run.runcontrol import RunControl
from station.cell.session.calibrate import CellLoader, CellRequest, run_calibration_session
from station.errors import Outcome
from station.ui.opcua.guard import guarded, signatures
from station.ui.opcua.model import OffsetParameter, StationNodes, identified_offsets, status

log = logging.getLogger(__name__)
#: asyncua's ua module as the place of the classes it makes from the loaded models (not in its stubs)
_UA: Any = ua

ACTIVE = ("Running", "Paused")
#: ResultEvaluationEnum of OPC 40001-101 §10.3: Undefined 0, OK 1, NotOK 2, NotDecidable 3
_EVALUATION = {Outcome.SUCCESS: 1, Outcome.DRIFTED: 2, Outcome.TARGET_MISSED: 2, Outcome.RECHECK_UNTRUSTED: 3,
               Outcome.NOT_UPLOADED: 3}


@dataclass(frozen=True)
class _Done:
    """The worker's last word: the session's summary as its ``--json`` object."""

    kind: str
    summary: dict[str, Any]


def _utc(text: str | None) -> dt.datetime:
    if not text:
        return dt.datetime(1601, 1, 1, tzinfo=dt.timezone.utc)
    return dt.datetime.fromisoformat(text.replace("Z", "+00:00"))


def _float(v: Any) -> float:
    return float(v) if isinstance(v, (int, float)) else float("nan")


class StationService:
    """The methods, the state and the results of one cell's station. ``load``: the cell loader the
    sessions get (``station.ui.simulated_cell.load_cell`` composes simulated cells)."""

    def __init__(self, server: Server, nodes: StationNodes, request: CellRequest, load: CellLoader,
                 offset_parameters: list[OffsetParameter | None]) -> None:
        self.server, self.nodes, self.request, self.load = server, nodes, request, load
        #: per axis: its offset parameter (index, name, nominal, display scale) or None
        self.offset_parameters = offset_parameters
        self.state = "Idle"
        self.run_id = 0
        self.kind = ""
        self.control: RunControl | None = None
        self.thread: threading.Thread | None = None
        self.results: dict[str, Any] = {}  # ResultId -> ResultDataType, the runs of this process
        self.latest_result: str | None = None
        self._queue: asyncio.Queue[Event | _Done] = asyncio.Queue()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._pump: asyncio.Task[None] | None = None
        #: this attempt's progress as the run counts it (Progress: k of n touches in the order made,
        #: station/cell/run/facts/progress.py), not the plan index: the body's locating touches come first
        #: and out of the plan's order (issue 37); the monotonic time of the attempt's first step and
        #: the count then, for the time left
        self._done = self._total = 0
        self._t0: float | None = None
        self._done_at_t0 = 0
        self._event: Any = None
        self._vtypes: dict[ua.NodeId, ua.VariantType] = {}
        #: the run's facts: the session emits into it, the address space follows it (a test or another
        #: view may subscribe beside)
        self.stream = RunStream(self._post)
        self._started_utc = _utc(None)  # when the active run was created (its RunStarted)
        self._ended = False  # the active run's RunEnded was applied

    # --- set-up -----------------------------------------------------------------------------
    async def start(self) -> None:
        self._loop = asyncio.get_running_loop()
        handlers: dict[str, Callable[..., Any]] = {
            "StartCalibration": self._start_calibration, "StartRecheck": self._start_recheck,
            "Abort": self._abort, "Acknowledge": self._acknowledge, "Pause": self._pause, "Resume": self._resume}
        handlers.update(GetLatestResult=self._get_latest, GetResultById=self._get_by_id)
        sigs = signatures(self.nodes.station.nodeid, self.nodes.result_management.nodeid, self.nodes.methods)
        for name, nodes in [*self.nodes.methods.items(), *self.nodes.result_methods.items()]:
            for node in nodes:  # each behind its argument and object checks (guard.py)
                self.server.link_method(node, guarded(handlers[name], sigs[name]))
        self._event = await self.server.get_event_generator(self.nodes.event_type.nodeid, self.nodes.station.nodeid)
        await self._write_state(State="Idle", OutcomeCode=-1, RunKind="", RunId=0, Phase="", Step=0, StepCount=0,
                                TimeLeftSeconds=0.0, LastRefusal="", Message="")
        await self._refresh_records()
        self._pump = asyncio.create_task(self._consume(), name="station-events")

    async def stop(self) -> None:
        """Abort a run at its next safe point and wait for its thread (the devices close there)."""
        if self.control is not None:
            self.control.abort()
        if self.thread is not None:
            await asyncio.get_running_loop().run_in_executor(None, self.thread.join, 60.0)
        if self._pump is not None:
            self._pump.cancel()
            # awaited: a write it was making ends here, not while the caller stops the server under it
            await asyncio.wait([self._pump])  # (wait, not await: the pump's CancelledError is not the caller's)

    @property
    def operator_methods(self) -> set[ua.NodeId]:
        return {n.nodeid for nodes in self.nodes.methods.values() for n in nodes}

    # --- methods (the role was checked before the call reached here: security.StationRuleset) ---
    async def _refuse(self, code: int, reason: str) -> ua.StatusCode:
        log.info("method call refused: %s", reason)
        await self._write_state(LastRefusal=reason)
        return status(code)

    async def _start_calibration(self, parent: ua.NodeId) -> ua.StatusCode:
        return await self._start("calibration")

    async def _start_recheck(self, parent: ua.NodeId) -> ua.StatusCode:
        return await self._start("recheck")

    async def _start(self, kind: str) -> ua.StatusCode:
        if self.state in ACTIVE:
            return await self._refuse(ua.StatusCodes.BadInvalidState,
                                      f"{kind} refused: {self.kind} run {self.run_id or '(starting)'} is active; wait for "
                                      f"its ResultReady event, or call Abort")
        if self.state != "Idle":
            return await self._refuse(ua.StatusCodes.BadInvalidState,
                                      f"{kind} refused: the outcome {self.state} of {self.kind} run {self.run_id} is not "
                                      f"acknowledged yet; read it, then call Acknowledge")
        self.state, self.kind, self.run_id, self._ended = "Running", kind, 0, False
        self._done, self._total, self._t0 = 0, 0, None
        self.control = RunControl()
        await self._write_state(State="Running", OutcomeCode=-1, RunKind=kind, RunId=0, Phase="connect", Step=0,
                                StepCount=0, TimeLeftSeconds=float("nan"), LastRefusal="", Message="")
        self.thread = threading.Thread(target=self._work, args=(kind, self.control), name=f"station-{kind}", daemon=True)
        self.thread.start()
        return status(ua.StatusCodes.Good)

    async def _abort(self, parent: ua.NodeId) -> ua.StatusCode:
        if self.state not in ACTIVE or self.control is None:
            return await self._refuse(ua.StatusCodes.BadInvalidState, "abort refused: no run is active")
        self.control.abort()  # the runner stops at its next safe point; the outcome is ABORTED
        return status(ua.StatusCodes.Good)

    async def _pause(self, parent: ua.NodeId) -> ua.StatusCode:
        if self.state != "Running" or self.control is None:
            return await self._refuse(ua.StatusCodes.BadInvalidState, "pause refused: no run is running")
        self.control.pause()  # the runner stops at its next safe point: State Paused then
        return status(ua.StatusCodes.Good)

    async def _resume(self, parent: ua.NodeId) -> ua.StatusCode:
        if self.state not in ACTIVE or self.control is None or not self.control.paused:
            return await self._refuse(ua.StatusCodes.BadInvalidState, "resume refused: no run is paused")
        self.control.resume()
        return status(ua.StatusCodes.Good)

    async def _acknowledge(self, parent: ua.NodeId) -> ua.StatusCode:
        if self.state in ACTIVE:
            return await self._refuse(ua.StatusCodes.BadInvalidState,
                                      f"acknowledge refused: {self.kind} run {self.run_id} is still active")
        self.state = "Idle"
        await self._write_state(State="Idle", OutcomeCode=-1, Phase="", Step=0, StepCount=0, TimeLeftSeconds=0.0)
        return status(ua.StatusCodes.Good)

    async def _get_latest(self, parent: ua.NodeId, timeout: Any = None) -> list[ua.Variant] | ua.StatusCode:
        if self.latest_result is None:  # none since the server started: the run database's latest
            cal, rec, _, _ = await asyncio.get_running_loop().run_in_executor(None, self._read_records)
            ids = [r.id for r in (cal, rec) if r is not None]
            if not ids:
                return status(ua.StatusCodes.BadNoData)
            return await self._get_by_id(parent, f"run-{max(ids)}")
        return self._result_outputs(await self._with_certificate(self.latest_result))

    async def _get_by_id(self, parent: ua.NodeId, result_id: Any = None, timeout: Any = None) -> list[ua.Variant] | ua.StatusCode:
        rid = str(getattr(result_id, "Value", result_id) or "")
        if rid not in self.results:
            found = await asyncio.get_running_loop().run_in_executor(None, self._stored_result, rid)
            if found is None:
                return status(ua.StatusCodes.BadNotFound)
            self.results[rid] = found
        return self._result_outputs(await self._with_certificate(rid))

    async def _with_certificate(self, rid: str) -> Any:
        """The result ``rid`` with its Digital Calibration Certificate, when 'station export-dcc' wrote
        one for the run: ResultContent[1], a ByteString holding the file's bytes (issue 41; OPC
        40001-101 §6.3 and §10.5: ResultContent is the result's data, BaseDataType[]). Read at each
        call: a certificate is written after the run, often after its ResultReady."""
        result = self.results[rid]
        if not rid.startswith("run-") or not rid[4:].isdigit():
            return result
        cert = await asyncio.get_running_loop().run_in_executor(None, stored_certificate, self.request.db, int(rid[4:]))
        if cert is None:
            return result
        content = list(result.ResultContent or [])[:1] + [ua.Variant(cert.xml, ua.VariantType.ByteString)]
        return _UA.ResultDataType(ResultMetaData=result.ResultMetaData, ResultContent=content)

    @staticmethod
    def _result_outputs(result: Any) -> list[ua.Variant]:
        # GetLatestResult / GetResultById (OPC 40001-101 §8.3): ResultHandle (no handles are held:
        # 0), Result, Error (0: none)
        return [ua.Variant(0, ua.VariantType.UInt32), ua.Variant(result, ua.VariantType.ExtensionObject),
                ua.Variant(0, ua.VariantType.Int32)]

    # --- the run, in its own thread ---------------------------------------------------------------
    def _post(self, event: Event) -> None:
        """The stream's subscriber: from the run's thread into the server's loop, never blocking."""
        loop = self._loop
        assert loop is not None, "the service's loop starts before any run"
        loop.call_soon_threadsafe(self._queue.put_nowait, event)

    def _work(self, kind: str, control: RunControl) -> None:
        loop = self._loop
        assert loop is not None
        try:
            if kind == "calibration":
                summary: Any = run_calibration_session(self.request, self.stream, control, None, load=self.load)
            else:
                summary = run_recheck_session(self.request, self.stream, control, RecheckOptions(), load=self.load)
            out = summary.to_json()
        except Exception as exc:  # noqa: BLE001 - the sessions return failures; a bug still ends the run visibly
            out = failure_summary(exc, run_id=self.run_id or None, log_dir=Path(self.request.db).resolve().parent,
                                  db=self.request.db).to_json()
        loop.call_soon_threadsafe(self._queue.put_nowait, _Done(kind, out))

    async def _consume(self) -> None:
        while True:
            item = await self._queue.get()
            try:
                if isinstance(item, _Done):
                    await self._finished(item)
                else:
                    await self._apply(item)
            except Exception:  # a failed write must not stop the pump: log it, go on
                log.exception("could not publish %r", item)

    async def _apply(self, ev: Event) -> None:
        if isinstance(ev, RunStarted):
            self.run_id, self.kind = ev.run_id, ev.kind  # the stream names the run (the start method did too)
            self._started_utc = dt.datetime.now(dt.timezone.utc)
            self._done, self._total, self._t0 = ev.resumed_from, ev.n_steps, None
            await self._write_state(RunId=ev.run_id, StepCount=ev.n_steps, RunKind=ev.kind)
        elif isinstance(ev, Progress):  # n grows with the search's and the warm-up's touches
            self._done, self._total = ev.done, ev.total
            await self._write_state(StepCount=ev.total)
        elif isinstance(ev, Identified):
            await self._write_offsets({"params": list(ev.params),
                                       "chosen": [p.name for p in ev.identification.parameters]})
        elif isinstance(ev, Uploaded):  # the station's table, read back active on the controller
            await self._write_state(ActiveTableCrc=ev.active_crc32)
        elif isinstance(ev, RunEnded):
            await self._run_ended(ev.summary)
        elif isinstance(ev, PhaseChanged):
            await self._write_state(Phase=ev.phase)
        elif isinstance(ev, StepStarted):
            now = time.monotonic()
            if self._t0 is None:
                self._t0, self._done_at_t0 = now, self._done
            k = min(self._done + 1, self._total)  # the touch under way: k − 1 are done
            done = self._done - self._done_at_t0  # touches this attempt finished since its first step
            left = (now - self._t0) / done * (self._total - k + 1) if done > 0 else float("nan")
            await self._write_state(Step=k, StepCount=self._total, TimeLeftSeconds=left)
        elif isinstance(ev, Paused):
            self.state = "Paused"
            await self._write_state(State="Paused")
        elif isinstance(ev, Resumed):
            self.state = "Running"
            await self._write_state(State="Running")
        elif isinstance(ev, Notice):
            await self._write_state(Message=ev.message[:500])

    async def _run_ended(self, summary: RunSummary) -> None:
        """A calibration's end, from its ``RunEnded`` event: LastCalibration and the table left
        active, as the run's summary states them (a run that never started has no record)."""
        if self.kind != "calibration" or summary.run_id is None:
            return
        self._ended = True
        # RunId last, in each record: the values are written one by one, and a client that sees a
        # new RunId (its subscription, its poll) must read that run's figures, not the last run's
        await self._write(self.nodes.last_calibration, Outcome=summary.outcome.name,
                          ExitCode=summary.exit_code, FinishedUtc=self._started_utc,
                          RmsBeforeMicrometre=_float(summary.before.rms_um if summary.before else None),
                          RmsAfterMicrometre=_float(summary.after.rms_um if summary.after else None),
                          Gain=_float(summary.gain),
                          InterpolationBoundMicrometre=_float(summary.correction.interpolation_bound_um
                                                              if summary.correction else None),
                          RunId=summary.run_id)
        if summary.tables is not None:
            await self._write_state(ActiveTableCrc=summary.tables.active_at_end)

    async def _finished(self, done: _Done) -> None:
        s = done.summary
        self.thread = None
        self.control = None
        outcome = Outcome[s.get("outcome", "INTERNAL_ERROR")]
        self.run_id = int(s.get("run_id") or 0)
        self.state = outcome.name
        # Message: this run's end (an abort included), never a notice left from before it
        failure: dict[str, Any] = s["failure"] if isinstance(s.get("failure"), dict) else {}
        message = f"{done.kind} run {self.run_id}: {outcome.name} (exit code {int(outcome)})"
        if failure.get("message"):
            message += f": {failure['message']}"
        await self._write_state(State=outcome.name, OutcomeCode=int(outcome), RunId=self.run_id, TimeLeftSeconds=0.0,
                                Phase="done", Message=message[:500])
        if done.kind == "calibration" and not self._ended:  # a bug ended it before its RunEnded
            await self._run_ended(RunSummary.from_json(s))
        try:  # the records first, so that a client reading them on ResultReady reads this run's
            if done.kind == "recheck":  # its drift figures are not streamed yet: read from the run database
                await self._refresh_records(calibration=False)
        except Exception:  # a damaged run database must not swallow the ResultReady
            log.exception("run %s: LastRecheck not updated", self.run_id)
        result = self._result(s, done.kind, dt.datetime.now(dt.timezone.utc))
        rid = result.ResultMetaData.ResultId
        self.results[rid] = result
        self.latest_result = rid
        await self._fire_result_ready(result, outcome, done.kind)

    async def _fire_result_ready(self, result: Any, outcome: Outcome, kind: str) -> None:
        assert self._event is not None
        ev = self._event.event
        # each field with its type: the generator takes a field's type from the type's initial value
        ev.add_property("Result", result, ua.VariantType.ExtensionObject)
        ev.add_property("Verdict", outcome.name, ua.VariantType.String)
        ev.add_property("ExitCode", int(outcome), ua.VariantType.Int32)
        ev.add_property("RunId", self.run_id, ua.VariantType.Int64)
        ev.add_property("RunKind", kind, ua.VariantType.String)
        ev.Severity = 100 if outcome is Outcome.SUCCESS else 500
        await self._event.trigger(message=f"{kind} run {self.run_id}: {outcome.name} (exit code {int(outcome)})")

    # --- results ------------------------------------------------------------------------------------
    def _result(self, summary: dict[str, Any], kind: str, when: dt.datetime) -> Any:
        """The run's summary as OPC 40001-101's ResultDataType: its metadata (id, evaluation, the
        exit code) and, as content, the run's ``--json`` object (the CLI's, with its units)."""
        outcome = Outcome[summary.get("outcome", "INTERNAL_ERROR")]
        run_id = summary.get("run_id")
        # the Machinery Result structures: classes asyncua made from the loaded model, not in its stubs
        meta = _UA.ResultMetaDataType(
            ResultId=f"run-{run_id}" if run_id is not None else f"failed-{when:%Y%m%dT%H%M%S%f}",
            IsSimulated=self.request.simulated, IsPartial=False, CreationTime=when,
            ResultEvaluation=_UA.ResultEvaluationEnum(_EVALUATION.get(outcome, 0)),
            ResultEvaluationCode=int(outcome), StepId=kind)
        return _UA.ResultDataType(ResultMetaData=meta,
                                  ResultContent=[ua.Variant(json.dumps(summary), ua.VariantType.String)])

    def _stored_result(self, rid: str) -> Any:
        """A result of an earlier run, from the run database (``run-N``)."""
        if not rid.startswith("run-") or not rid[4:].isdigit() or not Path(self.request.db).exists():
            return None
        with RunDB(self.request.db) as db:
            try:
                summary = db.load_result(int(rid[4:]), "summary")
                created = db.run(int(rid[4:])).created_utc
            except Exception:  # noqa: BLE001 - no such run, or one without a summary: not found
                return None
        return self._result(summary, str(summary.get("kind", "calibration")), _utc(created))

    async def _refresh_records(self, calibration: bool = True) -> None:
        """LastCalibration, LastRecheck, the axes' identified offsets and the active table's CRC,
        from the run database (read in a worker thread: the loop keeps serving); ``calibration``
        False: LastRecheck alone (a calibration of this server streamed its figures)."""
        records = await asyncio.get_running_loop().run_in_executor(None, self._read_records)
        cal, rec, params, crc = records
        if cal is not None and calibration:
            bound = await asyncio.get_running_loop().run_in_executor(None, self._stored_bound, cal.id)
            await self._write(self.nodes.last_calibration, Outcome=cal.outcome or "", ExitCode=_exit(cal),
                              FinishedUtc=_utc(cal.created_utc), RmsBeforeMicrometre=_float(cal.rms_before_um),
                              RmsAfterMicrometre=_float(cal.rms_after_um), Gain=_float(cal.gain),
                              InterpolationBoundMicrometre=bound, RunId=cal.id)  # RunId last (_run_ended)
        if rec is not None:
            await self._write(self.nodes.last_recheck, Outcome=rec.outcome or "", ExitCode=_exit(rec),
                              FinishedUtc=_utc(rec.created_utc), Verdict=rec.outcome or "",
                              BaselineRunId=int(rec.baseline or 0), DriftRmsMicrometre=_float(rec.drift_rms_um),
                              DriftMaxMicrometre=_float(rec.drift_max_um),
                              ToleranceMicrometre=_float(rec.drift_tolerance_um), RunId=rec.id)
        if calibration:
            await self._write_offsets(params)
            await self._write_state(ActiveTableCrc=crc)

    async def _write_offsets(self, identification: dict[str, Any] | None) -> None:
        """Each axis's identified zero offset (degrees or mm from the robot file's nominal; NaN
        where no calibration identified yet or its minimal set does not hold it: identified_offsets)."""
        for node, value in zip(self.nodes.axis_offsets, identified_offsets(identification, self.offset_parameters)):
            await node.write_value(ua.DataValue(ua.Variant(value, ua.VariantType.Double)))

    def _stored_bound(self, run_id: int) -> float:
        """The stored table bound of a run before this server [µm] (NaN: none, e.g. it stopped before)."""
        with RunDB(self.request.db) as db:
            try:
                return _float(db.load_result(run_id, "summary")["correction"]["interpolation_bound_um"])
            except Exception:  # noqa: BLE001 - no summary, or no table in it
                return float("nan")

    def _read_records(self) -> tuple[RunInfo | None, RunInfo | None, dict[str, Any] | None, str]:
        """The latest finished calibration and recheck (whatever their outcome), the identification
        (parameters and the chosen names) of the latest calibration that identified, and the table
        the latest calibration that knew it left active."""
        if not Path(self.request.db).exists():
            return None, None, None, "unknown"
        with RunDB(self.request.db) as db:
            runs = sorted((r for r in list_runs(db) if r.outcome is not None), key=lambda r: r.id, reverse=True)
            cals = [r for r in runs if r.kind == "calibration"]  # newest first
            rec = next((r for r in runs if r.kind == "recheck"), None)
            params, crc = None, "unknown"
            for r in cals:
                try:
                    ident = db.load_result(r.id, "identification")
                    params = {"params": np.asarray(ident["params"], dtype=float), "chosen": ident.get("chosen")}
                    break
                except Exception:  # noqa: BLE001 - a calibration that stopped before identifying
                    continue
            for r in cals:
                try:
                    table = db.load_result(r.id, "summary").get("tables") or {}
                except Exception:  # noqa: BLE001 - a run without a summary
                    continue
                if table.get("active_at_end"):
                    crc = str(table["active_at_end"])
                    break
        return (cals[0] if cals else None), rec, params, crc

    # --- writing ------------------------------------------------------------------------------------
    async def _write_state(self, **values: Any) -> None:
        await self._write(self.nodes.variables, **values)

    async def _write(self, nodes: dict[str, Any], **values: Any) -> None:
        for name, value in values.items():
            node = nodes[name]
            vtype = self._vtypes.get(node.nodeid)
            if vtype is None:
                vtype = self._vtypes[node.nodeid] = await node.read_data_type_as_variant_type()
            await self.server.write_attribute_value(node.nodeid, ua.DataValue(ua.Variant(value, vtype)))


def _exit(run: RunInfo) -> int:
    try:
        return int(Outcome[run.outcome or ""])
    except KeyError:
        return -1

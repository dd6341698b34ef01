"""The controller's Modbus TCP server, as UR's support page "Modbus Server" (16377) describes
it: the controller is a Modbus TCP server on port 502; several clients may connect at once; it
answers function codes 0x01 READ_COILS, 0x02 READ_DISCRETE_INPUTS, 0x03 READ_HOLDING_REGISTERS,
0x04 READ_INPUT_REGISTERS, 0x05 WRITE_SINGLE_COIL, 0x06 WRITE_SINGLE_REGISTER, 0x0F
WRITE_MULTIPLE_COILS and 0x10 WRITE_MULTIPLE_REGISTERS, and answers errors with exception codes
0x01 ILLEGAL_FUNCTION_CODE, 0x02 ILLEGAL_DATA_ACCESS ("if the request address is illegal") and
0x03 ILLEGAL_DATA_VALUE ("if the request data is invalid"). Registers 128..255 are the general
purpose registers, which a script reads with §17.38 ``read_port_register`` and writes with §17.70
``write_port_register``.

Modelled here: the general-purpose registers 128..255 (read by 0x03 and 0x04, written by 0x06 and
0x10). The controller's other registers (I/O, robot state) and its coils are not modelled: a
request for them is refused with 0x02, which the station never sends (it stays inside its
window, ``tests/test_real_devices.py``). Any other function code gets 0x01. pymodbus (the
project's Modbus library) frames the protocol and refuses malformed requests (a register count
beyond the protocol's limits) with 0x03 itself.
"""

from __future__ import annotations

import asyncio
import threading
from typing import cast

from pymodbus.constants import ExcCodes
from pymodbus.server import ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

from simulators.urscript.builtins import PortRegisters

__all__ = ["URModbusServer", "GENERAL_PURPOSE", "UR_FUNCTION_CODES"]

#: the general-purpose registers of the UR Modbus server
GENERAL_PURPOSE = range(128, 256)
#: the function codes the UR page lists
UR_FUNCTION_CODES = (0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x0F, 0x10)
_REGISTER_CODES = (0x03, 0x04, 0x06, 0x10)


class URModbusServer:
    """pymodbus TCP server on a background thread, serving :class:`PortRegisters`."""

    def __init__(self, ports: PortRegisters, host: str = "127.0.0.1", port: int = 0):
        self.ports = ports
        self.host, self._port_req = host, int(port)
        self.port = 0
        self.requests: list[tuple[int, int, int]] = []
        self._thread: threading.Thread | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stop: asyncio.Event | None = None
        self._ready = threading.Event()
        self.failure: BaseException | None = None

    async def _action(self, function_code: int, start_address: int, address: int, count: int,
                      registers: list[int], set_values) -> ExcCodes | None:
        self.requests.append((int(function_code), int(address), int(count)))
        if function_code not in UR_FUNCTION_CODES:
            return ExcCodes.ILLEGAL_FUNCTION
        if function_code not in _REGISTER_CODES:
            return ExcCodes.ILLEGAL_ADDRESS  # coils are not modelled
        if address < GENERAL_PURPOSE.start or address + count > GENERAL_PURPOSE.stop:
            return ExcCodes.ILLEGAL_ADDRESS
        if set_values:
            self.ports.set_words(address, [int(v) for v in set_values])
        else:
            off = address - start_address
            registers[off:off + count] = self.ports.words(address, count)
        return None

    def start(self, timeout: float = 10.0) -> "URModbusServer":
        self._thread = threading.Thread(target=self._run, name="ur-modbus", daemon=True)
        self._thread.start()
        if not self._ready.wait(timeout) or self.failure is not None:
            raise RuntimeError(f"the Modbus server did not start: {self.failure}")
        return self

    def _run(self) -> None:
        loop = asyncio.new_event_loop()
        self._loop = loop
        try:
            loop.run_until_complete(self._main())
        except BaseException as exc:  # noqa: BLE001 - reported through .failure
            self.failure = exc
        finally:
            self._ready.set()
            loop.close()

    async def _main(self) -> None:
        self._stop = asyncio.Event()
        block = SimData(GENERAL_PURPOSE.start, count=len(GENERAL_PURPOSE), values=0, datatype=DataType.REGISTERS)
        server = ModbusTcpServer(SimDevice(0, simdata=[block], action=self._action), address=(self.host, self._port_req))
        await server.serve_forever(background=True)
        listener = cast(asyncio.Server, server.transport)
        self.port = int(listener.sockets[0].getsockname()[1])
        self._ready.set()
        await self._stop.wait()
        await server.shutdown()

    def stop(self) -> None:
        if self._thread is None:
            return
        if self._loop is not None and self._stop is not None and self._thread.is_alive():
            self._loop.call_soon_threadsafe(self._stop.set)
        self._thread.join(10.0)
        self._thread = None

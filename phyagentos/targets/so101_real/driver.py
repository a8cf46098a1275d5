"""The SO-101's Feetech bus through the official SDK (``scservo_sdk``).

:class:`FeetechBus` opens the serial port (a real ``/dev/ttyACM0`` or the bus twin's
pseudo-terminal: the code path is the same), checks that the six expected STS3215
answer, and offers what the target needs: one group sync read of the state block
(``Present_Position`` 56 .. ``Moving`` 66: position, velocity, load, voltage,
temperature, status), one group sync write of the six goals, torque on/off, and
register reads/writes for calibration and diagnosis.

Every failure is a :class:`BusError` with a ``code``:

======================  ====================================================
``bus.port``            the port cannot be opened (missing, busy, no permission)
``bus.id_mismatch``     an expected servo id does not answer (the ids that do are listed)
``bus.model``           a servo is not an STS3215 (model number 777)
``bus.timeout``         a servo did not answer within the SDK's packet timeout
``bus.corrupt``         a status packet failed its checksum / framing
``bus.tx``              the instruction could not be written
``bus.calibration_ids`` the calibration file's ids differ from the bus's
======================  ====================================================

Retries: a failed read is retried ``retries`` times (a lost packet on a real bus is not
rare); only then it raises. Writes of goals are broadcast SYNC_WRITEs (no answer).
"""

from __future__ import annotations

import logging
import os
import select
import threading
import time
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from phyagentos.errors import TargetError
from phyagentos.extras import import_extra

from .protocol import (
    ADDR,
    MOTOR_IDS,
    MOTOR_NAMES,
    SIGN_BITS,
    STS3215_MODEL_NUMBER,
    decode_sign_magnitude,
    encode_sign_magnitude,
)

scs = import_extra("scservo_sdk", extra="real")  # Feetech's SDK (it imports pyserial)

__all__ = ["FeetechBus", "BusError", "BusState", "STATE_BLOCK"]

log = logging.getLogger(__name__)

#: (start address, length) of the state block read every control period.
STATE_BLOCK = (ADDR["Present_Position"].address, ADDR["Moving"].address + 1 - ADDR["Present_Position"].address)
_COMM_CODES = {scs.COMM_RX_TIMEOUT: "bus.timeout", scs.COMM_RX_CORRUPT: "bus.corrupt", scs.COMM_TX_FAIL: "bus.tx",
               scs.COMM_TX_ERROR: "bus.tx", scs.COMM_PORT_BUSY: "bus.tx", scs.COMM_RX_FAIL: "bus.timeout"}


class BusError(TargetError):
    """A Feetech bus failure; ``code`` is one of the module's codes, ``servo_id`` the
    servo concerned (None for the port or the whole bus)."""

    def __init__(self, message: str, *, code: str, servo_id: int | None = None):
        super().__init__(message)
        self.code = code
        self.servo_id = servo_id


@dataclass(frozen=True)
class BusState:
    """One sync read of the six servos (joint order :data:`MOTOR_NAMES`).

    Attributes: ``position`` steps (6,) int; ``velocity`` steps/s; ``load`` 0.1 % of
    max torque (signed); ``voltage`` 0.1 V; ``temperature`` deg C; ``status`` error bits
    (32 overload, 4 overheat, 2 angle sensor, 1 voltage, 8 overcurrent); ``moving`` 0/1;
    ``t`` monotonic time of the read, s.
    """

    position: np.ndarray
    velocity: np.ndarray
    load: np.ndarray
    voltage: np.ndarray
    temperature: np.ndarray
    status: np.ndarray
    moving: np.ndarray
    t: float


class _PortHandler(scs.PortHandler):
    """The SDK's port handler with ``margin_ms`` added to every packet timeout (the SDK's is
    ``2 x LATENCY_TIMER (16 ms) + 2 ms`` plus the bytes' time: the USB adapter's latency),
    and a read that waits on the port instead of spinning.

    The SDK polls a non-blocking read in a loop until the status packet is complete or the
    timeout passes, which keeps a core busy and, in Python, the GIL held: a bus twin serving
    from a thread of the same process then answers late on a loaded machine. An empty read
    here waits up to :data:`_READ_WAIT_S` for the port to become readable (``select``), so
    the answer is taken as soon as it arrives and nothing spins.
    """

    def __init__(self, port_name: str, margin_ms: float):
        super().__init__(port_name)
        self.margin_ms = float(margin_ms)

    def setPacketTimeout(self, packet_length):  # noqa: N802 - the SDK's name
        super().setPacketTimeout(packet_length)
        self.packet_timeout += self.margin_ms

    def readPort(self, length):  # noqa: N802 - the SDK's name
        data = self.ser.read(length)
        if not data:
            try:
                select.select([self.ser.fileno()], [], [], _READ_WAIT_S)
            except (OSError, ValueError):  # closed under us: the SDK's timeout ends the read
                pass
        return data


#: Longest wait of one empty read for the port to become readable, in s (well under the
#: SDK's smallest packet timeout, ~34 ms at 1 Mbaud).
_READ_WAIT_S = 0.002


def default_timeout_margin_ms(port: str) -> float:
    """0 for a serial device; 1000 ms for a pseudo-terminal (``/dev/pts/N``, a bus twin), whose
    servos are a thread of some process on a possibly busy machine, not microcontrollers
    (300 ms was measured too short: a full test run on a loaded 2-core machine starved the
    twin through three 300 ms timeouts in a row, 2026-11-26)."""
    return 1000.0 if os.path.realpath(port).startswith("/dev/pts/") else 0.0


class FeetechBus:
    """Six STS3215 on one serial port.

    Args:
        port: serial device path (``/dev/ttyACM0``, ``/dev/pts/N`` of a bus twin).
        ids: servo ids in :data:`MOTOR_NAMES` order (default 1..6, LeRobot's SO-101).
        baudrate: 1 000 000 (the SO-101's, LeRobot's default).
        retries: extra attempts of a failed read before :class:`BusError`.
        timeout_margin_ms: added to the SDK's packet timeout (default
            :func:`default_timeout_margin_ms`: 0 on a real port).
    """

    def __init__(self, port: str, *, ids: Sequence[int] | None = None, baudrate: int = 1_000_000, retries: int = 2,
                 timeout_margin_ms: float | None = None):
        self.port = str(port)
        self.ids: tuple[int, ...] = tuple(int(i) for i in ids) if ids is not None else tuple(MOTOR_IDS.values())
        self.baudrate = int(baudrate)
        self.retries = int(retries)
        self.timeout_margin_ms = default_timeout_margin_ms(self.port) if timeout_margin_ms is None \
            else float(timeout_margin_ms)
        self._ph: scs.PortHandler | None = None
        self._pk = scs.PacketHandler(0)  # protocol_end 0: STS servos, little-endian words
        self._lock = threading.RLock()
        self._reader: scs.GroupSyncRead | None = None
        self.stats = {"sync_reads": 0, "sync_writes": 0, "retries": 0}

    # -- connection ---------------------------------------------------------------------
    @property
    def connected(self) -> bool:
        return self._ph is not None

    def open(self) -> None:
        """Open the port (no servo traffic).

        Raises:
            BusError: ``bus.port`` (the message names the port and the OS error).
        """
        if self._ph is not None:
            return
        ph = _PortHandler(self.port, self.timeout_margin_ms)
        try:
            ok = ph.openPort() and ph.setBaudRate(self.baudrate)
        except Exception as exc:  # serial.SerialException, OSError: missing, busy, permission
            raise BusError(f"cannot open the servo bus at {self.port!r}: {exc}. Check the USB cable and "
                           f"`ls /dev/ttyACM* /dev/ttyUSB*`; on Linux add yourself to the dialout group",
                           code="bus.port") from exc
        if not ok:
            raise BusError(f"cannot open the servo bus at {self.port!r} at {self.baudrate} baud", code="bus.port")
        self._ph = ph
        reader = scs.GroupSyncRead(ph, self._pk, *STATE_BLOCK)
        for i in self.ids:
            reader.addParam(i)
        self._reader = reader

    def connect(self) -> list[dict]:
        """Open the port and ping every expected id; returns ``[{id, model, firmware}]``.

        Raises:
            BusError: ``bus.port``; ``bus.id_mismatch`` (missing ids, and the ids found
                by a scan of 0..20); ``bus.model`` (not an STS3215).
        """
        self.open()
        found, missing = [], []
        for name, i in zip(MOTOR_NAMES, self.ids):
            model = self._ping(i)
            if model is None:
                missing.append((name, i))
                continue
            if model != STS3215_MODEL_NUMBER:
                raise BusError(f"servo {i} ({name}) reports model number {model}, not an STS3215 "
                               f"({STS3215_MODEL_NUMBER}); is this an SO-101 follower arm?", code="bus.model", servo_id=i)
            major = self.read(i, "Firmware_Major_Version")
            minor = self.read(i, "Firmware_Minor_Version")
            found.append({"id": i, "joint": name, "model": model, "firmware": f"{major}.{minor}"})
        if missing:
            # a diagnostic scan: one ping per id (each silent id costs a packet timeout)
            present = [i for i in range(0, 21) if i not in self.ids and self._ping(i, retries=0) is not None]
            present += [f["id"] for f in found]
            raise BusError(
                "servos not answering: " + ", ".join(f"{n} (id {i})" for n, i in missing)
                + f"; ids answering on {self.port}: {sorted(present) or 'none'}. Set the ids with LeRobot's "
                "`lerobot-setup-motors` (one servo on the bus at a time) or check the daisy-chain cables",
                code="bus.id_mismatch", servo_id=missing[0][1])
        return found

    def close(self) -> None:
        """Close the port (idempotent). Does not change the torque."""
        with self._lock:
            if self._ph is not None:
                try:
                    self._ph.closePort()
                finally:
                    self._ph = None
                    self._reader = None

    def __enter__(self) -> "FeetechBus":
        self.connect()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # -- registers ----------------------------------------------------------------------
    def _port(self) -> scs.PortHandler:
        if self._ph is None:
            raise BusError(f"servo bus {self.port!r} is not open", code="bus.port")
        return self._ph

    def _flush(self) -> None:
        """Drop unread input (a late answer to an earlier, timed-out instruction would
        otherwise be taken for the next one's: the SDK's ``clearPort`` flushes output only)."""
        self._port().ser.reset_input_buffer()

    def _ping(self, servo_id: int, *, retries: int | None = None) -> int | None:
        with self._lock:
            for _ in range((self.retries if retries is None else retries) + 1):
                self._flush()
                try:
                    model, res, _err = self._pk.ping(self._port(), servo_id)
                except IndexError:  # the SDK read a short (late, stale) answer as the model number
                    continue
                if res == scs.COMM_SUCCESS:
                    return int(model)
        return None

    def read(self, servo_id: int, name: str) -> int:
        """Read register ``name`` (:data:`~.protocol.ADDR`) of one servo (sign decoded).

        Raises:
            BusError: ``bus.timeout`` / ``bus.corrupt`` after the retries.
        """
        reg = ADDR[name]
        fn = self._pk.read1ByteTxRx if reg.size == 1 else self._pk.read2ByteTxRx
        with self._lock:
            for attempt in range(self.retries + 1):
                self._flush()
                try:
                    value, res, _err = fn(self._port(), servo_id, reg.address)
                except IndexError:  # a short (late, stale) answer
                    value, res = 0, scs.COMM_RX_CORRUPT
                if res == scs.COMM_SUCCESS:
                    return decode_sign_magnitude(value, SIGN_BITS[name]) if name in SIGN_BITS else int(value)
                self.stats["retries"] += attempt < self.retries
        raise self._comm_error(res, servo_id, f"read {name}")

    def write(self, servo_id: int, name: str, value: int) -> None:
        """Write register ``name`` of one servo and wait for its status packet.

        Raises:
            BusError: no or corrupt answer after the retries.
        """
        reg = ADDR[name]
        v = encode_sign_magnitude(value, SIGN_BITS[name]) if name in SIGN_BITS else int(value)
        fn = self._pk.write1ByteTxRx if reg.size == 1 else self._pk.write2ByteTxRx
        with self._lock:
            for _ in range(self.retries + 1):
                self._flush()
                res, _err = fn(self._port(), servo_id, reg.address, v)
                if res == scs.COMM_SUCCESS:
                    return
        raise self._comm_error(res, servo_id, f"write {name}")

    def read_all(self, name: str) -> list[int]:
        """Register ``name`` of the six servos, joint order."""
        return [self.read(i, name) for i in self.ids]

    def write_all(self, name: str, values: Sequence[int]) -> None:
        """Write register ``name`` of the six servos (EPROM registers: torque off and
        ``Lock`` 0 first, as :meth:`torque` (False) leaves them)."""
        for i, v in zip(self.ids, values):
            self.write(i, name, int(v))

    # -- control period -----------------------------------------------------------------
    def sync_read_state(self) -> BusState:
        """One GROUP_SYNC_READ of the state block of all six servos.

        Raises:
            BusError: ``bus.timeout`` (the first servo that did not answer) or
                ``bus.corrupt`` after the retries.
        """
        with self._lock:
            reader = self._reader
            if reader is None:
                raise BusError(f"servo bus {self.port!r} is not open", code="bus.port")
            for attempt in range(self.retries + 1):
                self._flush()
                res = reader.txRxPacket()
                self.stats["sync_reads"] += 1
                if res == scs.COMM_SUCCESS:
                    break
                self.stats["retries"] += attempt < self.retries
            else:
                bad = next((i for i in self.ids if len(reader.data_dict.get(i) or ()) < STATE_BLOCK[1]), None)
                raise self._comm_error(res, bad, "sync read of the state")
            a0 = STATE_BLOCK[0]
            rows = []
            for i in self.ids:
                d = reader.data_dict[i]
                w = lambda n, d=d: d[ADDR[n].address - a0] | (d[ADDR[n].address - a0 + 1] << 8)  # noqa: E731
                b = lambda n, d=d: d[ADDR[n].address - a0]  # noqa: E731
                rows.append((w("Present_Position"), decode_sign_magnitude(w("Present_Velocity"), 15),
                             decode_sign_magnitude(w("Present_Load"), 10), b("Present_Voltage"),
                             b("Present_Temperature"), b("Status"), b("Moving")))
        a = np.array(rows, dtype=np.int64).T
        return BusState(position=a[0], velocity=a[1], load=a[2], voltage=a[3], temperature=a[4], status=a[5],
                        moving=a[6], t=time.monotonic())

    def sync_write_goals(self, steps: Sequence[int]) -> None:
        """One GROUP_SYNC_WRITE of ``Goal_Position`` (6,) steps (no answer on the bus).

        Raises:
            BusError: ``bus.tx`` when the packet could not be written.
        """
        self._sync_write("Goal_Position", [int(s) for s in steps])

    def _sync_write(self, name: str, values: Sequence[int]) -> None:
        reg = ADDR[name]
        with self._lock:
            w = scs.GroupSyncWrite(self._port(), self._pk, reg.address, reg.size)
            for i, v in zip(self.ids, values):
                data = [v & 0xFF] if reg.size == 1 else [scs.SCS_LOBYTE(v), scs.SCS_HIBYTE(v)]
                w.addParam(i, data)
            res = w.txPacket()
            self.stats["sync_writes"] += 1
        if res != scs.COMM_SUCCESS:
            raise self._comm_error(res, None, f"sync write of {name}")

    def torque(self, enable: bool, *, goals: Sequence[int] | None = None) -> None:
        """Torque on (after writing ``goals``, default the present positions, so nothing
        jumps) or off (and ``Lock`` 0: EPROM writable) on all six servos, one sync write each.

        Raises:
            BusError: on a bus failure.
        """
        if enable:
            if goals is None:
                goals = [int(p) for p in self.sync_read_state().position]
            self.sync_write_goals(goals)
            self._sync_write("Torque_Enable", [1] * 6)
            self._sync_write("Lock", [1] * 6)
        else:
            self._sync_write("Torque_Enable", [0] * 6)
            self._sync_write("Lock", [0] * 6)

    def write_calibration(self, calibration) -> bool:
        """Write a :class:`~.calibration.Calibration` into the servos (``Homing_Offset``,
        position limits), as LeRobot does on connect, unless they already hold it (then
        nothing is written and the torque is untouched: an arm holding a pose keeps it).
        Writing turns the torque off first (EPROM). Returns True if it wrote.

        Raises:
            BusError: ``bus.calibration_ids`` when the file's ids are not the bus's.
        """
        if tuple(calibration.ids) != self.ids:
            raise BusError(f"calibration ids {list(calibration.ids)} differ from the bus ids {list(self.ids)} "
                           f"({', '.join(MOTOR_NAMES)}); re-run calibration for this arm", code="bus.calibration_ids")
        mc = [calibration.motors[n] for n in MOTOR_NAMES]
        want = {"Homing_Offset": [m.homing_offset for m in mc], "Min_Position_Limit": [m.range_min for m in mc],
                "Max_Position_Limit": [m.range_max for m in mc]}
        if all(self.read_all(name) == values for name, values in want.items()):
            return False
        self.torque(False)
        for name, values in want.items():
            self.write_all(name, values)
        return True

    def _comm_error(self, res: int, servo_id: int | None, what: str) -> BusError:
        code = _COMM_CODES.get(res, "bus.timeout")
        who = f"servo {servo_id} ({MOTOR_NAMES[self.ids.index(servo_id)]})" if servo_id in self.ids else \
            (f"servo {servo_id}" if servo_id is not None else "the bus")
        return BusError(f"{what} on {self.port}: {who}: {self._pk.getTxRxResult(res)} after {self.retries + 1} "
                        f"attempts", code=code, servo_id=servo_id)

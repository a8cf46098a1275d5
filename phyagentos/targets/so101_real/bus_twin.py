"""A simulated Feetech bus: six STS3215 servos on a pseudo-terminal, backed by MuJoCo.

:class:`BusTwin` opens a pseudo-terminal (``pty.openpty``); its slave path
(``/dev/pts/N``) is the serial port a driver opens exactly as it would open
``/dev/ttyACM0`` of a real SO-101 (``scservo_sdk.PortHandler(path)``, 1 Mbaud). The
master end is served by a thread that parses instruction packets and answers with status
packets byte for byte as an STS3215 does (:mod:`.protocol`): PING, READ, WRITE,
REG_WRITE/ACTION, SYNC_READ (one status packet per addressed servo, in id order) and
SYNC_WRITE (no answer).

Behind the registers is the shipped MuJoCo SO-101
(:func:`phyagentos.targets.so101.build_so101_scene` with the SO-101's default scene: a
3 cm cube and a goal region), advanced in wall-clock time (a ticker thread every
``tick_s``, and before every answer that reads state). Each servo:

- moves its internal set point toward the commanded ``Goal_Position`` at
  ``Goal_Velocity`` steps/s (0: the STS3215's no-load speed, 4.7 rad/s) and drives the
  model's position actuator with it (the actuator is the servo's position loop:
  kp 17.8 N m/rad, 3.35 N m torque limit in the shipped model);
- clamps goals into its ``Min/Max_Position_Limit`` (as the firmware does);
- reports ``Present_Position`` = encoder - ``Homing_Offset`` (mod 4096), where the
  encoder reads ``2048 + mount_offset + q * 4096 / 2 pi`` (``mount_offset``: how the horn
  happens to be mounted, random per servo from ``seed``, which calibration must find);
  ``Present_Velocity`` in steps/s, ``Present_Load`` as actuator force / torque limit in
  0.1 % (sign bit 10), temperature, voltage, ``Moving``;
- with torque off, reports no load and no longer follows goals; the joint stays where a
  hand leaves it (:meth:`BusTwin.hand_move`): the STS3215's 1:345 gearbox is modelled as
  not back-drivable (the joint is held kinematically). A real SO-101 may sag a little
  with torque off; the twin does not.

EPROM registers (addresses below 40) are written only while ``Lock`` is 0 (the
firmware's write protection; LeRobot and the driver unlock before calibration writes).

Injectable faults (:meth:`BusTwin.inject`), per servo id:

=============  ================================================================
``silent``     the servo stops answering (no status packet at all)
``checksum``   its status packets carry a wrong checksum
``overload``   status error bit 32 (overload) and the servo drops its torque, as the
               STS protection does
``stall``      the joint is blocked where it is: it no longer moves, the servo pushes
               with its full torque (``Present_Load`` 1000)
``glitch``     its position sensor reads nonsense (half a turn off, error bit 2)
=============  ================================================================

Units: the registers' (steps, steps/s, 0.1 %, deg C, 0.1 V); joint angles in radians.
"""

from __future__ import annotations

import logging
import math
import os
import pty
import select
import threading
import time
import tty
from dataclasses import dataclass, field
from typing import Mapping, Sequence

import mujoco
import numpy as np

from phyagentos.errors import TargetError, format_choices

from .protocol import (
    ADDR,
    BROADCAST_ID,
    ERR_ANGLE,
    ERR_OVERLOAD,
    INST_ACTION,
    INST_PING,
    INST_READ,
    INST_REG_WRITE,
    INST_SYNC_READ,
    INST_SYNC_WRITE,
    INST_WRITE,
    MOTOR_NAMES,
    RESOLUTION,
    SIGN_BITS,
    STEPS_PER_RAD,
    STS3215_MODEL_NUMBER,
    checksum,
    decode_sign_magnitude,
    encode_sign_magnitude,
    status_packet,
)

__all__ = ["BusTwin", "FAULT_KINDS", "DEFAULT_SPEED_RAD_S", "FIRMWARE_VERSION"]

log = logging.getLogger(__name__)

FAULT_KINDS: tuple[str, ...] = ("silent", "checksum", "overload", "stall", "glitch")
#: STS3215 no-load speed (0.222 s / 60 deg at 7.4 V, Feetech datasheet), rad/s.
DEFAULT_SPEED_RAD_S = 4.7
#: Firmware version the simulated servos report (major, minor).
FIRMWARE_VERSION = (3, 10)
_TABLE_SIZE = 90
_EPROM_END = 40
_MAX_CATCH_UP_S = 0.1


@dataclass
class _Servo:
    servo_id: int
    joint: str
    mount_offset: int
    regs: bytearray = field(default_factory=lambda: bytearray(_TABLE_SIZE))
    setpoint: float = 0.0  # rad, the servo's internal set point
    faults: set = field(default_factory=set)
    stall_q: float | None = None
    pending: tuple[int, bytes] | None = None  # REG_WRITE waiting for ACTION

    def get(self, name: str) -> int:
        r = ADDR[name]
        v = self.regs[r.address] if r.size == 1 else self.regs[r.address] | (self.regs[r.address + 1] << 8)
        return decode_sign_magnitude(v, SIGN_BITS[name]) if name in SIGN_BITS else v

    def put(self, name: str, value: int) -> None:
        r = ADDR[name]
        v = encode_sign_magnitude(int(value), SIGN_BITS[name]) if name in SIGN_BITS else int(value)
        v &= (1 << (8 * r.size)) - 1
        self.regs[r.address] = v & 0xFF
        if r.size == 2:
            self.regs[r.address + 1] = (v >> 8) & 0xFF


class BusTwin:
    """Six simulated STS3215 servos on a pseudo-terminal (see the module docstring).

    Args:
        ids: the servo ids on the bus, one per joint in :data:`MOTOR_NAMES` order
            (default 1..6; another tuple simulates a mis-addressed arm).
        seed: draws the per-servo horn mount offsets (steps, -600..600).
        mount_offsets: explicit offsets (steps, 6 ints) instead of drawn ones.
        tick_s: period of the physics ticker thread, s.
        start_q: initial joint angles (6,) rad (default: the SO-101 target's ready pose
            :data:`~phyagentos.targets.so101.HOME_QPOS` with the jaw closed, where a first
            session finds the arm at rest).

    Use as a context manager or call :meth:`start` / :meth:`stop`. :attr:`port` is the
    serial device path once started.

    Raises:
        TargetError: bad ids/offsets, or the SO-101 model is missing.
    """

    def __init__(self, *, ids: Sequence[int] = (1, 2, 3, 4, 5, 6), seed: int = 0,
                 mount_offsets: Sequence[int] | None = None, tick_s: float = 0.01,
                 start_q: Sequence[float] | None = None):
        from phyagentos.targets.so101 import HOME_QPOS, SO101_DEFAULT_SCENE, build_so101_scene  # noqa: PLC0415 - the model only for a twin

        ids = tuple(int(i) for i in ids)
        if len(ids) != 6 or len(set(ids)) != 6 or not all(0 <= i < BROADCAST_ID for i in ids):
            raise TargetError(f"bus twin: ids must be 6 distinct ints in 0..253, got {ids}")
        rng = np.random.default_rng(seed)
        offs = rng.integers(-600, 601, size=6) if mount_offsets is None else np.asarray(mount_offsets, dtype=int)
        if offs.shape != (6,):
            raise TargetError(f"bus twin: mount_offsets must be 6 ints, got {mount_offsets!r}")
        self._model = build_so101_scene(SO101_DEFAULT_SCENE)
        self._data = mujoco.MjData(self._model)
        m = self._model
        self._qadr = np.array([m.jnt_qposadr[m.joint(n).id] for n in MOTOR_NAMES])
        self._dadr = np.array([m.jnt_dofadr[m.joint(n).id] for n in MOTOR_NAMES])
        self._act = np.array([m.actuator(n).id for n in MOTOR_NAMES])
        self._frc = np.abs(m.actuator_forcerange[self._act, 1])
        self._qlo = m.jnt_range[[m.joint(n).id for n in MOTOR_NAMES], 0].copy()
        self._qhi = m.jnt_range[[m.joint(n).id for n in MOTOR_NAMES], 1].copy()
        q0 = np.array([*HOME_QPOS, 0.0]) if start_q is None else np.asarray(start_q, dtype=float).reshape(6)
        self._data.qpos[self._qadr] = q0
        mujoco.mj_forward(m, self._data)
        self._servos: dict[int, _Servo] = {}
        for k, (sid, name) in enumerate(zip(ids, MOTOR_NAMES)):
            s = _Servo(sid, name, int(offs[k]))
            s.put("Firmware_Major_Version", FIRMWARE_VERSION[0])
            s.put("Firmware_Minor_Version", FIRMWARE_VERSION[1])
            s.put("Model_Number", STS3215_MODEL_NUMBER)
            s.put("ID", sid)
            s.put("Baud_Rate", 0)  # 1 Mbaud
            s.put("Response_Status_Level", 1)
            s.put("Min_Position_Limit", 0)
            s.put("Max_Position_Limit", RESOLUTION - 1)
            s.put("Max_Temperature_Limit", 70)
            s.put("Max_Torque_Limit", 1000)
            s.put("P_Coefficient", 32)
            s.put("Torque_Limit", 1000)
            s.put("Lock", 1)
            s.put("Present_Voltage", 120)
            s.put("Present_Temperature", 28)
            s.setpoint = float(q0[k])
            self._servos[sid] = s
        for s in self._servos.values():
            s.put("Goal_Position", self._present_steps(s, self._joint_q(s)))
        self._tick_s = float(tick_s)
        self._lock = threading.RLock()
        self._last = time.monotonic()
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._master = self._slave = -1
        self.port: str | None = None
        self.packets_served = 0
        self.goal_writes = 0  # WRITE/SYNC_WRITE instructions touching Goal_Position or Torque_Enable
        self.last_goal_write_t: float | None = None  # monotonic time of the last such instruction

    # -- lifecycle ------------------------------------------------------------------
    def start(self) -> "BusTwin":
        """Open the pseudo-terminal and start serving; returns self (``port`` set)."""
        if self.port is not None:
            return self
        self._master, self._slave = pty.openpty()
        tty.setraw(self._slave)  # no line discipline: binary bytes pass unchanged
        tty.setraw(self._master)
        self.port = os.ttyname(self._slave)
        self._last = time.monotonic()
        for fn, name in ((self._serve, "bus-twin-serve"), (self._tick, "bus-twin-physics")):
            t = threading.Thread(target=fn, name=name, daemon=True)
            t.start()
            self._threads.append(t)
        log.info("bus twin serving six STS3215 on %s", self.port)
        return self

    def stop(self) -> None:
        """Stop serving and close the pseudo-terminal (idempotent)."""
        self._stop.set()
        for t in self._threads:
            t.join(timeout=2.0)
        self._threads.clear()
        for fd in (self._master, self._slave):
            if fd >= 0:
                try:
                    os.close(fd)
                except OSError:
                    pass
        self._master = self._slave = -1

    def __enter__(self) -> "BusTwin":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    # -- test / bench hooks (the "world" side, not the bus) -------------------------------
    def inject(self, servo_id: int, kind: str) -> None:
        """Inject fault ``kind`` (:data:`FAULT_KINDS`) into servo ``servo_id``.

        Raises:
            TargetError: unknown kind or id.
        """
        if kind not in FAULT_KINDS:
            raise TargetError(f"unknown bus fault {kind!r}; valid faults: {format_choices(FAULT_KINDS)}")
        with self._lock:
            s = self._servo_or_raise(servo_id)
            s.faults.add(kind)
            if kind == "stall":
                s.stall_q = self._joint_q(s)
            if kind == "overload":
                s.put("Torque_Enable", 0)

    def clear(self, servo_id: int | None = None) -> None:
        """Clear the faults of one servo (or of all)."""
        with self._lock:
            for s in self._servos.values():
                if servo_id is None or s.servo_id == servo_id:
                    s.faults.clear()
                    s.stall_q = None

    def hand_move(self, q: Mapping[str, float]) -> None:
        """Move joints by hand (torque must be off on them): ``{joint: rad}``.

        Raises:
            TargetError: unknown joint, or its servo holds torque (a hand cannot move it).
        """
        with self._lock:
            for name, val in q.items():
                if name not in MOTOR_NAMES:
                    raise TargetError(f"unknown joint {name!r}; valid joints: {format_choices(MOTOR_NAMES)}")
                k = MOTOR_NAMES.index(name)
                s = self._by_joint(name)
                if s.get("Torque_Enable"):
                    raise TargetError(f"joint {name} holds torque; disable it before moving it by hand")
                v = float(np.clip(val, self._qlo[k], self._qhi[k]))
                self._data.qpos[self._qadr[k]] = v
                self._data.qvel[self._dadr[k]] = 0.0
                s.setpoint = v
            mujoco.mj_forward(self._model, self._data)
            self._advance(refresh=True)

    def joint_ranges(self) -> np.ndarray:
        """(6, 2) joint ranges of the model, rad."""
        return np.column_stack([self._qlo, self._qhi])

    def joint_positions(self) -> np.ndarray:
        """(6,) true joint angles, rad (the world, for tests and benches)."""
        with self._lock:
            self._advance()
            return self._data.qpos[self._qadr].copy()

    def object_position(self, name: str = "cube") -> np.ndarray:
        """(3,) world position of an object of the twin's scene, m."""
        with self._lock:
            return self._data.body(name).xpos.copy()

    def moving(self) -> list[int]:
        """Each servo's ``Moving`` flag (1: still turning or still ramping to its goal), in
        joint order, after stepping the physics up to now."""
        with self._lock:
            self._advance(refresh=True)
            return [self._by_joint(n).get("Moving") for n in MOTOR_NAMES]

    def torque_enabled(self) -> list[int]:
        """Torque_Enable of each servo, in joint order."""
        with self._lock:
            return [self._by_joint(n).get("Torque_Enable") for n in MOTOR_NAMES]

    # -- servo model ----------------------------------------------------------------
    def _servo_or_raise(self, servo_id: int) -> _Servo:
        if servo_id not in self._servos:
            raise TargetError(f"no servo {servo_id} on the bus twin; ids: {sorted(self._servos)}")
        return self._servos[servo_id]

    def _by_joint(self, name: str) -> _Servo:
        return next(s for s in self._servos.values() if s.joint == name)

    def _k(self, s: _Servo) -> int:
        return MOTOR_NAMES.index(s.joint)

    def _joint_q(self, s: _Servo) -> float:
        return float(self._data.qpos[self._qadr[self._k(s)]])

    def _encoder(self, s: _Servo, q: float) -> float:
        return 2048.0 + s.mount_offset + q * STEPS_PER_RAD

    def _present_steps(self, s: _Servo, q: float) -> int:
        return int(round(self._encoder(s, q) - s.get("Homing_Offset"))) % RESOLUTION

    def _goal_q(self, s: _Servo) -> float:
        lo, hi = s.get("Min_Position_Limit"), s.get("Max_Position_Limit")
        goal = min(max(s.get("Goal_Position"), lo), hi)
        enc = goal + s.get("Homing_Offset")
        d = (enc - 2048 - s.mount_offset + RESOLUTION / 2) % RESOLUTION - RESOLUTION / 2
        return d / STEPS_PER_RAD

    def _advance(self, *, refresh: bool = False) -> None:
        """Step the physics up to now (wall clock), at most ``_MAX_CATCH_UP_S`` behind, and
        refresh the present-value registers (``refresh``: even if no step was due)."""
        m, d = self._model, self._data
        now = time.monotonic()
        ts = m.opt.timestep
        n = int((now - self._last) / ts)
        if n <= 0 and not refresh:
            return
        if n * ts > _MAX_CATCH_UP_S:
            n = int(_MAX_CATCH_UP_S / ts)
            self._last = now
        elif n > 0:
            self._last += n * ts
        servos = [self._by_joint(name) for name in MOTOR_NAMES]
        goals, speeds, on = np.zeros(6), np.zeros(6), np.zeros(6, dtype=bool)
        for k, s in enumerate(servos):
            on[k] = bool(s.get("Torque_Enable")) and "overload" not in s.faults
            goals[k] = self._goal_q(s)
            v = abs(s.get("Goal_Velocity"))
            speeds[k] = v / STEPS_PER_RAD if v > 0 else DEFAULT_SPEED_RAD_S
        # held joints: a stalled one where it stalled; a limp one where the hand left it
        stall = [(k, s.stall_q) for k, s in enumerate(servos) if s.stall_q is not None]
        stall += [(k, s.setpoint) for k, s in enumerate(servos) if not on[k] and s.stall_q is None]
        qadr, dadr, act = self._qadr, self._dadr, self._act
        for _ in range(n):
            for k, s in enumerate(servos):
                if on[k]:
                    step = speeds[k] * ts
                    s.setpoint += float(np.clip(goals[k] - s.setpoint, -step, step))
                d.ctrl[act[k]] = s.setpoint
            mujoco.mj_step(m, d)
            for k, q in stall:
                d.qpos[qadr[k]] = q
                d.qvel[dadr[k]] = 0.0
        if stall and n > 0:
            mujoco.mj_forward(m, d)
        for k, s in enumerate(servos):
            q, qd = float(d.qpos[qadr[k]]), float(d.qvel[dadr[k]])
            pos = self._present_steps(s, q)
            err = 0
            if "glitch" in s.faults:  # a half-turn jump, as a misread magnet
                pos = (pos + RESOLUTION // 2) % RESOLUTION
                err |= ERR_ANGLE
            s.put("Present_Position", pos)
            s.put("Present_Velocity", int(round(qd * STEPS_PER_RAD)))
            load = 0.0 if not on[k] else float(d.actuator_force[act[k]]) / self._frc[k] * 1000.0
            if s.stall_q is not None and on[k] and abs(s.setpoint - q) > 0.01:
                load = 1000.0 * math.copysign(1.0, s.setpoint - q)
            s.put("Present_Load", int(round(np.clip(load, -1000, 1000))))
            s.put("Present_Current", int(abs(load) * 2))
            s.put("Moving", int(abs(qd) > 0.02 or (on[k] and abs(goals[k] - s.setpoint) > 1e-4)))
            temp = 28 + int(abs(load) / 100)
            s.put("Present_Temperature", temp)
            s.put("Status", err | (ERR_OVERLOAD if "overload" in s.faults else 0))

    def _tick(self) -> None:
        while not self._stop.wait(self._tick_s):
            with self._lock:
                self._advance()

    # -- the bus ----------------------------------------------------------------------
    def _serve(self) -> None:
        buf = bytearray()
        while not self._stop.is_set():
            try:
                ready, _, _ = select.select([self._master], [], [], 0.05)
            except (OSError, ValueError):
                return
            if not ready:
                continue
            try:
                chunk = os.read(self._master, 4096)
            except OSError:  # no slave open at the moment (EIO): wait for the next driver
                time.sleep(0.01)
                continue
            buf.extend(chunk)
            while True:
                pkt = _take_packet(buf)
                if pkt is None:
                    break
                if pkt is _BAD:
                    continue
                reply = self._handle(*pkt)
                if reply:
                    try:
                        os.write(self._master, reply)
                    except OSError:
                        pass

    def _handle(self, sid: int, inst: int, params: bytes) -> bytes:
        with self._lock:
            self.packets_served += 1
            if inst in (INST_READ, INST_SYNC_READ, INST_PING):
                self._advance()
            if inst == INST_SYNC_READ:
                addr, n = params[0], params[1]
                out = b""
                for i in params[2:]:
                    s = self._servos.get(i)
                    if s is not None and "silent" not in s.faults:
                        out += self._status(s, bytes(s.regs[addr:addr + n]))
                return out
            if inst == INST_SYNC_WRITE:
                addr, n = params[0], params[1]
                body = params[2:]
                now = time.monotonic()
                for j in range(0, len(body) - n + 1, n + 1):
                    s = self._servos.get(body[j])
                    if s is not None and "silent" not in s.faults:
                        self._write(s, addr, body[j + 1:j + 1 + n], now)
                return b""
            targets = list(self._servos.values()) if sid == BROADCAST_ID else (
                [self._servos[sid]] if sid in self._servos else [])
            reply = b""
            for s in targets:
                if "silent" in s.faults:
                    continue
                if inst == INST_PING:
                    data = b""
                elif inst == INST_READ:
                    addr, n = params[0], params[1]
                    data = bytes(s.regs[addr:addr + n]).ljust(n, b"\0")
                elif inst == INST_WRITE:
                    self._write(s, params[0], params[1:], time.monotonic())
                    data = b""
                elif inst == INST_REG_WRITE:
                    s.pending = (params[0], bytes(params[1:]))
                    data = b""
                elif inst == INST_ACTION:
                    if s.pending is not None:
                        self._write(s, *s.pending, time.monotonic())
                        s.pending = None
                    data = b""
                else:
                    continue  # unknown instruction: a servo ignores it
                if sid != BROADCAST_ID:
                    reply += self._status(s, data)
            return reply

    def _status(self, s: _Servo, data: bytes) -> bytes:
        return status_packet(s.servo_id, s.get("Status"), data, corrupt="checksum" in s.faults)

    def _write(self, s: _Servo, addr: int, data: bytes, now: float) -> None:
        if addr < _EPROM_END and s.get("Lock") and addr != ADDR["Lock"].address:
            return  # EPROM locked
        if any(addr < r.address + r.size and addr + len(data) > r.address
               for r in (ADDR["Torque_Enable"], ADDR["Goal_Position"])):
            self.goal_writes += 1
            self.last_goal_write_t = now
        self._advance()
        for i, b in enumerate(data):
            if addr + i < _TABLE_SIZE:
                s.regs[addr + i] = b
        if s.get("ID") != s.servo_id:  # re-addressed
            new = s.get("ID")
            if new in self._servos:
                s.put("ID", s.servo_id)
            else:
                del self._servos[s.servo_id]
                s.servo_id = new
                self._servos[new] = s
        if "overload" in s.faults:
            s.put("Torque_Enable", 0)
        self._advance(refresh=True)  # e.g. a new Homing_Offset shows in the next read


_BAD = object()


def _take_packet(buf: bytearray):
    """Pop one instruction packet from ``buf``: (id, instruction, params), ``_BAD`` for a
    dropped corrupt one, or None when more bytes are needed."""
    while len(buf) >= 2 and not (buf[0] == 0xFF and buf[1] == 0xFF):
        del buf[0]
    if len(buf) < 6:
        return None
    sid, length = buf[2], buf[3]
    if sid == 0xFF or length < 2:
        del buf[0]
        return _BAD
    total = length + 4
    if len(buf) < total:
        return None
    pkt = bytes(buf[:total])
    del buf[:total]
    if checksum(pkt[2:-1]) != pkt[-1]:
        log.debug("bus twin: dropped an instruction with a bad checksum")
        return _BAD
    return sid, pkt[4], pkt[5:-1]


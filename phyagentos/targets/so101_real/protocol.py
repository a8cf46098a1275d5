"""The Feetech STS3215 wire protocol and control table, as the bus twin answers it.

The driver itself talks through Feetech's SDK (``scservo_sdk`` from the
``feetech-servo-sdk`` wheel); this module is what the *servo side* needs to speak the
same bytes, and the register addresses both sides use.

Packet format (``scservo_sdk/protocol_packet_handler.py``, Feetech SCS protocol 1.0)::

    instruction:  0xFF 0xFF ID LEN INSTR PARAM... CHECKSUM
    status:       0xFF 0xFF ID LEN ERROR DATA...  CHECKSUM

``LEN`` counts the bytes after itself (instruction/error, parameters, checksum);
``CHECKSUM = ~(ID + LEN + INSTR/ERROR + PARAMS) & 0xFF``. Instructions: PING 1,
READ 2 (addr, n), WRITE 3 (addr, data...), REG_WRITE 4, ACTION 5, SYNC_READ 0x82
(addr, n, ids...; each addressed servo answers with its own status packet, in the order
of the ids), SYNC_WRITE 0x83 (addr, n, then per servo id + n bytes; broadcast id 0xFE,
no answer). Status error bits: 1 voltage, 2 angle sensor, 4 overheat, 8 overcurrent,
32 overload (``ERRBIT_*`` in the SDK). Multi-byte values are little-endian (the SDK's
``SCS_SETEND(0)``, protocol_end 0 for STS servos).

Control table of the STS3215 (addresses and sizes as in LeRobot's
``lerobot/motors/feetech/tables.py`` ``STS_SMS_SERIES_CONTROL_TABLE``; the same
addresses are quoted from it by third-party SO-101 tools, e.g. ``kazuhitogo/so101-control``
``servo_constants.py``: ID 5, Homing_Offset 31, Torque_Enable 40, Goal_Position 42, Lock 55,
Present_Position 56). Sign-magnitude fields (LeRobot's encodings table): Homing_Offset
sign bit 11, Goal_Velocity and Present_Velocity bit 15, Present_Load bit 10 (load in
0.1 % of the maximum torque, 0..1000). Model number 777 is the STS3215 (LeRobot's
``MODEL_NUMBER_TABLE``). Resolution 4096 steps per turn.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = [
    "ADDR", "STS3215_MODEL_NUMBER", "RESOLUTION", "INST_PING", "INST_READ", "INST_WRITE", "INST_REG_WRITE",
    "INST_ACTION", "INST_SYNC_READ", "INST_SYNC_WRITE", "BROADCAST_ID", "ERR_VOLTAGE", "ERR_ANGLE", "ERR_OVERHEAT",
    "ERR_OVERCURRENT", "ERR_OVERLOAD", "checksum", "status_packet", "encode_sign_magnitude",
    "decode_sign_magnitude", "Register", "SIGN_BITS", "MOTOR_NAMES", "MOTOR_IDS", "STEPS_PER_RAD",
]

INST_PING, INST_READ, INST_WRITE, INST_REG_WRITE, INST_ACTION = 1, 2, 3, 4, 5
INST_SYNC_READ, INST_SYNC_WRITE = 0x82, 0x83
BROADCAST_ID = 0xFE
ERR_VOLTAGE, ERR_ANGLE, ERR_OVERHEAT, ERR_OVERCURRENT, ERR_OVERLOAD = 1, 2, 4, 8, 32

STS3215_MODEL_NUMBER = 777
#: Encoder steps per turn.
RESOLUTION = 4096
STEPS_PER_RAD = RESOLUTION / (2.0 * 3.141592653589793)

#: SO-101 motor names (LeRobot's ``so101_follower``) in bus-id order 1..6.
MOTOR_NAMES: tuple[str, ...] = ("shoulder_pan", "shoulder_lift", "elbow_flex", "wrist_flex", "wrist_roll", "gripper")
MOTOR_IDS: dict[str, int] = {n: i + 1 for i, n in enumerate(MOTOR_NAMES)}


@dataclass(frozen=True)
class Register:
    """One control-table entry: byte address and size (1 or 2)."""

    address: int
    size: int


#: STS3215 control table (the entries this project reads or writes).
ADDR: dict[str, Register] = {
    "Firmware_Major_Version": Register(0, 1),
    "Firmware_Minor_Version": Register(1, 1),
    "Model_Number": Register(3, 2),
    "ID": Register(5, 1),
    "Baud_Rate": Register(6, 1),
    "Return_Delay_Time": Register(7, 1),
    "Response_Status_Level": Register(8, 1),
    "Min_Position_Limit": Register(9, 2),
    "Max_Position_Limit": Register(11, 2),
    "Max_Temperature_Limit": Register(13, 1),
    "Max_Torque_Limit": Register(16, 2),
    "P_Coefficient": Register(21, 1),
    "D_Coefficient": Register(22, 1),
    "I_Coefficient": Register(23, 1),
    "Homing_Offset": Register(31, 2),
    "Operating_Mode": Register(33, 1),
    "Overload_Torque": Register(36, 1),
    "Torque_Enable": Register(40, 1),
    "Acceleration": Register(41, 1),
    "Goal_Position": Register(42, 2),
    "Goal_Time": Register(44, 2),
    "Goal_Velocity": Register(46, 2),
    "Torque_Limit": Register(48, 2),
    "Lock": Register(55, 1),
    "Present_Position": Register(56, 2),
    "Present_Velocity": Register(58, 2),
    "Present_Load": Register(60, 2),
    "Present_Voltage": Register(62, 1),
    "Present_Temperature": Register(63, 1),
    "Status": Register(65, 1),
    "Moving": Register(66, 1),
    "Present_Current": Register(69, 2),
}

#: Sign bit of the sign-magnitude fields (LeRobot's ``STS_SMS_SERIES_ENCODINGS_TABLE``).
SIGN_BITS: dict[str, int] = {"Homing_Offset": 11, "Goal_Velocity": 15, "Present_Velocity": 15, "Present_Load": 10}


def checksum(body: bytes | bytearray | list[int]) -> int:
    """``~sum(body) & 0xFF`` over ID, LEN, instruction/error and parameters."""
    return (~sum(body)) & 0xFF


def status_packet(servo_id: int, error: int, data: bytes = b"", *, corrupt: bool = False) -> bytes:
    """A status packet ``FF FF id len error data chk``; ``corrupt`` flips the checksum."""
    body = bytes([servo_id, len(data) + 2, error]) + bytes(data)
    chk = checksum(body)
    if corrupt:
        chk ^= 0x5A
    return b"\xff\xff" + body + bytes([chk])


def encode_sign_magnitude(value: int, sign_bit: int) -> int:
    """Signed int -> Feetech sign-magnitude (magnitude below ``sign_bit``, sign at it)."""
    mag = min(abs(int(value)), (1 << sign_bit) - 1)
    return mag | (1 << sign_bit) if value < 0 else mag


def decode_sign_magnitude(raw: int, sign_bit: int) -> int:
    """Feetech sign-magnitude -> signed int."""
    mag = raw & ((1 << sign_bit) - 1)
    return -mag if raw & (1 << sign_bit) else mag

"""Real-arm commands (issue 32): the bus twin, calibration, the doctor, and ``run --port``.

    phyagentos bus-twin so101 [--seed N] [--ids 1,2,3,4,5,6] [--fault ID:KIND[@SECONDS]] ...
                              [--write-calibration FILE] [--duration S]
    phyagentos calibrate --port PORT [--out FILE] [--robot-id ID]
    phyagentos doctor --target so101_real --port PORT [--calibration FILE] [--json]
    phyagentos run GRAPH --workspace DIR --target so101_real --port PORT [--calibration FILE]
                   [--dry-run] [--stop-policy hold|torque_off]

``run --port`` writes (or updates) the workspace's ``so101_real`` entry in TARGETS.md
(``endpoint`` = the port; ``constraints``: calibration, dry_run, bus limits, and the tool
policy a real robot needs to be allowed to move, an operator decision this flag makes)
and its ``sensors.yaml`` entry (the twin's overview camera unless one is declared),
then runs as usual. Registered in :mod:`phyagentos.cli` by :func:`add_real_commands`
and :func:`with_real`.
"""

from __future__ import annotations

import argparse
import json
import threading
import time
from pathlib import Path
from typing import TYPE_CHECKING, Callable

if TYPE_CHECKING:
    from rich.console import Console

__all__ = ["add_real_commands", "with_real", "doctor_report", "prepare_real_workspace"]

Handler = Callable[[argparse.Namespace, "Console", "Console"], int]
REAL_TARGET = "so101_real"


def add_real_commands(sub: argparse._SubParsersAction) -> None:
    """Add ``bus-twin``, ``calibrate``, ``doctor``, and ``--port`` & co. to ``run``."""
    twin = sub.add_parser("bus-twin", help="serve a simulated Feetech bus (six STS3215, MuJoCo-backed) on a "
                                           "pseudo-terminal and print its port")
    twin.add_argument("robot", choices=("so101",))
    twin.add_argument("--seed", type=int, default=0, help="draws the servos' horn mount offsets (default 0)")
    twin.add_argument("--ids", default="1,2,3,4,5,6", help="servo ids in joint order (default 1,2,3,4,5,6)")
    twin.add_argument("--fault", action="append", default=[], metavar="ID:KIND[@SECONDS]",
                      help="inject a fault (silent, checksum, overload, stall, glitch) into servo ID, optionally "
                           "SECONDS after start (repeatable)")
    twin.add_argument("--write-calibration", type=Path, metavar="FILE",
                      help="write the LeRobot calibration an exact calibration of this twin gives (twin only: a real "
                           "arm is calibrated with `phyagentos calibrate`)")
    twin.add_argument("--duration", type=float, help="stop after this many seconds (default: until Ctrl-C)")

    cal = sub.add_parser("calibrate", help="calibrate an SO-101 on its bus (LeRobot's procedure and file format)")
    cal.add_argument("--port", required=True, help="serial port of the arm (/dev/ttyACM0)")
    cal.add_argument("--out", type=Path, help="calibration JSON to write (default: LeRobot's so101_follower path "
                                              "for --robot-id)")
    cal.add_argument("--robot-id", default="so101", help="LeRobot robot id naming the file (default so101)")

    doc = sub.add_parser("doctor", help="check a real target before power: port, servo ids, firmware, calibration")
    doc.add_argument("--target", required=True, choices=(REAL_TARGET,))
    doc.add_argument("--port", required=True)
    doc.add_argument("--calibration", type=Path, help="calibration JSON (default: LeRobot's so101_follower/so101.json)")
    doc.add_argument("--json", action="store_true", help="print one JSON object")

    run = sub.choices["run"]
    run.add_argument("--port", help="serial port of a real arm (with --target so101_real); a bus twin's port works")
    run.add_argument("--calibration", type=Path, help="calibration JSON of the real arm (LeRobot format)")
    run.add_argument("--dry-run", action="store_true", help="real target: read the bus only; plan, check and "
                                                            "execute in the twin; nothing moves")
    run.add_argument("--stop-policy", choices=("hold", "torque_off"), default="hold",
                     help="what the bus guard does on a fault or e-stop (default hold)")


# -- bus-twin ----------------------------------------------------------------------------------
def _cmd_bus_twin(args, out: Console, err: Console) -> int:
    from phyagentos.errors import TargetError
    from phyagentos.targets.so101_real.bus_twin import FAULT_KINDS, BusTwin

    ids = tuple(int(x) for x in args.ids.split(","))
    faults = []
    for spec in args.fault:
        try:
            head, _, at = spec.partition("@")
            sid, kind = head.split(":")
            faults.append((float(at) if at else 0.0, int(sid), kind))
        except ValueError as exc:
            raise TargetError(f"--fault {spec!r}: expected ID:KIND[@SECONDS], KIND one of {', '.join(FAULT_KINDS)}") \
                from exc
        if kind not in FAULT_KINDS:
            raise TargetError(f"--fault {spec!r}: unknown kind {kind!r}; valid: {', '.join(FAULT_KINDS)}")
    twin = BusTwin(ids=ids, seed=args.seed)
    with twin:
        if args.write_calibration:
            ideal_calibration(twin).save(args.write_calibration)
            err.print(f"[dim]wrote the twin's calibration to {args.write_calibration}[/dim]")
        print(twin.port, flush=True)
        err.print(f"[dim]bus twin: six STS3215 (ids {list(ids)}) on {twin.port} at 1 Mbaud; Ctrl-C stops[/dim]")
        t0 = time.monotonic()
        pending = sorted(faults)
        try:
            while args.duration is None or time.monotonic() - t0 < args.duration:
                while pending and time.monotonic() - t0 >= pending[0][0]:
                    _, sid, kind = pending.pop(0)
                    twin.inject(sid, kind)
                    err.print(f"[yellow]bus twin: fault {kind} on servo {sid}[/yellow]")
                time.sleep(0.05)
        except KeyboardInterrupt:
            pass
    return 0


def ideal_calibration(twin):
    """The calibration an exact LeRobot calibration of ``twin`` produces (homing pose at the
    middle of the model's ranges, ranges at the model's stops). Twin only."""
    import numpy as np

    from phyagentos.targets.so101_real.calibration import Calibration, MotorCalibration
    from phyagentos.targets.so101_real.protocol import MOTOR_NAMES, STEPS_PER_RAD

    R = twin.joint_ranges()
    motors = {}
    for k, name in enumerate(MOTOR_NAMES):
        s = twin._by_joint(name)  # noqa: SLF001 - the twin's own mount offsets
        mid = 0.5 * (R[k, 0] + R[k, 1])
        homing = int(round(2048 + s.mount_offset + mid * STEPS_PER_RAD - 2047))
        lo, hi = (int(round(2048 + s.mount_offset + q * STEPS_PER_RAD - homing)) for q in R[k])
        motors[name] = MotorCalibration(id=s.servo_id, drive_mode=0, homing_offset=homing, range_min=lo, range_max=hi)
    return Calibration(motors, joint_ranges=np.asarray(R))


# -- calibrate ------------------------------------------------------------------------------------
def _cmd_calibrate(args, out: Console, err: Console) -> int:
    from phyagentos.targets.so101_real.calibration import calibrate, default_calibration_path
    from phyagentos.targets.so101_real.driver import FeetechBus

    path = args.out or default_calibration_path(args.robot_id)
    done = threading.Event()
    with FeetechBus(args.port) as bus:
        def at_middle() -> None:
            input("Torque is off. Move the arm to the middle of its range of motion, then press Enter... ")

        def sweep_started() -> None:
            input("Move every joint through its whole range (to both stops), then press Enter... ")
            done.set()

        def sweep_done() -> bool:
            if not hasattr(sweep_done, "thread"):
                sweep_done.thread = threading.Thread(target=sweep_started, daemon=True)
                sweep_done.thread.start()
            return done.is_set()

        cal = calibrate(bus, at_middle=at_middle, sweep_done=sweep_done)
    cal.save(path)
    out.print(f"wrote {path}")
    for problem in cal.compare_with_twin():
        out.print(f"[yellow]warning[/yellow]: {problem}")
    return 0


# -- doctor -------------------------------------------------------------------------------------------
def doctor_report(port: str, calibration: Path | None) -> dict:
    """Check port, ids, model/firmware and the calibration against the twin; moves nothing
    (no torque, no goal, no EPROM write). Returns ``{ok, checks: [{check, ok, detail, fix}]}``."""
    from phyagentos.targets.so101_real.calibration import Calibration, CalibrationError, default_calibration_path
    from phyagentos.targets.so101_real.driver import BusError, FeetechBus
    from phyagentos.targets.so101_real.protocol import MOTOR_NAMES

    checks: list[dict] = []

    def add(check: str, ok: bool, detail: str, fix: str = "") -> None:
        checks.append({"check": check, "ok": ok, "detail": detail, "fix": fix})

    cal_path = calibration or default_calibration_path()
    cal = None
    try:
        cal = Calibration.load(cal_path)
        add("calibration file", True, f"{cal_path}: ids {list(cal.ids)}")
    except CalibrationError as exc:
        add("calibration file", False, str(exc), "calibrate: `phyagentos calibrate --port PORT --out FILE`")
    bus = FeetechBus(port, ids=cal.ids if cal is not None else None)
    try:
        bus.open()
        add("port", True, f"{port} opened at 1 Mbaud")
        found = bus.connect()
        add("servo ids", True, ", ".join(f"{f['joint']}={f['id']}" for f in found))
        fw = sorted({f["firmware"] for f in found})
        add("model and firmware", True, f"STS3215 (777) x6, firmware {', '.join(fw)}",
            "" if len(fw) == 1 else "servos with different firmware: update them with Feetech's FD tool")
        state = bus.sync_read_state()
        add("sync read", True, f"positions {state.position.tolist()}, voltage {state.voltage.max() / 10:.1f} V, "
                               f"temperatures {state.temperature.tolist()} C")
        if state.status.any():
            add("servo status", False, f"status bits {state.status.tolist()}",
                "power-cycle the arm; check the supply voltage and that no joint is blocked")
        if cal is not None:
            offsets = bus.read_all("Homing_Offset")
            mismatch = [n for n, o in zip(MOTOR_NAMES, offsets) if o != cal.motors[n].homing_offset]
            # not an error: the first connect writes the file into the servos (torque off, as LeRobot)
            add("calibration in the servos", True,
                "homing offsets match the file" if not mismatch else
                f"servos {mismatch} do not hold the file's homing offsets yet; the first connect writes them "
                f"(torque off)")
            shift = [o - cal.motors[n].homing_offset for n, o in zip(MOTOR_NAMES, offsets)]
            q = cal.to_radians([(p + d) % 4096 for p, d in zip(state.position.tolist(), shift)])
            ranges = cal.safe_ranges_rad()
            out = [f"{n} {q[k]:+.2f} rad" for k, n in enumerate(MOTOR_NAMES)
                   if not (ranges[k, 0] - 0.15 <= q[k] <= ranges[k, 1] + 0.15)]
            add("pose within calibrated ranges", not out, "all joints inside" if not out else ", ".join(out),
                "" if not out else "the arm reads outside its calibrated range: re-calibrate (a horn may have "
                                   "slipped) or check that the file belongs to this arm")
    except BusError as exc:
        fixes = {"bus.port": "plug the arm's USB, power its servos, check the path (`ls /dev/ttyACM*`) and permissions",
                 "bus.id_mismatch": "set ids 1-6 with `lerobot-setup-motors` (one servo on the bus at a time) or "
                                    "fix the calibration file's ids",
                 "bus.model": "this bus holds servos other than STS3215"}
        check = {"bus.port": "port", "bus.id_mismatch": "servo ids", "bus.model": "model and firmware"}.get(
            exc.code, "bus")
        add(check, False, f"{exc.code}: {exc}", fixes.get(exc.code, "check the cabling and the supply"))
    finally:
        bus.close()
    if cal is not None:
        problems = cal.compare_with_twin()
        add("calibration vs twin ranges", not problems, "consistent" if not problems else "; ".join(problems),
            "" if not problems else "re-run calibration moving each joint to both of its stops")
    return {"ok": all(c["ok"] for c in checks), "port": port, "checks": checks}


def _cmd_doctor(args, out: Console, err: Console) -> int:
    report = doctor_report(args.port, args.calibration)
    if args.json:
        print(json.dumps(report))
    else:
        for c in report["checks"]:
            mark = "[green]ok[/green]  " if c["ok"] else "[red]FAIL[/red]"
            out.print(f"{mark} {c['check']}: {c['detail']}", soft_wrap=True)
            if c["fix"]:
                out.print(f"      fix: {c['fix']}", soft_wrap=True)
        out.print("[green]ready[/green]" if report["ok"] else "[red]not ready: fix the items above before powering "
                                                               "the arm's motion[/red]")
    return 0 if report["ok"] else 1


# -- run --port ---------------------------------------------------------------------------------------
def prepare_real_workspace(workspace: Path, *, port: str, calibration: Path | None, dry_run: bool,
                           stop_policy: str = "hold") -> None:
    """Create ``workspace`` if needed and write its ``so101_real`` target (TARGETS.md) and
    sensors (``sensors.yaml``, the twin's overview camera unless declared)."""
    import yaml

    from phyagentos.protocol import Workspace
    from phyagentos.protocol.atomic import atomic_write_text
    from phyagentos.protocol.schemas import TargetSpec
    from phyagentos.runtime.preflight import NEVER_EXPOSED
    from phyagentos.targets.so101_real.calibration import default_calibration_path
    from phyagentos.targets.so101_real.target import SO101RealTarget

    ws = Workspace.create(workspace)
    cal = str(Path(calibration).expanduser().resolve()) if calibration else str(default_calibration_path())
    spec = TargetSpec(
        name=REAL_TARGET, kind="real_robot", driver="so101_real", enabled=True,
        capabilities=["arm", "arm_5dof", "parallel_gripper", "joint_position_control", "grasp", "place",
                      "ik_position_priority"],
        observations=["joint_positions", "gripper_opening", "object_poses", "rgb"],
        action={"space": "joint_position", "dof": 5, "gripper": "opening_m", "control_rate_hz": 50},
        endpoint=port,
        constraints={"mount_xy": [0.25, 0.0], "calibration": cal, "dry_run": bool(dry_run),
                     "control_period_s": 0.02, "bus_limits": {"stop_policy": stop_policy},
                     # granted by the operator who passed --port: a real robot moves only when allowed
                     "tool_policy": {"allow": sorted(set(SO101RealTarget.TOOLS) - NEVER_EXPOSED)}},
        scene={})

    def put(doc):
        doc.targets = [t for t in doc.targets if t.name != REAL_TARGET] + [spec]
        return doc

    ws.update("TARGETS", put)
    sensors_path = ws.root / "sensors.yaml"
    from phyagentos.errors import DocumentError
    from phyagentos.yamlsource import read_yaml

    raw = read_yaml(sensors_path, error=DocumentError, root=ws.root) if sensors_path.is_file() else None
    if not isinstance(raw, dict):
        from phyagentos.resources import templates_dir

        raw = read_yaml(templates_dir() / "sensors.yaml", error=DocumentError)
    targets = raw.setdefault("targets", {})
    if REAL_TARGET not in targets:
        targets[REAL_TARGET] = [s for s in targets.get("so101_tabletop", [])
                                if s.get("kind") != "force_torque"]  # a real SO-101 has no wrist F/T sensor
        atomic_write_text(sensors_path, yaml.safe_dump(raw, sort_keys=False))


def with_real(handlers: dict[str, Handler]) -> dict[str, Handler]:
    """``handlers`` plus ``bus-twin``, ``calibrate``, ``doctor``; ``run`` honours ``--port``."""
    inner = handlers["run"]

    def run(args, out: Console, err: Console) -> int:
        port = getattr(args, "port", None)
        if port is None:
            if getattr(args, "dry_run", False) or getattr(args, "target", None) == REAL_TARGET:
                from phyagentos.errors import TargetError

                raise TargetError("--target so101_real needs --port PORT (the arm's serial port, or a bus twin's)")
            return inner(args, out, err)
        if args.target is None:
            args.target = REAL_TARGET
        if args.target != REAL_TARGET:
            from phyagentos.errors import TargetError

            raise TargetError(f"--port applies to --target {REAL_TARGET}, got --target {args.target}")
        prepare_real_workspace(args.workspace, port=port, calibration=args.calibration, dry_run=args.dry_run,
                               stop_policy=args.stop_policy)
        _refuse_depth_criteria(args.goal_graph, args.workspace)
        _preflight_bus(port, args.calibration)
        err.print(f"[dim]{REAL_TARGET} on {port}{' (dry run: nothing moves)' if args.dry_run else ''}[/dim]")
        return inner(args, out, err)

    return {**handlers, "run": run, "bus-twin": _cmd_bus_twin, "calibrate": _cmd_calibrate, "doctor": _cmd_doctor}


def _refuse_depth_criteria(goal_graph: Path, workspace: Path) -> None:
    """Refuse (TargetError, before the bus is touched) a graph with criteria that need
    perceived object poses when the real target's cameras give no depth."""
    from phyagentos.errors import GoalGraphError, TargetError
    from phyagentos.protocol.sensors import read_sensors
    from phyagentos.targets.so101_real.camera import RGB_ONLY_PREDICATES, depth_needing_criteria, has_depth

    cams = [s for s in read_sensors(workspace).for_target(REAL_TARGET) if s.kind in ("rgb_camera", "rgbd_camera")]
    if has_depth(cams):
        return
    from phyagentos.yamlsource import read_yaml

    try:
        graph = read_yaml(goal_graph, error=GoalGraphError) or {}
    except (OSError, GoalGraphError):
        return  # the run reports the graph's own problem with its location
    needing = depth_needing_criteria(graph if isinstance(graph, dict) else {})
    if needing:
        what = ", ".join(f"{node}: {pred}" for node, pred in needing)
        raise TargetError(
            f"{goal_graph}: criteria need perceived object poses, i.e. depth, but {REAL_TARGET}'s cameras in "
            f"{Path(workspace) / 'sensors.yaml'} are "
            f"{', '.join(f'{c.name} ({c.kind})' for c in cams) or 'none'}: {what}. With RGB only, perception "
            f"cannot locate objects; judgeable criteria are {', '.join(sorted(RGB_ONLY_PREDICATES))}. Add an RGB-D "
            f"camera (kind rgbd_camera) or drop those criteria; nothing was moved")


def _preflight_bus(port: str, calibration: Path | None) -> None:
    """Before any workspace or runner: the calibration loads and the bus answers with the
    calibration's ids (clear errors: ``calibration.missing``, ``bus.port``, ``bus.id_mismatch``)."""
    from phyagentos.targets.so101_real.calibration import Calibration, default_calibration_path
    from phyagentos.targets.so101_real.driver import FeetechBus

    cal = Calibration.load(Path(calibration).expanduser() if calibration else default_calibration_path())
    with FeetechBus(port, ids=cal.ids):
        pass

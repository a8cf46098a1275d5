"""Policy round-trip latency over the openpi websocket protocol on loopback.

    .venv/bin/python bench/policy_latency.py [--n 300]

Starts ``phyagentos policy serve --port 0`` as a separate process (the mink
reach-and-grasp controller) and sends it ``--n`` observations of the simulated Franka
scene with a :class:`~phyagentos.policy.client.PolicyClient`, with and without a
224x224 RGB frame (openpi-style keys, msgpack + numpy framing). Reported per case, p50
and p99 in ms: the full round trip (encode, send, server inference, reply, decode),
the transport share (round trip minus the server's own ``infer_ms``), and the
websocket ping round trip used as the policy heartbeat. Writes
bench/results/policy_latency.json.
"""

from __future__ import annotations

import subprocess
import sys

from _harness import parser, percentile, write_json

import phyagentos  # noqa: F401  (headless GL before mujoco loads)

# isort: split
import mujoco
import numpy as np

from phyagentos.policy.client import PolicyClient
from phyagentos.targets import MuJoCoTarget, SceneSpec


def observation(target: MuJoCoTarget, image: np.ndarray | None) -> dict:
    o = target.observe()
    quat = np.empty(4)
    mujoco.mju_mat2Quat(quat, o["objects"]["cube"][:3, :3].reshape(-1))
    obs = {
        "prompt": "pick up the cube",
        "observation/joint_position": o["arm_qpos"].astype(np.float32),
        "observation/joint_velocity": o["arm_qvel"].astype(np.float32),
        "observation/gripper_position": np.array([0.0], np.float32),
        "observation/object_pose": np.concatenate([o["objects"]["cube"][:3, 3], quat]).astype(np.float32),
        "observation/object_half_extents": np.full(3, 0.02, np.float32),
    }
    if image is not None:
        obs["observation/image"] = image
    return obs


def pct(values, q) -> float:
    return round(percentile([v * 1e3 for v in values], q), 3)


def main() -> int:
    ap = parser(__doc__, "policy_latency")
    ap.add_argument("--n", type=int, default=300)
    args = ap.parse_args()
    proc = subprocess.Popen([sys.executable, "-m", "phyagentos.cli", "policy", "serve", "--port", "0"],
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        uri = proc.stdout.readline().split()[-1]
        target = MuJoCoTarget("bench", SceneSpec.default())
        frame = target.render(width=224, height=224)
        rows = []
        with PolicyClient(uri, open_timeout_s=10.0) as client:
            for name, image in (("state only", None), ("state + 224x224 RGB", frame)):
                obs = observation(target, image)
                rtt, transport = [], []
                for _ in range(10):  # warm-up
                    client.infer(obs, timeout_s=10.0)
                for _ in range(args.n):
                    out = client.infer(obs, timeout_s=10.0)
                    rtt.append(client.latencies_s[-1])
                    transport.append(client.latencies_s[-1] - out["server_timing"]["infer_ms"] / 1e3)
                rows.append({"case": name, "n": args.n, "rtt_ms_p50": pct(rtt, 50), "rtt_ms_p99": pct(rtt, 99),
                             "transport_ms_p50": pct(transport, 50), "transport_ms_p99": pct(transport, 99)})
            pings = [client.heartbeat(timeout_s=5.0) for _ in range(args.n)]
        heartbeat = {"ping_ms_p50": pct(pings, 50), "ping_ms_p99": pct(pings, 99)}
    finally:
        proc.kill()
        proc.wait(timeout=10)
    print(f"{'case':24s} {'n':>5s} {'rtt p50 ms':>11s} {'rtt p99 ms':>11s} {'transport p50':>14s} {'transport p99':>14s}")
    for r in rows:
        print(f"{r['case']:24s} {r['n']:5d} {r['rtt_ms_p50']:11.3f} {r['rtt_ms_p99']:11.3f} "
              f"{r['transport_ms_p50']:14.3f} {r['transport_ms_p99']:14.3f}")
    print(f"heartbeat (websocket ping) p50 {heartbeat['ping_ms_p50']:.3f} ms, p99 {heartbeat['ping_ms_p99']:.3f} ms")
    write_json(args.out, {"rows": rows, "heartbeat": heartbeat})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

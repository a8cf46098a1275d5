"""The real SO-101 over its Feetech bus, and a bus twin that speaks the same bytes.

- :mod:`.protocol`: STS3215 packet format and control table;
- :mod:`.bus_twin`: a pseudo-terminal answering as six STS3215, backed by MuJoCo;
- :mod:`.driver`: the bus through Feetech's SDK (``scservo_sdk``);
- :mod:`.calibration`: LeRobot's calibration JSON and the steps <-> radians map;
- :mod:`.guard`: the bus-level SafetyGuard; :mod:`.arm`: the control loop;
- :mod:`.target`: the ``so101_real`` rollout target (the MuJoCo twin plans and checks);
- :mod:`.camera`: OpenCV cameras with intrinsics from ``sensors.yaml``.

See docs/real_robot.md.
"""

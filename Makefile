# The two commands a newcomer needs:
#   make demo   set up, then run the shipped example goal graph pick_and_place (phyagentos/data/goal_graphs/)
#               end to end on the MuJoCo Franka
#   make test   set up, then check the plane boundary, lint (ruff, mypy on its checked core), and run the test suite (4 workers, one file per worker at a time)
#   make soak   the SIGKILL and scale drills at their full scale (PHYAGENTOS_SOAK=1; make test runs them smaller)
# The test recipes clear PYTHONDONTWRITEBYTECODE for pytest, so it keeps the test modules it
# rewrites as bytecode under __pycache__/ (git-ignored); otherwise each of the four workers
# parses and rewrites every test module on every run (about 5 s of CPU each).
.PHONY: setup demo test soak bench clean

setup:
	@scripts/setup.sh

demo: setup
	.venv/bin/phyagentos run pick_and_place --workspace ws/

test: setup
	.venv/bin/lint-imports
	.venv/bin/python scripts/check_import_cycles.py
	.venv/bin/python scripts/check_ground_truth_boundary.py
	.venv/bin/ruff check .
	.venv/bin/mypy
	PYTHONDONTWRITEBYTECODE= .venv/bin/pytest -q -n 4 --dist loadfile --no-loadscope-reorder --durations=20

soak: setup
	PHYAGENTOS_SOAK=1 PYTHONDONTWRITEBYTECODE= .venv/bin/pytest -q -n 2 -m soak --durations=0

bench: setup
	.venv/bin/python -m bench all

clean:
	rm -rf ws/ bench/results/ .pytest_cache .ruff_cache .mypy_cache

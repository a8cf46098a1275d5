"""Which model to use: ``llm.yaml`` (workspace, then current directory) overridden by the environment.

``llm.yaml``::

    provider: offline          # offline (llama.cpp, the default) or openai
    base_url: http://127.0.0.1:8080/v1   # openai only
    model: my-model                      # openai only (offline: the shipped SmolLM2)
    api_key_env: OPENAI_API_KEY          # the NAME of the variable holding the key
    seed: 0
    threads: 1                           # offline only

Environment: ``PHYAGENTOS_LLM_PROVIDER``, ``PHYAGENTOS_LLM_BASE_URL``,
``PHYAGENTOS_LLM_MODEL``, ``PHYAGENTOS_LLM_API_KEY_ENV``, ``PHYAGENTOS_LLM_SEED``. A key
written into ``llm.yaml`` (``api_key``) is refused: keys live only in the environment.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any


from .client import LLMClient, LLMError
from phyagentos.yamlsource import read_yaml

__all__ = ["LLMConfig", "load_llm_config", "make_client", "PROVIDERS"]

PROVIDERS = ("offline", "openai")
_KEYS = {"provider", "base_url", "model", "api_key_env", "seed", "threads", "model_path"}


@dataclass(frozen=True)
class LLMConfig:
    """Model selection; ``source`` says where it came from (for the record)."""

    provider: str = "offline"
    base_url: str | None = None
    model: str | None = None
    api_key_env: str = "OPENAI_API_KEY"
    seed: int = 0
    threads: int | None = None
    model_path: str | None = None
    source: str = "default"


def load_llm_config(workspace: str | Path | None = None, *, env: dict[str, str] | None = None) -> LLMConfig:
    """Read ``llm.yaml`` from ``workspace`` (or the current directory) and apply the environment.

    Raises:
        LLMError: unreadable ``llm.yaml``, unknown keys, an ``api_key`` in the file, an
            unknown provider or an ``openai`` provider without ``base_url``/``model``.
    """
    env = dict(os.environ if env is None else env)
    data: dict[str, Any] = {}
    source = "default"
    for candidate in ([Path(workspace) / "llm.yaml"] if workspace else []) + [Path("llm.yaml")]:
        if candidate.is_file():
            try:
                data = read_yaml(candidate, error=LLMError) or {}
            except LLMError as exc:
                raise LLMError(f"not valid YAML: {exc}") from None
            if not isinstance(data, dict):
                raise LLMError(f"{candidate}: expected a mapping of settings")
            if "api_key" in data:
                raise LLMError(f"{candidate}: 'api_key' must not be written to a file; put the key in an environment "
                               f"variable and name it with 'api_key_env'")
            unknown = set(data) - _KEYS
            if unknown:
                raise LLMError(f"{candidate}: unknown key(s) {sorted(unknown)}; valid keys: {sorted(_KEYS)}")
            source = str(candidate)
            break
    for key in ("provider", "base_url", "model", "api_key_env", "seed"):
        value = env.get(f"PHYAGENTOS_LLM_{key.upper()}")
        if value:
            data[key] = value
            source = f"{source}+env" if source != "default" else "env"
    provider = str(data.get("provider", "offline"))
    if provider not in PROVIDERS:
        raise LLMError(f"unknown model provider {provider!r} ({source}); valid providers: {', '.join(PROVIDERS)}")
    if provider == "openai" and not (data.get("base_url") and data.get("model")):
        raise LLMError(f"provider 'openai' needs base_url and model ({source}); set them in llm.yaml or "
                       "PHYAGENTOS_LLM_BASE_URL / PHYAGENTOS_LLM_MODEL")
    return LLMConfig(provider=provider, base_url=data.get("base_url"), model=data.get("model"),
                     api_key_env=str(data.get("api_key_env", "OPENAI_API_KEY")), seed=int(data.get("seed", 0)),
                     threads=int(data["threads"]) if data.get("threads") else None,
                     model_path=data.get("model_path"), source=source)


def make_client(config: LLMConfig | None = None) -> LLMClient:
    """The client ``config`` names (default: the offline model)."""
    config = config or LLMConfig()
    if config.provider == "openai":
        from .openai_client import OpenAICompatClient  # noqa: PLC0415

        return OpenAICompatClient(base_url=str(config.base_url), model=str(config.model),
                                  api_key_env=config.api_key_env, seed=config.seed)
    from .offline import LlamaCppClient  # noqa: PLC0415

    return LlamaCppClient(config.model_path, seed=config.seed, threads=config.threads)

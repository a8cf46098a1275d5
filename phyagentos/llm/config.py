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
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from phyagentos.untrusted import quote
from phyagentos.yamlsource import line_of, read_yaml

from .client import LLMClient, LLMError

__all__ = ["LLMConfig", "LLMFile", "load_llm_config", "read_llm_file", "make_client", "PROVIDERS"]

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



class LLMFile(BaseModel):
    """``llm.yaml`` as written: a strict schema (unknown keys, wrong types, non-finite or
    out-of-range numbers refused, with ``file:line``)."""

    model_config = ConfigDict(extra="forbid", frozen=True, strict=True, allow_inf_nan=False)

    provider: Literal["offline", "openai"] = "offline"
    base_url: str | None = Field(None, max_length=2048, pattern=r"^https?://[^\s]+$",
                                 description="openai only: http(s) URL of the endpoint")
    model: str | None = Field(None, min_length=1, max_length=256, pattern=r"^[^\s]+$")
    api_key_env: str = Field("OPENAI_API_KEY", max_length=128, pattern=r"^[A-Za-z_][A-Za-z0-9_]*$",
                             description="the NAME of the environment variable holding the key")
    seed: int = Field(0, ge=0, le=2**31 - 1)
    threads: int | None = Field(None, ge=1, le=256)
    model_path: str | None = Field(None, min_length=1, max_length=4096, description="offline only: a GGUF file")


def read_llm_file(path: str | Path) -> dict[str, Any]:
    """The settings written in the ``llm.yaml`` at ``path`` (only those written), validated.

    Raises:
        LLMError: not YAML, not a mapping, an ``api_key`` written into it, an unknown key,
            or a bad value (``path:line``, the valid keys or choices).
        OSError: the file cannot be read (a FIFO or a device is refused, never waited on).
    """
    path = Path(path)
    data = read_yaml(path, error=LLMError, plain=False)
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise LLMError(f"{path}:{line_of(data) or 1}: expected a mapping of settings")
    if "api_key" in data:
        raise LLMError(f"{path}:{line_of(data, 'api_key')}: 'api_key' must not be written to a file; put the key in "
                       f"an environment variable and name it with 'api_key_env'")
    unknown = set(data) - _KEYS
    if unknown:
        key = sorted(unknown, key=str)[0]
        raise LLMError(f"{path}:{line_of(data, key)}: unknown key(s) {sorted(map(str, unknown))}; "
                       f"valid keys: {sorted(_KEYS)}")
    try:
        LLMFile.model_validate(dict(data))
    except ValidationError as exc:
        first = exc.errors()[0]
        key = first["loc"][0] if first["loc"] else None
        where = f"{path}:{line_of(data, key) if key is not None else line_of(data) or 1}"
        choices = f"; valid providers: {', '.join(PROVIDERS)}" if key == "provider" else ""
        raise LLMError(f"{where}: {key}: {first['msg']}{choices}") from None
    return dict(data)


def load_llm_config(workspace: str | Path | None = None, *, env: dict[str, str] | None = None) -> LLMConfig:
    """Read ``llm.yaml`` from ``workspace`` (or the current directory) and apply the environment.

    Raises:
        LLMError: unreadable ``llm.yaml``, unknown keys, an ``api_key`` in the file, a value
            out of :class:`LLMFile`'s ranges (``file:line``), an unknown provider or an
            ``openai`` provider without ``base_url``/``model``.
    """
    env = dict(os.environ if env is None else env)
    data: dict[str, Any] = {}
    source = "default"
    for candidate in ([Path(workspace) / "llm.yaml"] if workspace else []) + [Path("llm.yaml")]:
        if candidate.is_file():
            try:
                data = read_llm_file(candidate)
            except OSError as exc:
                raise LLMError(f"{candidate}: cannot be read: {exc}") from None
            source = str(candidate)
            break
    for key in ("provider", "base_url", "model", "api_key_env", "seed"):
        value = env.get(f"PHYAGENTOS_LLM_{key.upper()}")
        if value:
            data[key] = value
            source = f"{source}+env" if source != "default" else "env"
    provider = str(data.get("provider", "offline"))
    if provider not in PROVIDERS:
        raise LLMError(f"unknown model provider {quote(provider)} ({source}); valid providers: {', '.join(PROVIDERS)}")
    if provider == "openai" and not (data.get("base_url") and data.get("model")):
        raise LLMError(f"provider 'openai' needs base_url and model ({source}); set them in llm.yaml or "
                       "PHYAGENTOS_LLM_BASE_URL / PHYAGENTOS_LLM_MODEL")
    try:
        seed = int(data.get("seed", 0))
    except (TypeError, ValueError):
        raise LLMError(f"seed must be an integer ({source}), got {quote(data.get('seed'))}") from None
    return LLMConfig(provider=provider, base_url=data.get("base_url"), model=data.get("model"),
                     api_key_env=str(data.get("api_key_env", "OPENAI_API_KEY")), seed=seed,
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

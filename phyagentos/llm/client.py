"""The model interface: chat messages in, (schema-constrained) text out, every call recorded."""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass
from typing import Any, Mapping, Protocol, Sequence, runtime_checkable

from phyagentos.errors import PhyAgentOSError
from phyagentos.protocol.schemas import ModelCallRecord

__all__ = ["LLMError", "LLMCall", "LLMReply", "LLMClient", "prompt_hash", "call_record"]


class LLMError(PhyAgentOSError):
    """A language model could not be configured, loaded or called, or its output was unusable."""


def prompt_hash(messages: Sequence[Mapping[str, str]], schema: Mapping[str, Any] | None = None) -> str:
    """SHA-256 (hex, first 16 chars) of the messages and the output schema, canonical JSON."""
    blob = json.dumps({"messages": list(messages), "schema": schema}, sort_keys=True, ensure_ascii=False)
    return hashlib.sha256(blob.encode("utf-8")).hexdigest()[:16]


@dataclass(frozen=True)
class LLMCall:
    """The record of one model call (what the session's or plan's context keeps).

    Attributes:
        provider: ``llama.cpp`` or ``openai``.
        model: model name (file name of the GGUF offline).
        purpose: what the call was for (``plan``, ``repair``, ``revise``, ``act``).
        prompt_sha256: :func:`prompt_hash` of messages and schema.
        prompt_tokens, completion_tokens: as reported by the provider (0 if unknown).
        latency_s: wall time of the call, s.
        temperature, seed: sampling settings sent.
        constrained: the output was decoded under the JSON schema (grammar) rather than
            only checked afterwards.
        max_tokens: the completion budget sent (0 if unknown).
    """

    provider: str
    model: str
    purpose: str
    prompt_sha256: str
    prompt_tokens: int
    completion_tokens: int
    latency_s: float
    temperature: float
    seed: int
    constrained: bool
    max_tokens: int = 0

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["latency_s"] = round(self.latency_s, 4)
        return d


@dataclass(frozen=True)
class LLMReply:
    """A model's answer: ``text`` (JSON text when a schema was given) and its call record."""

    text: str
    call: LLMCall

    def json(self) -> Any:
        """The text parsed as JSON; :class:`LLMError` quoting the text if it does not parse."""
        try:
            return json.loads(self.text)
        except json.JSONDecodeError as exc:
            raise LLMError(f"model output is not JSON ({exc.msg} at char {exc.pos}): {self.text[:300]!r}") from exc


@runtime_checkable
class LLMClient(Protocol):
    """What every provider offers. Deterministic settings (temperature, seed) are the client's."""

    provider: str
    model: str

    def complete(self, messages: Sequence[Mapping[str, str]], *, schema: Mapping[str, Any] | None = None,
                 max_tokens: int = 256, purpose: str = "chat") -> LLMReply:
        """Answer ``messages`` (``[{role, content}]``); with ``schema`` the answer is JSON
        decoded under that JSON schema. Raises :class:`LLMError`."""
        ...


def call_record(call: LLMCall, *, role: str, output: str, outcome: str, detail: str = "",
                ref: str | None = None) -> ModelCallRecord:
    """The protocol record of ``call`` (what a session's context keeps): its settings, usage and
    latency, the raw ``output`` and what became of it (``outcome``: accepted, refused, rejected,
    repaired, gave_up, fallback, error; ``detail``: why)."""
    return ModelCallRecord(
        role=role, purpose=call.purpose, provider=call.provider, model=call.model, prompt_sha256=call.prompt_sha256,
        parameters={"temperature": call.temperature, "seed": call.seed, "max_tokens": call.max_tokens,
                    "constrained": call.constrained},
        prompt_tokens=max(0, call.prompt_tokens), completion_tokens=max(0, call.completion_tokens),
        latency_s=round(max(0.0, call.latency_s), 4), output=output, outcome=outcome, detail=detail[:2000], ref=ref)

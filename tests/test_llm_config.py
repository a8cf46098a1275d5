"""Model configuration and the OpenAI-compatible path, against a real local endpoint."""

from __future__ import annotations

import json
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import pytest

from phyagentos.llm import LlamaCppClient, LLMError, OpenAICompatClient, load_llm_config, make_client, prompt_hash


def test_llm_yaml_is_read_and_the_environment_overrides_it(tmp_path):
    (tmp_path / "llm.yaml").write_text("provider: openai\nbase_url: http://127.0.0.1:9/v1\nmodel: a\n")
    cfg = load_llm_config(tmp_path, env={"PHYAGENTOS_LLM_MODEL": "b"})
    assert (cfg.provider, cfg.base_url, cfg.model) == ("openai", "http://127.0.0.1:9/v1", "b")
    assert load_llm_config(tmp_path / "nowhere", env={}).provider == "offline"


def test_a_key_written_into_llm_yaml_is_refused(tmp_path):
    (tmp_path / "llm.yaml").write_text("provider: openai\nbase_url: http://x/v1\nmodel: m\napi_key: sk-123\n")
    with pytest.raises(LLMError, match="must not be written to a file"):
        load_llm_config(tmp_path, env={})


def test_unknown_provider_and_incomplete_endpoint_are_clear_errors(tmp_path):
    with pytest.raises(LLMError, match="valid providers: offline, openai"):
        load_llm_config(tmp_path, env={"PHYAGENTOS_LLM_PROVIDER": "magic"})
    with pytest.raises(LLMError, match="needs base_url and model"):
        load_llm_config(tmp_path, env={"PHYAGENTOS_LLM_PROVIDER": "openai"})


def test_the_offline_model_is_deterministic_and_schema_constrained():
    client = make_client()
    assert isinstance(client, LlamaCppClient)
    schema = {"type": "object", "properties": {"colour": {"enum": ["red", "green"]}}, "required": ["colour"]}
    messages = [{"role": "user", "content": "Which colour is grass?"}]
    a, b = (client.complete(messages, schema=schema, max_tokens=20, purpose="test") for _ in range(2))
    assert a.text == b.text and a.json()["colour"] in ("red", "green")
    assert a.call.prompt_sha256 == prompt_hash(messages, schema) and a.call.constrained


def test_an_openai_compatible_endpoint_is_called_through_the_sdk(monkeypatch):
    """A real HTTP endpoint on localhost serving /v1/chat/completions from the offline model."""
    offline = make_client()
    seen = {}

    class Handler(BaseHTTPRequestHandler):
        def do_POST(self):  # noqa: N802
            body = json.loads(self.rfile.read(int(self.headers["Content-Length"])))
            seen.update(body=body, auth=self.headers.get("Authorization"))
            schema = (body.get("response_format") or {}).get("json_schema", {}).get("schema")
            reply = offline.complete(body["messages"], schema=schema, max_tokens=body.get("max_tokens", 32))
            out = {"id": "x", "object": "chat.completion", "created": 0, "model": body["model"],
                   "choices": [{"index": 0, "finish_reason": "stop",
                                "message": {"role": "assistant", "content": reply.text}}],
                   "usage": {"prompt_tokens": reply.call.prompt_tokens, "completion_tokens": reply.call.completion_tokens,
                             "total_tokens": reply.call.prompt_tokens + reply.call.completion_tokens}}
            data = json.dumps(out).encode()
            self.send_response(200)
            self.send_header("Content-Type", "application/json")
            self.send_header("Content-Length", str(len(data)))
            self.end_headers()
            self.wfile.write(data)

        def log_message(self, *args):
            pass

    server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        monkeypatch.setenv("MY_TEST_KEY", "sk-local")
        client = OpenAICompatClient(base_url=f"http://127.0.0.1:{server.server_port}/v1", model="smol",
                                    api_key_env="MY_TEST_KEY", seed=3)
        schema = {"type": "object", "properties": {"answer": {"enum": ["yes", "no"]}}, "required": ["answer"]}
        reply = client.complete([{"role": "user", "content": "Is the sky blue?"}], schema=schema, max_tokens=20)
    finally:
        server.shutdown()
    assert reply.json()["answer"] in ("yes", "no")
    assert reply.call.provider == "openai" and reply.call.model == "smol" and reply.call.prompt_tokens > 0
    assert seen["body"]["temperature"] == 0.0 and seen["body"]["seed"] == 3
    assert seen["body"]["response_format"]["type"] == "json_schema"
    assert seen["auth"] == "Bearer sk-local"  # the key came from the named variable only

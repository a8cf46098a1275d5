"""A MuJoCo offscreen renderer that, closed, frees only what is its own.

``mujoco.Renderer.close()`` (mujoco 3.11, ``rendering/classic/renderer.py``) destroys its GL
context first and then frees its ``MjrContext``; ``mjr_freeContext`` deletes the textures,
buffers and framebuffers it names by id on whatever GL context is current at that moment. When
another renderer's context is current (it rendered last), that renderer's framebuffer and
textures are deleted and every image it renders afterwards is garbage: depth images with
non-finite values, RGB noise. A renderer garbage-collected between two renders of another
(``__del__`` calls ``close``) does it at a moment nobody chose: a test of the perception
pipeline failed that way in a fresh clone (a second capture of a synthetic scene, depth not
finite), and the same hazard was reported for OSMesa servers that swap worlds (innate-os pull
request 766).

:class:`Renderer` makes its own GL context current, frees its ``MjrContext`` there, then frees
the GL context: the deletes land on the context being destroyed. Every renderer this project
opens is one (a view of another size that shares a context, ``SharedContextRenderer``, frees
nothing).
"""

from __future__ import annotations

import logging

import mujoco

__all__ = ["Renderer"]

log = logging.getLogger(__name__)


class Renderer(mujoco.Renderer):
    """:class:`mujoco.Renderer` whose :meth:`close` (and so its ``__del__``) frees its MuJoCo
    render context with its own GL context current. Arguments, images and errors as
    :class:`mujoco.Renderer` (``model``, ``height``, ``width`` in pixels)."""

    def close(self) -> None:
        """Free the ``MjrContext`` with this renderer's GL context current, then the GL
        context; idempotent (a second call, or one after a constructor that failed part-way,
        frees nothing). Where the GL context cannot be made current in this thread (a GLFW
        context current in another), the render context is freed as ``mujoco.Renderer``
        frees it, with a warning in the log."""
        gl = getattr(self, "_gl_context", None)
        mjr = getattr(self, "_mjr_context", None)
        if mjr is not None:
            if gl is not None:
                try:
                    gl.make_current()
                except Exception as exc:  # noqa: BLE001 - any backend's failure: free as mujoco would
                    log.warning("renderer: its GL context could not be made current to free its render "
                                "context (%s: %s); freed on the current one", type(exc).__name__, exc)
            mjr.free()
        self._mjr_context = None
        if gl is not None:
            gl.free()
        self._gl_context = None
